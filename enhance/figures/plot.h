// The pieces every plot shares, on top of the chart model (chart.h): the palette, nice tick
// values (1-2-5 steps), a plot frame that maps data to chart units, the axes with their labels,
// a legend placed where it covers no data, and the "not computed" chart.
//
// Layout units are chart units (CSS pixels); y grows downwards in the chart, upwards in the data.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "enhance/figures/chart.h"

namespace macro::enhance {

inline constexpr uint32_t kChartInk = 0x222222, kChartMuted = 0x666666, kChartGrid = 0xe4e4e4;
uint32_t chart_palette(size_t i);  // the ten matplotlib "tab10" colours (own order), cycled

// Tick values on a 1-2-5 grid: step = {1, 2, 5} x 10^k, the smallest giving at most `target`
// intervals over [lo, hi]; the axis [first, last] is [lo, hi] rounded outwards to the step.
// A zero-width or reversed range is widened first (+-5% of |lo|, or +-0.5 at 0); non-finite
// bounds give [0, 1].
struct Ticks {
  double first = 0, last = 1, step = 0.2;
  std::vector<double> values;  // first, first + step, ..., last
  int decimals = 1;            // enough to tell the ticks apart (max(0, -floor(log10 step)))
};
Ticks nice_ticks(double lo, double hi, int target = 6);
std::string tick_label(double v, int decimals);  // "%.*f", and "0" rather than "-0"

// The plot area inside a chart of w x h units (margins around it) and the data range it shows.
struct PlotFrame {
  double left = 72, top = 56, right = 24, bottom = 56;
  double x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  int w = 640, h = 420;
  double px(double x) const { return left + (x - x0) / (x1 - x0) * (w - left - right); }
  double py(double y) const { return h - bottom - (y - y0) / (y1 - y0) * (h - top - bottom); }
  double plot_right() const { return w - right; }
  double plot_bottom() const { return h - bottom; }
};

struct AxisText {
  std::string title;     // bold, top left
  std::string subtitle;  // one smaller grey line under the title (what the marks mean)
  std::string xlabel, ylabel;
};

// Sizes `chart` to the frame, sets its title and draws the grid at the ticks, the left and bottom
// axes with outward tick marks and labels (x ticks only when `xticks` is non-null), the axis
// labels (y rotated) and the title lines. Call before adding data so the data draws on top.
void draw_axes(Chart& chart, const PlotFrame& frame, const Ticks* xticks, const Ticks& yticks,
               const AxisText& text);

struct LegendEntry {
  enum Kind { kLine, kMarker, kBox } kind;
  std::string label;
  uint32_t rgb;
};
struct LegendBox {
  double x = 0, y = 0, w = 0, h = 0;
  int corner = 0;  // 0 top right, 1 top left, 2 bottom right, 3 bottom left (inside), 4 outside
};
// The legend's size for `entries`, then its place: the inside corner of the plot whose box covers
// the fewest of `occupied` (data positions in chart units; ties: top right, top left, bottom
// right, bottom left), or outside right of the plot when every corner covers some and
// `allow_outside`; then `frame` (and the chart width drawn from it) grows by the legend's width.
LegendBox place_legend(PlotFrame& frame, const std::vector<LegendEntry>& entries,
                       const std::vector<std::pair<double, double>>& occupied,
                       bool allow_outside = true);
size_t points_inside(const LegendBox& box, const std::vector<std::pair<double, double>>& points,
                     double margin = 4);
void draw_legend(Chart& chart, const LegendBox& box, const std::vector<LegendEntry>& entries);

// A titled chart whose plot area says "not computed: <reason>" (a figure that cannot be drawn
// says why instead of showing an empty frame).
Chart not_computed_chart(const std::string& title, const std::string& reason, int w = 640,
                         int h = 420);

}  // namespace macro::enhance
