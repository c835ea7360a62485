// enhance/figures/chart.h and plot.h, enhance/bench/report_charts.h: nice ticks on analytic
// ranges, legend placement, the antialiased raster with its colours at computed positions, the
// SVG and PDF documents, the "not computed" chart and the report's charts from hand-made results.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>
#include <set>
#include <string>

#include "enhance/bench/report_charts.h"
#include "enhance/figures/chart.h"
#include "enhance/figures/plot.h"

namespace macro::enhance {
namespace {

uint32_t pixel(const gs::Image& img, int row, int col) {
  uint32_t v = 0;
  for (int c = 0; c < 3; ++c) v = (v << 8) | uint32_t(std::lround(img.at(row, col, c) * 255.f));
  return v;
}

std::vector<std::string> texts_of(const Chart& c) {
  std::vector<std::string> out;
  for (const Chart::Shape& s : c.shapes)
    if (auto* t = std::get_if<Chart::Text>(&s)) out.push_back(t->text);
  return out;
}

bool has_text_starting(const Chart& c, const std::string& prefix) {
  for (const std::string& t : texts_of(c))
    if (t.rfind(prefix, 0) == 0) return true;
  return false;
}

}  // namespace

TEST_CASE("chart: nice ticks on 1-2-5 steps over analytic ranges", "[chart]") {
  struct Case {
    double lo, hi, step, first, last;
    int decimals;
  };
  const Case cases[] = {
      {0, 1, 0.2, 0, 1, 1},                      // 5 intervals of 0.2
      {0, 10, 2, 0, 10, 0},                      //
      {17.2, 29.8, 5, 15, 30, 0},                // 12.6 / 6 = 2.1 -> 2 gives 6.3 intervals, so 5
      {0.36, 0.91, 0.1, 0.3, 1.0, 1},            // 0.55 / 6 -> 0.1
      {-3, 3, 1, -3, 3, 0},                      //
      {0.0012, 0.0049, 0.001, 0.001, 0.005, 3},  // 5 x 10^-4 gives 7.4 intervals
      {1500, 1500, 50, 1400, 1600, 0},           // zero width: +-5% = [1425, 1575]
      {3, 1, 0.5, 1, 3, 1},                      // reversed
  };
  for (const Case& c : cases) {
    INFO(c.lo << " .. " << c.hi);
    const Ticks t = nice_ticks(c.lo, c.hi);
    CHECK(t.step == Approx(c.step));
    CHECK(t.first == Approx(c.first).margin(1e-12));
    CHECK(t.last == Approx(c.last));
    CHECK(t.decimals == c.decimals);
    REQUIRE(t.values.size() == size_t(std::lround((t.last - t.first) / t.step)) + 1);
    CHECK(t.values.front() == Approx(t.first).margin(1e-12));
    CHECK(t.values.back() == Approx(t.last));
  }
  const Ticks bad = nice_ticks(NAN, 1);
  CHECK(bad.first == 0);
  CHECK(bad.last == Approx(1));
  // Properties on random ranges: the axis covers the data, the step is 1, 2 or 5 x 10^k, at
  // most `target` intervals over the data (+2 from rounding outwards).
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3, 3);
  for (int i = 0; i < 200; ++i) {
    const double scale = std::pow(10.0, u(rng));
    const double lo = u(rng) * scale, hi = lo + std::fabs(u(rng)) * scale + 1e-9 * scale;
    const Ticks t = nice_ticks(lo, hi, 6);
    INFO(lo << " .. " << hi << " step " << t.step);
    CHECK(t.first <= lo + 1e-9 * scale);
    CHECK(t.last >= hi - 1e-9 * scale);
    const double mant = t.step / std::pow(10.0, std::floor(std::log10(t.step) + 1e-9));
    CHECK((std::fabs(mant - 1) < 1e-6 || std::fabs(mant - 2) < 1e-6 || std::fabs(mant - 5) < 1e-6));
    CHECK(t.values.size() <= 6 + 3);
  }
  CHECK(tick_label(-0.0001, 2) == "0.00");
  CHECK(tick_label(2.5, 1) == "2.5");
  CHECK(tick_label(-3, 0) == "-3");
}

TEST_CASE("chart: the legend goes to the corner with no data, else outside", "[chart]") {
  PlotFrame f;
  const std::vector<LegendEntry> entries = {{LegendEntry::kLine, "3dgs", 0x1f77b4},
                                            {LegendEntry::kLine, "transfer-whole", 0xd62728}};
  // Data crowding the top right and the bottom left: the legend takes the top left.
  std::vector<std::pair<double, double>> pts;
  for (int i = 0; i < 20; ++i) {
    pts.push_back({f.plot_right() - 5 - 8 * i, f.top + 5 + 4 * i});
    pts.push_back({f.left + 5 + 8 * i, f.plot_bottom() - 5 - 4 * i});
  }
  PlotFrame g = f;
  const LegendBox box = place_legend(g, entries, pts);
  CHECK(box.corner == 1);
  CHECK(points_inside(box, pts) == 0);
  CHECK(g.w == f.w);  // inside: the chart keeps its size
  CHECK(box.w > text_width("transfer-whole", 11));
  // Points in every corner: outside right, and the chart grows by about the legend's width.
  for (double x : {f.left + 20, f.plot_right() - 20})
    for (double y : {f.top + 15, f.plot_bottom() - 15})
      for (int k = 0; k < 9; ++k) pts.push_back({x + 10 * (k % 3) - 10, y + 5 * (k / 3) - 5});
  PlotFrame h = f;
  const LegendBox out = place_legend(h, entries, pts);
  CHECK(out.corner == 4);
  CHECK(out.x >= f.plot_right());
  CHECK(h.w >= f.w + out.w);
  CHECK(h.px(3.0) == Approx(f.px(3.0)));  // data positions unchanged
  CHECK(points_inside(out, pts) == 0);
}

