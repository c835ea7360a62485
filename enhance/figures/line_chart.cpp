// Line charts over the shared axes (line_chart.h).
#include "enhance/figures/line_chart.h"

#include <algorithm>
#include <cmath>

namespace macro::enhance {

std::vector<double> running_mean(const std::vector<double>& values, int window) {
  std::vector<double> out(values.size(), NAN);
  const size_t w = size_t(std::max(1, window));
  double sum = 0;
  size_t n = 0;
  for (size_t i = 0; i < values.size(); ++i) {
    if (std::isfinite(values[i])) sum += values[i], ++n;
    if (i >= w && std::isfinite(values[i - w])) sum -= values[i - w], --n;
    if (n > 0) out[i] = sum / double(n);
  }
  return out;
}

Chart line_chart(const LineChartSpec& spec) {
  double xlo = INFINITY, xhi = -INFINITY, ylo = INFINITY, yhi = -INFINITY;
  for (const LineSeries& s : spec.series)
    for (const auto& [x, y] : s.points) {
      if (!std::isfinite(x) || !std::isfinite(y)) continue;
      xlo = std::min(xlo, x), xhi = std::max(xhi, x);
      ylo = std::min(ylo, y), yhi = std::max(yhi, y);
    }
  if (!std::isfinite(xlo))
    return not_computed_chart(spec.text.title, "no finite values", spec.width, spec.height);
  if (spec.y_from_zero) ylo = std::min(ylo, 0.0);
  const double ypad = 0.04 * (yhi - ylo);
  const Ticks xt = nice_ticks(xlo, xhi);
  const Ticks yt = nice_ticks(spec.y_from_zero && ylo >= 0 ? ylo : ylo - ypad, yhi + ypad);
  PlotFrame f;
  f.w = spec.width, f.h = spec.height;
  f.x0 = xt.first, f.x1 = xt.last, f.y0 = yt.first, f.y1 = yt.last;

  // What the legend must not cover: every drawn point, and the segments between them.
  std::vector<std::pair<double, double>> occupied;
  std::vector<LegendEntry> entries;
  for (const LineSeries& s : spec.series) {
    bool any = false;
    double px = NAN, py = NAN;
    for (const auto& [x, y] : s.points) {
      if (!std::isfinite(x) || !std::isfinite(y)) {
        px = NAN;
        continue;
      }
      any = true;
      const double cx = f.px(x), cy = f.py(y);
      if (std::isfinite(px) && !s.markers) {
        const int steps = std::max(1, int(std::hypot(cx - px, cy - py) / 5));
        for (int k = 1; k < steps; ++k)
          occupied.push_back({px + (cx - px) * k / steps, py + (cy - py) * k / steps});
      }
      occupied.push_back({cx, cy});
      px = cx, py = cy;
    }
    if (any && !s.label.empty())
      entries.push_back({s.markers ? LegendEntry::kMarker : LegendEntry::kLine, s.label, s.rgb});
  }
  LegendBox legend;
  if (!entries.empty()) legend = place_legend(f, entries, occupied);

  Chart c;
  draw_axes(c, f, &xt, yt, spec.text);
  for (const LineSeries& s : spec.series) {
    Chart::Polyline line{{}, s.rgb, s.width, s.alpha};
    auto flush = [&] {
      if (line.points.size() > 1) c.add(line);
      if (line.points.size() == 1)  // a lone point between gaps: a dot of the line's width
        c.add(Chart::Circle{line.points[0].first, line.points[0].second, s.width, s.rgb, s.alpha});
      line.points.clear();
    };
    for (const auto& [x, y] : s.points) {
      if (!std::isfinite(x) || !std::isfinite(y)) {
        flush();
        continue;
      }
      if (s.markers)
        c.add(Chart::Circle{f.px(x), f.py(y), 4.5, s.rgb, s.alpha, 0xffffff});
      else
        line.points.push_back({f.px(x), f.py(y)});
    }
    flush();
  }
  if (!entries.empty()) draw_legend(c, legend, entries);
  return c;
}

}  // namespace macro::enhance
