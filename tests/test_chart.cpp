// enhance/bench/chart.h: the SVG text and the raster of a tiny hand-made chart, and the axes.
#include <catch2/catch.hpp>

#include <string>

#include "enhance/bench/chart.h"

namespace macro::enhance {
namespace {

Chart tiny_chart() {
  Chart c;
  c.width = 40, c.height = 20;
  c.rects.push_back({2, 2, 4, 3, 0xff0000});
  c.lines.push_back({0, 10, 39, 10, 0x00ff00, 1});
  c.circles.push_back({30.5, 4.5, 2, 0x0000ff});
  c.texts.push_back({10, 18, "a<1", 0x222222, -1});
  return c;
}

}  // namespace

TEST_CASE("chart: SVG text of a tiny chart", "[chart][harness]") {
  const std::string svg = chart_to_svg(tiny_chart());
  CHECK(svg ==
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"40\" height=\"20\" viewBox=\"0 0 40 "
        "20\" font-family=\"sans-serif\" font-size=\"12\">\n"
        "<rect x=\"2.00\" y=\"2.00\" width=\"4.00\" height=\"3.00\" fill=\"#ff0000\"/>\n"
        "<line x1=\"0.00\" y1=\"10.00\" x2=\"39.00\" y2=\"10.00\" stroke=\"#00ff00\" "
        "stroke-width=\"1.00\"/>\n"
        "<circle cx=\"30.50\" cy=\"4.50\" r=\"2.00\" fill=\"#0000ff\"/>\n"
        "<text x=\"10.00\" y=\"18.00\" fill=\"#222222\" text-anchor=\"start\">a&lt;1</text>\n"
        "</svg>\n");
}

TEST_CASE("chart: raster of a tiny chart", "[chart][harness]") {
  const gs::Image img = rasterize_chart(tiny_chart());
  REQUIRE(img.width == 40);
  REQUIRE(img.height == 20);
  REQUIRE(img.channels == 3);
  const auto rgb = [&](int row, int col) {
    return std::to_string(int(img.at(row, col, 0) * 255 + 0.5f)) + "," +
           std::to_string(int(img.at(row, col, 1) * 255 + 0.5f)) + "," +
           std::to_string(int(img.at(row, col, 2) * 255 + 0.5f));
  };
  CHECK(rgb(0, 0) == "255,255,255");  // background
  CHECK(rgb(2, 2) == "255,0,0");      // rectangle [2, 6) x [2, 5)
  CHECK(rgb(4, 5) == "255,0,0");
  CHECK(rgb(5, 5) == "255,255,255");
  CHECK(rgb(10, 0) == "0,255,0");  // a 1 px line: single pixels along y = 10
  CHECK(rgb(10, 39) == "0,255,0");
  CHECK(rgb(11, 20) == "255,255,255");
  CHECK(rgb(4, 30) == "0,0,255");  // disc centred on pixel (row 4, column 30)
  CHECK(rgb(4, 33) == "255,255,255");
  // 'A' at 2x: its top row is ".#.", so ink at columns 12-13 of rows 8-9, none at 10-11.
  CHECK(rgb(8, 12) == "34,34,34");
  CHECK(rgb(8, 10) == "255,255,255");
}

TEST_CASE("chart: axes, ranges and ticks", "[chart][harness]") {
  double lo = 2, hi = 2;
  pad_range(lo, hi);  // zero width: +-0.5, then 8% of 1
  CHECK(lo == Approx(1.42));
  CHECK(hi == Approx(2.58));
  CHECK(tick_text(123.4) == "123");
  CHECK(tick_text(12.34) == "12.3");
  CHECK(tick_text(1.234) == "1.23");
  CHECK(tick_text(-0.1234) == "-0.123");
  PlotFrame f;
  f.x0 = 0, f.x1 = 10, f.y0 = 0, f.y1 = 1;
  CHECK(f.px(0) == 70);
  CHECK(f.px(10) == 640 - 20);
  CHECK(f.py(0) == 420 - 50);
  CHECK(f.py(1) == 40);
  Chart c;
  draw_axes(c, f, "title", "x", "y", true);
  CHECK(c.width == 640);
  CHECK(c.rects.size() == 1);
  CHECK(c.lines.size() == 5 + 5 + 2);  // grid rows, grid columns, two axes
  CHECK(c.texts.size() == 5 + 5 + 3);  // y ticks, x ticks, title and labels
  CHECK(chart_palette(0) == chart_palette(10));
}

}  // namespace macro::enhance
