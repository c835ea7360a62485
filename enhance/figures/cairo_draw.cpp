// Shared cairo helpers (cairo_draw.h).
#include "enhance/figures/cairo_draw.h"

#include <algorithm>
#include <cmath>

namespace macro::enhance::figures {

void set_rgb(cairo_t* cr, uint32_t rgb, double alpha) {
  cairo_set_source_rgba(cr, double((rgb >> 16) & 255) / 255.0, double((rgb >> 8) & 255) / 255.0,
                        double(rgb & 255) / 255.0, alpha);
}

void set_font(cairo_t* cr, double size, bool bold) {
  cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL,
                         bold ? CAIRO_FONT_WEIGHT_BOLD : CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, size);
  cairo_font_options_t* fo = cairo_font_options_create();
  cairo_font_options_set_hint_metrics(fo, CAIRO_HINT_METRICS_OFF);
  cairo_font_options_set_hint_style(fo, CAIRO_HINT_STYLE_NONE);
  cairo_font_options_set_antialias(fo, CAIRO_ANTIALIAS_GRAY);
  cairo_set_font_options(cr, fo);
  cairo_font_options_destroy(fo);
}

double measure_text(cairo_t* cr, const std::string& text) {
  cairo_text_extents_t e;
  cairo_text_extents(cr, text.c_str(), &e);
  return e.x_advance;
}

void draw_text(cairo_t* cr, double x, double y, const std::string& text, int anchor) {
  const double w = measure_text(cr, text);
  const double left = anchor < 0 ? x : anchor > 0 ? x - w : x - w / 2;
  cairo_move_to(cr, left, y);
  cairo_show_text(cr, text.c_str());
  cairo_new_path(cr);
}

SurfacePtr surface_from_image(const gs::Image& img) {
  SurfacePtr s(cairo_image_surface_create(CAIRO_FORMAT_RGB24, img.width, img.height));
  cairo_surface_flush(s.get());
  unsigned char* data = cairo_image_surface_get_data(s.get());
  const int stride = cairo_image_surface_get_stride(s.get());
  const auto u8 = [](float v) {
    return uint32_t(std::lround(std::clamp(std::isfinite(v) ? v : 0.f, 0.f, 1.f) * 255.f));
  };
  for (int y = 0; y < img.height; ++y) {
    auto* row = reinterpret_cast<uint32_t*>(data + size_t(y) * size_t(stride));
    for (int x = 0; x < img.width; ++x) {
      const float r = img.at(y, x, 0);
      const float g = img.channels >= 3 ? img.at(y, x, 1) : r;
      const float b = img.channels >= 3 ? img.at(y, x, 2) : r;
      row[x] = 0xff000000u | (u8(r) << 16) | (u8(g) << 8) | u8(b);
    }
  }
  cairo_surface_mark_dirty(s.get());
  return s;
}

gs::Image image_from_surface(cairo_surface_t* s) {
  cairo_surface_flush(s);
  const int w = cairo_image_surface_get_width(s), h = cairo_image_surface_get_height(s);
  const int stride = cairo_image_surface_get_stride(s);
  const unsigned char* data = cairo_image_surface_get_data(s);
  gs::Image img(w, h, 3);
  for (int y = 0; y < h; ++y) {
    const auto* row = reinterpret_cast<const uint32_t*>(data + size_t(y) * size_t(stride));
    for (int x = 0; x < w; ++x) {
      // Opaque surfaces only (white background), so premultiplication changes nothing.
      img.at(y, x, 0) = float((row[x] >> 16) & 255) / 255.f;
      img.at(y, x, 1) = float((row[x] >> 8) & 255) / 255.f;
      img.at(y, x, 2) = float(row[x] & 255) / 255.f;
    }
  }
  return img;
}

}  // namespace macro::enhance::figures