TEST_CASE("chart: antialiased raster with the expected colours at computed positions", "[chart]") {
  Chart c;
  c.width = 120, c.height = 80;
  c.add(Chart::Rect{10, 10, 40, 30, 0xff0000});
  c.add(Chart::Line{0, 79, 119, 0, 0x0000ff, 1.5});
  c.add(Chart::Circle{90, 60, 6, 0x00aa00});
  c.add(Chart::Text{60, 75, "Abc 12", 0x000000, 0, 12});
  for (double scale : {1.0, 2.0}) {
    INFO("scale " << scale);
    const gs::Image img = render_chart(c, scale);
    REQUIRE(img.width == int(120 * scale));
    REQUIRE(img.height == int(80 * scale));
    const auto at = [&](double x, double y) { return pixel(img, int(y * scale), int(x * scale)); };
    CHECK(at(1, 1) == 0xffffff);    // background
    CHECK(at(20, 20) == 0xff0000);  // inside the rectangle (the line passes elsewhere)
    CHECK(at(90, 60) == 0x00aa00);  // the disc's centre
    CHECK(at(90, 52) == 0xffffff);  // just outside its radius
    // The line: blends of blue over white (r = g strictly between 0 and 255, b = 255) on its
    // edges: antialiased, not a binary line.
    std::set<uint32_t> levels;
    for (int y = 0; y < img.height; ++y)
      for (int x = int(60 * scale); x < int(100 * scale); ++x) {
        const uint32_t p = pixel(img, y, x), r = p >> 16, g = (p >> 8) & 255, bl = p & 255;
        if (r == g && bl == 255 && r > 0 && r < 255) levels.insert(r);
      }
    CHECK(levels.size() >= 3);
    // Text: black ink with grey edge levels in its box.
    std::set<uint32_t> greys;
    bool dark = false;
    for (int y = int(62 * scale); y < int(78 * scale); ++y)
      for (int x = int(35 * scale); x < int(85 * scale); ++x) {
        const uint32_t p = pixel(img, y, x), r = p >> 16;
        if (p == r * 0x010101 && r > 0 && r < 255) greys.insert(r);
        dark = dark || r < 60;
      }
    CHECK(dark);
    CHECK(greys.size() >= 3);
  }
}

TEST_CASE("chart: SVG and PDF documents", "[chart]") {
  Chart c;
  c.width = 200, c.height = 100;
  c.title = "Tiny <chart> & test";
  c.add(Chart::Line{0, 50, 200, 50, 0x00ff00, 1});
  c.add(Chart::Text{10, 30, "hello", 0x222222});
  const std::string svg = chart_svg(c);
  CHECK(svg.rfind("<?xml", 0) == 0);
  CHECK(svg.find("<svg") != std::string::npos);
  CHECK(svg.find("width=\"200px\"") != std::string::npos);
  CHECK(svg.find("<title>Tiny &lt;chart&gt; &amp; test</title>") != std::string::npos);
  CHECK(svg.find("glyph") != std::string::npos);            // text as glyph outlines
  CHECK(svg.find("rgb(0%,100%,0%)") != std::string::npos);  // the line's colour
  CHECK(svg.find("</svg>") != std::string::npos);
  const std::string pdf = chart_pdf(c);
  CHECK(pdf.rfind("%PDF-1.", 0) == 0);
  CHECK(pdf.find("/Title (Tiny <chart> & test)") != std::string::npos);
  CHECK(pdf.find("/Font") != std::string::npos);  // the text's embedded font
  CHECK(pdf.find("%%EOF") != std::string::npos);
  // Without text there is no font.
  Chart bare;
  bare.add(Chart::Line{0, 0, 10, 10, 0, 1});
  CHECK(chart_pdf(bare).find("/Font") == std::string::npos);
  CHECK(chart_svg(bare).find("glyph") == std::string::npos);
}

