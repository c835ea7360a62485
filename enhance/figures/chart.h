// Figures as drawings: a chart is an ordered list of shapes (lines, polylines, circles,
// rectangles, text) in chart units (CSS pixels, origin top left), drawn by one cairo routine onto
// three surfaces: an antialiased RGB raster (PNG), SVG and PDF. The text is DejaVu Sans (cairo's
// toy font API through fontconfig; another sans-serif where it is missing), with hinting off so
// that widths measured here (text_width) are the widths drawn on every surface.
//
// What it does not: clipping to a plot area (builders keep shapes inside), text wrapping, or
// kerning beyond what cairo's toy API does. cairo never appears in this header.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr uint32_t kNoEdge = 0xffffffffu;  // a circle or rectangle without an outline

struct Chart {
  struct Line {
    double x0, y0, x1, y1;
    uint32_t rgb;  // 0xRRGGBB
    double width;  // stroke, chart units
    double alpha = 1;
    bool dashed = false;
  };
  struct Polyline {  // round joins and caps
    std::vector<std::pair<double, double>> points;
    uint32_t rgb;
    double width;
    double alpha = 1;
  };
  struct Circle {
    double x, y, r;
    uint32_t rgb;
    double alpha = 1;
    uint32_t edge = kNoEdge;  // outline colour (1 unit wide)
  };
  struct Rect {
    double x, y, w, h;
    uint32_t rgb;  // fill; kNoEdge: no fill
    double alpha = 1;
    uint32_t edge = kNoEdge;
    double edge_width = 1;
  };
  struct Text {
    double x, y;       // anchor point on the baseline (vertical: the baseline runs upwards)
    std::string text;  // UTF-8
    uint32_t rgb;
    int anchor = -1;   // -1 left, 0 middle, 1 right (along the baseline)
    double size = 12;  // font size, chart units
    bool bold = false;
    bool vertical = false;  // rotated 90 degrees counter-clockwise (y-axis labels)
  };
  using Shape = std::variant<Line, Polyline, Circle, Rect, Text>;

  int width = 640, height = 420;
  std::string title;          // the SVG <title> and the PDF Title
  std::vector<Shape> shapes;  // drawn in order over a white background

  template <class S>
  void add(S shape) {
    shapes.emplace_back(std::move(shape));
  }
};

// Width in chart units of `text` at `size` (what every surface draws).
double text_width(const std::string& text, double size, bool bold = false);

// The chart as an RGB image [height * scale, width * scale, 3] (antialiased).
gs::Image render_chart(const Chart& chart, double scale = 1);
// The SVG and PDF documents (text as glyph outlines, the SVG with a <title>).
std::string chart_svg(const Chart& chart);
std::string chart_pdf(const Chart& chart);

// STEM.png (at `png_scale`, 2 = sharp on high-density screens and in print), STEM.svg and
// STEM.pdf, each written atomically; `written` receives the paths.
Status write_chart(const Chart& chart, const std::string& stem,
                   std::vector<std::string>* written = nullptr, double png_scale = 2);

}  // namespace macro::enhance
