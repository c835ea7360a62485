// Charts as drawings: a list of primitives (lines, circles, rectangles, text) in pixel coordinates,
// origin top left, written as SVG text by hand or rasterised to an RGB image here (no plotting
// library). Also the pieces every benchmark chart shares: the palette, a plot frame that maps data
// to pixels, padded ranges, tick labels and the axes.
//
// Raster: rectangles filled with their edges rounded to whole pixels, circles as
// discs over pixel centres, lines as discs of the stroke's radius stepped every half pixel (single
// pixels up to 1.5 px width), text in a built-in 3x5 bitmap font drawn at 2x (8 px advance, upper
// case, unknown characters blank), baseline at y. Primitives are drawn by kind in the order
// rectangles, lines, circles, text, each kind in list order, with no blending. The SVG draws the
// same lists in the same order (coordinates with 2 decimals, sans-serif 12 px text).
//
// What it does not: anti-aliasing, clipping to a plot area, or text metrics (both renderers
// assume 8 px per character).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "gs/image_io.h"

namespace macro::enhance {

struct Chart {
  struct Line {
    double x0, y0, x1, y1;
    uint32_t rgb;  // 0xRRGGBB
    double width;  // stroke, pixels
  };
  struct Circle {
    double x, y, r;
    uint32_t rgb;
  };
  struct Rect {
    double x, y, w, h;
    uint32_t rgb;
  };
  struct Text {
    double x, y;  // anchor point on the baseline
    std::string text;
    uint32_t rgb;
    int anchor;  // -1 left, 0 middle, 1 right
  };
  int width = 640, height = 420;
  std::vector<Line> lines;
  std::vector<Circle> circles;
  std::vector<Rect> rects;
  std::vector<Text> texts;
};

std::string chart_to_svg(const Chart& chart);
gs::Image rasterize_chart(const Chart& chart);  // [height, width, 3]

// ---- Building charts ---------------------------------------------------------------------------
inline constexpr uint32_t kChartInk = 0x222222, kChartGrid = 0xdddddd;
uint32_t chart_palette(size_t i);  // the ten matplotlib "tab10" colours (own order), cycled

// The plot area inside a chart of w x h pixels (margins in pixels) and the data ranges it shows.
struct PlotFrame {
  double left = 70, top = 40, right = 20, bottom = 50;
  double x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  int w = 640, h = 420;
  double px(double x) const { return left + (x - x0) / (x1 - x0) * (w - left - right); }
  double py(double y) const { return h - bottom - (y - y0) / (y1 - y0) * (h - top - bottom); }
};

// [lo, hi] widened by 8% on each side; [0, 1] when either is not finite, at least 1 wide.
void pad_range(double& lo, double& hi);
// "%.0f" from 100, "%.1f" from 10, "%.2f" from 1, else "%.3f" (by magnitude).
std::string tick_text(double v);

// Sizes `chart` to the frame and draws a white background, five horizontal grid lines with y tick
// labels (and five vertical ones with x labels when x_ticks), the two axes, the title (top
// centre), the x label (bottom centre) and the y label (top left).
void draw_axes(Chart& chart, const PlotFrame& frame, const std::string& title,
               const std::string& xlabel, const std::string& ylabel, bool x_ticks);

}  // namespace macro::enhance
