// The cairo calls the figure code shares (chart.cpp, side_by_side.cpp); included only by .cpp
// files in enhance/figures/, so cairo never reaches another header. Font: "DejaVu Sans" through
// cairo's toy API (fontconfig picks a fallback where it is missing), hinting off.
#pragma once

#include <cairo.h>

#include <cstdint>
#include <memory>
#include <string>

#include "gs/image_io.h"

namespace macro::enhance::figures {

struct SurfaceDeleter {
  void operator()(cairo_surface_t* s) const { cairo_surface_destroy(s); }
};
struct ContextDeleter {
  void operator()(cairo_t* c) const { cairo_destroy(c); }
};
using SurfacePtr = std::unique_ptr<cairo_surface_t, SurfaceDeleter>;
using ContextPtr = std::unique_ptr<cairo_t, ContextDeleter>;

void set_rgb(cairo_t* cr, uint32_t rgb, double alpha = 1);
// Selects the font at `size` with unhinted metrics (the same widths on every surface).
void set_font(cairo_t* cr, double size, bool bold);
double measure_text(cairo_t* cr, const std::string& text);  // x advance at the current font
// Text with its baseline at y; anchor -1 left, 0 middle, 1 right.
void draw_text(cairo_t* cr, double x, double y, const std::string& text, int anchor);

// 8-bit RGB (A = 255) cairo surface from an image (values clamped to [0, 1]) and back.
SurfacePtr surface_from_image(const gs::Image& image);
gs::Image image_from_surface(cairo_surface_t* surface);

}  // namespace macro::enhance::figures