TEST_CASE("chart: a chart with no data says not computed and why", "[chart]") {
  const Chart c = not_computed_chart("LPIPS vs zoom factor", "LPIPS-Alex backbone not supplied");
  CHECK(has_text_starting(c, "not computed: LPIPS-Alex backbone not supplied"));
  CHECK(c.title.find("not computed") != std::string::npos);
  const gs::Image img = render_chart(c, 1);
  PlotFrame f;
  size_t ink = 0;  // dark text pixels in the middle band of the plot area
  for (int y = int((f.top + f.plot_bottom()) / 2) - 12; y < int((f.top + f.plot_bottom()) / 2) + 8;
       ++y)
    for (int x = int(f.left); x < int(f.plot_right()); ++x) ink += pixel(img, y, x) < 0xb0b0b0;
  CHECK(ink > 100);
  // A long reason wraps onto several lines inside the frame.
  const Chart w = not_computed_chart(
      "t", std::string(30, 'x') + " " + std::string(400, 'y') + " " + std::string(30, 'z'));
  CHECK(texts_of(w).size() >= 4);  // title + 3 lines

  // The report's charts of a metric nobody computed say so, with the records' reason.
  ConfigResult cfg;
  cfg.label = "3dgs";
  cfg.metric["psnr"] = 20;
  cfg.seconds_per_closeup = 0.1;
  cfg.not_computed["lpips_alex"] = "backbone missing";
  cfg.pairs.push_back({"A", 2.0, {{"psnr", 20.0}}});
  cfg.scene_means["A"]["psnr"] = 20;
  const MetricColumn lpips = metric_columns()[2];
  for (const Chart& ch : {chart_time_vs_metric({cfg}, lpips), chart_metric_vs_zoom({cfg}, lpips),
                          chart_scene_bars({cfg}, lpips)})
    CHECK(has_text_starting(ch, "not computed: backbone missing"));
  CHECK_FALSE(has_text_starting(chart_time_vs_metric({cfg}, metric_columns()[0]), "not computed"));
}

TEST_CASE("chart: report charts put points, bars and legends where the data says", "[chart]") {
  // Two configurations over two scenes: the scatter's points sit at (seconds, mean of scene
  // means), with +-1 s.d. bars; the zoom chart has a point per distinct zoom.
  std::vector<ConfigResult> configs(2);
  const double psnr[2][2] = {{20, 24}, {21, 27}};
  for (int i = 0; i < 2; ++i) {
    ConfigResult& c = configs[size_t(i)];
    c.label = i == 0 ? "3dgs" : "transfer";
    c.seconds_per_closeup = i == 0 ? 0.2 : 2.4;
    c.metric["psnr"] = (psnr[i][0] + psnr[i][1]) / 2;
    for (int s = 0; s < 2; ++s) {
      const std::string scene = s == 0 ? "scene_a" : "scene_b";
      c.scene_means[scene]["psnr"] = psnr[i][s];
      for (double zoom : {1.5, 3.0}) c.pairs.push_back({scene, zoom, {{"psnr", psnr[i][s]}}});
    }
  }
  const MetricColumn m = metric_columns()[0];
  const Chart scatter = chart_time_vs_metric(configs, m);
  const gs::Image img = render_chart(scatter, 1);
  int discs = 0;
  for (const Chart::Shape& s : scatter.shapes)
    if (auto* c = std::get_if<Chart::Circle>(&s); c && c->r > 5) {
      ++discs;
      CHECK(pixel(img, int(c->y), int(c->x)) == c->rgb);  // drawn, not covered
    }
  CHECK(discs == 2);
  CHECK(has_text_starting(scatter,
                          "points: mean of the scene means over 2 scenes; bars: \u00b11 s.d."));
  CHECK(has_text_starting(scatter, "PSNR (dB, higher is better)"));
  CHECK(has_text_starting(scatter, "seconds per close-up (s"));
  // transfer: mean 24 at 2.4 s, s.d. of {21, 27} = 4.243: its bar spans 19.76 .. 28.24 in data.
  const Chart zoom = chart_metric_vs_zoom(configs, m);
  size_t polylines = 0;
  for (const Chart::Shape& s : zoom.shapes)
    if (auto* p = std::get_if<Chart::Polyline>(&s)) {
      ++polylines;
      CHECK(p->points.size() == 2);  // the two distinct zooms
    }
  CHECK(polylines == 2);
  CHECK(has_text_starting(zoom, "zoom factor (depth ratio"));
  const Chart bars = chart_scene_bars(configs, m);
  size_t filled = 0;
  for (const Chart::Shape& s : bars.shapes)
    if (auto* r = std::get_if<Chart::Rect>(&s); r && r->h > 20 && r->rgb == chart_palette(1))
      ++filled;
  CHECK(filled == 2);                               // transfer's bar in each scene
  CHECK(has_text_starting(bars, "scene (scene_"));  // the common prefix goes to the label
  CHECK(has_text_starting(bars, "a"));
  // Non-negative data never gets a negative axis (a ratio of 0.02 .. 0.7 starts at 0).
  for (ConfigResult& c : configs)
    for (auto& p : c.pairs) p.values["grad_ratio"] = p.zoom < 2 ? 0.7 : 0.02;
  const Chart ratio = chart_metric_vs_zoom(configs, metric_columns()[5]);
  CHECK(has_text_starting(ratio, "0.0"));
  CHECK_FALSE(has_text_starting(ratio, "-"));
}

}  // namespace macro::enhance
