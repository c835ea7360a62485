// The benchmark report's charts (report_charts.h).
#include "enhance/bench/report_charts.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <set>

#include "enhance/figures/plot.h"

namespace macro::enhance {
namespace {

using Points = std::vector<std::pair<double, double>>;

struct Stats {
  double mean = 0, sd = 0;
  size_t n = 0;
};
Stats stats_of(const std::vector<double>& v) {
  Stats s;
  s.n = v.size();
  if (v.empty()) return s;
  for (double x : v) s.mean += x;
  s.mean /= double(v.size());
  if (v.size() > 1) {
    double ss = 0;
    for (double x : v) ss += (x - s.mean) * (x - s.mean);
    s.sd = std::sqrt(ss / double(v.size() - 1));  // sample standard deviation
  }
  return s;
}

std::string not_computed_reason(const std::vector<ConfigResult>& configs, const MetricColumn& m) {
  if (configs.empty()) return "no benchmark records";
  for (const ConfigResult& c : configs) {
    auto it = c.not_computed.find(m.name);
    if (it != c.not_computed.end()) return it->second;
  }
  return std::string("no pair has a finite ") + m.title;
}

std::optional<double> finite_metric(const ConfigResult& c, const std::string& name) {
  auto it = c.metric.find(name);
  if (it == c.metric.end() || !std::isfinite(it->second)) return std::nullopt;
  return it->second;
}

// Data range [lo, hi] -> ticks, padded by `pad` of the span on both sides first (never below 0
// for data that is not: ratios and scores do not get a negative axis).
Ticks ticks_for(double lo, double hi, double pad = 0.04, int target = 6) {
  const double span = hi - lo;
  const double padded_lo = lo >= 0 ? std::max(0.0, lo - pad * span) : lo - pad * span;
  return nice_ticks(padded_lo, hi + pad * span, target);
}

void error_bar(Chart& c, double x, double y_lo, double y_hi, uint32_t rgb, Points* occupied) {
  c.add(Chart::Line{x, y_lo, x, y_hi, rgb, 1.2});
  c.add(Chart::Line{x - 3.5, y_lo, x + 3.5, y_lo, rgb, 1.2});
  c.add(Chart::Line{x - 3.5, y_hi, x + 3.5, y_hi, rgb, 1.2});
  for (double t = 0; t <= 1.0; t += 0.25) occupied->push_back({x, y_lo + t * (y_hi - y_lo)});
}

struct Box {
  double x0, y0, x1, y1;
  bool overlaps(const Box& o) const { return x0 < o.x1 && o.x0 < x1 && y0 < o.y1 && o.y0 < y1; }
};

}  // namespace

std::string metric_axis_label(const MetricColumn& m) {
  const std::string unit = std::string(m.name) == "psnr" ? "dB, " : "";
  if (m.target_one) return std::string(m.title) + " (" + unit + "1 is best)";
  return std::string(m.title) + " (" + unit +
         (m.higher_better ? "higher is better)" : "lower is better)");
}

// ---- Speed vs accuracy -------------------------------------------------------------------------
Chart chart_time_vs_metric(const std::vector<ConfigResult>& configs, const MetricColumn& m,
                           bool full_cost) {
  const std::string title =
      std::string(full_cost ? "Full cost per close-up vs " : "Seconds per close-up vs ") + m.title;
  const auto cost = [full_cost](const ConfigResult& c) {
    return full_cost ? c.full_seconds_per_closeup : c.seconds_per_closeup;
  };
  struct Point {
    size_t config;
    double x, y;
    Stats scenes;
  };
  std::vector<Point> pts;
  for (size_t i = 0; i < configs.size(); ++i) {
    auto v = finite_metric(configs[i], m.name);
    if (!v || !cost(configs[i])) continue;
    std::vector<double> means;
    for (const auto& [scene, values] : configs[i].scene_means) {
      auto it = values.find(m.name);
      if (it != values.end() && std::isfinite(it->second)) means.push_back(it->second);
    }
    pts.push_back({i, *cost(configs[i]), *v, stats_of(means)});
  }
  if (pts.empty()) return not_computed_chart(title, not_computed_reason(configs, m));
  double xhi = 0, ylo = 1e300, yhi = -1e300;
  size_t max_scenes = 0;
  bool any_sd = false;
  for (const Point& p : pts) {
    xhi = std::max(xhi, p.x);
    ylo = std::min(ylo, p.y - p.scenes.sd), yhi = std::max(yhi, p.y + p.scenes.sd);
    max_scenes = std::max(max_scenes, p.scenes.n);
    any_sd = any_sd || p.scenes.n > 1;
  }
  const Ticks xt = nice_ticks(0, xhi * 1.12 + 1e-9);
  const Ticks yt = ticks_for(ylo, yhi, 0.08);
  PlotFrame f;
  f.x0 = xt.first, f.x1 = xt.last, f.y0 = yt.first, f.y1 = yt.last;
  AxisText text{title,
                "points: mean of the scene means over " + std::to_string(max_scenes) +
                    (max_scenes == 1 ? " scene" : " scenes") +
                    (any_sd ? "; bars: \u00b11 s.d. of the scene means" : ""),
                full_cost ? "seconds per close-up of a new scene (s, training + method)"
                          : "seconds per close-up (s, render + plan + enhance)",
                metric_axis_label(m)};
  Chart c;
  draw_axes(c, f, &xt, yt, text);
  Points occupied;
  std::vector<Box> taken;
  for (const Point& p : pts) {
    const double x = f.px(p.x), y = f.py(p.y);
    taken.push_back({x - 6, y - 6, x + 6, y + 6});
    if (p.scenes.n > 1) {
      const double y0 = f.py(p.y - p.scenes.sd), y1 = f.py(p.y + p.scenes.sd);
      error_bar(c, x, y0, y1, chart_palette(p.config), &occupied);
      taken.push_back({x - 4, std::min(y0, y1), x + 4, std::max(y0, y1)});
    }
  }
  for (const Point& p : pts)
    c.add(Chart::Circle{f.px(p.x), f.py(p.y), 5.5, chart_palette(p.config), 1, 0xffffff});
  // Labels: the first of right, left, above, below, and the four diagonals that stays inside the
  // plot and clear of every point, bar and earlier label.
  for (const Point& p : pts) {
    const std::string& label = configs[p.config].label;
    const double x = f.px(p.x), y = f.py(p.y), w = text_width(label, 11), h = 11;
    struct Candidate {
      double dx, dy;
      int anchor;
    };
    const Candidate cands[] = {{9, 4, -1},  {-9, 4, 1},  {0, -10, 0}, {0, 19, 0},
                               {7, -8, -1}, {-7, -8, 1}, {7, 16, -1}, {-7, 16, 1}};
    const Candidate* chosen = &cands[0];
    Box chosen_box{};
    for (const Candidate& cand : cands) {
      const double left = cand.anchor < 0   ? x + cand.dx
                          : cand.anchor > 0 ? x + cand.dx - w
                                            : x + cand.dx - w / 2;
      const Box b{left, y + cand.dy - h, left + w, y + cand.dy + 2};
      bool ok = b.x0 >= f.left + 2 && b.x1 <= f.plot_right() - 2 && b.y0 >= f.top &&
                b.y1 <= f.plot_bottom() - 2;
      for (const Box& t : taken) ok = ok && !b.overlaps(t);
      if (ok) {
        chosen = &cand, chosen_box = b;
        break;
      }
      if (&cand == &cands[0]) chosen_box = b;
    }
    taken.push_back(chosen_box);
    c.add(Chart::Text{x + chosen->dx, y + chosen->dy, label, kChartInk, chosen->anchor, 11});
  }
  return c;
}

// ---- Metric vs zoom ----------------------------------------------------------------------------
Chart chart_metric_vs_zoom(const std::vector<ConfigResult>& configs, const MetricColumn& m) {
  const std::string title = std::string(m.title) + " vs zoom factor";
  std::vector<double> zooms;
  for (const ConfigResult& c : configs)
    for (const auto& p : c.pairs) {
      auto it = p.values.find(m.name);
      if (it != p.values.end() && std::isfinite(it->second) && std::isfinite(p.zoom))
        zooms.push_back(p.zoom);
    }
  if (zooms.empty()) return not_computed_chart(title, not_computed_reason(configs, m));
  std::sort(zooms.begin(), zooms.end());
  std::vector<double> distinct;
  for (double z : zooms)
    if (distinct.empty() || z - distinct.back() > 1e-6) distinct.push_back(z);
  const bool by_value = distinct.size() <= 12;
  const double zlo = zooms.front(), zhi = zooms.back();
  constexpr int kEqualBins = 8;
  const int bins = by_value ? int(distinct.size()) : kEqualBins;
  const auto bin_of = [&](double z) {
    if (by_value)
      return int(std::lower_bound(distinct.begin(), distinct.end(), z - 1e-6) - distinct.begin());
    return std::clamp(int((z - zlo) / (zhi - zlo) * kEqualBins), 0, kEqualBins - 1);
  };
  // The bin's x: its zoom value, or the mean zoom of every pair in it.
  std::vector<double> bin_x(size_t(bins), 0), bin_n(size_t(bins), 0);
  for (double z : zooms) bin_x[size_t(bin_of(z))] += z, bin_n[size_t(bin_of(z))] += 1;
  for (int b = 0; b < bins; ++b) bin_x[size_t(b)] /= std::max(1.0, bin_n[size_t(b)]);

  struct Curve {
    std::vector<std::pair<double, Stats>> points;  // (bin x, stats over scenes)
  };
  std::vector<Curve> curves(configs.size());
  double ylo = 1e300, yhi = -1e300;
  bool any_sd = false;
  for (size_t i = 0; i < configs.size(); ++i) {
    std::map<int, std::map<std::string, std::vector<double>>> per_bin;  // bin -> scene -> values
    for (const auto& p : configs[i].pairs) {
      auto it = p.values.find(m.name);
      if (it == p.values.end() || !std::isfinite(it->second) || !std::isfinite(p.zoom)) continue;
      per_bin[bin_of(p.zoom)][p.scene].push_back(it->second);
      ylo = std::min(ylo, it->second), yhi = std::max(yhi, it->second);
    }
    for (const auto& [b, scenes] : per_bin) {
      std::vector<double> means;
      for (const auto& [scene, v] : scenes) means.push_back(stats_of(v).mean);
      const Stats s = stats_of(means);
      any_sd = any_sd || s.n > 1;
      ylo = std::min(ylo, s.mean - s.sd), yhi = std::max(yhi, s.mean + s.sd);
      curves[i].points.push_back({bin_x[size_t(b)], s});
    }
  }
  const Ticks xt = ticks_for(zlo, zhi, 0.05);
  const Ticks yt = ticks_for(ylo, yhi, 0.05);
  PlotFrame f;
  f.x0 = xt.first, f.x1 = xt.last, f.y0 = yt.first, f.y1 = yt.last;
  const double n = double(configs.size());
  const auto dodge = [&](size_t i) { return (double(i) - (n - 1) / 2) * 5.0; };
  // What the legend must not cover: pair dots, bin means, bars, and the lines between them.
  Points occupied;
  for (size_t i = 0; i < configs.size(); ++i) {
    for (const auto& p : configs[i].pairs) {
      auto it = p.values.find(m.name);
      if (it != p.values.end() && std::isfinite(it->second))
        occupied.push_back({f.px(p.zoom) + dodge(i), f.py(it->second)});
    }
    const auto& pts = curves[i].points;
    for (size_t k = 0; k < pts.size(); ++k) {
      const double x = f.px(pts[k].first) + dodge(i), y = f.py(pts[k].second.mean);
      occupied.push_back({x, f.py(pts[k].second.mean - pts[k].second.sd)});
      occupied.push_back({x, f.py(pts[k].second.mean + pts[k].second.sd)});
      if (k + 1 < pts.size()) {
        const double x1 = f.px(pts[k + 1].first) + dodge(i), y1 = f.py(pts[k + 1].second.mean);
        const int steps = std::max(1, int(std::hypot(x1 - x, y1 - y) / 5));
        for (int s = 0; s <= steps; ++s)
          occupied.push_back({x + (x1 - x) * s / steps, y + (y1 - y) * s / steps});
      }
    }
  }
  std::vector<LegendEntry> entries;
  for (size_t i = 0; i < configs.size(); ++i)
    entries.push_back({LegendEntry::kLine, configs[i].label, chart_palette(i)});
  const LegendBox legend = place_legend(f, entries, occupied);
  AxisText text{title,
                std::string("lines: per zoom, the mean over scenes of each scene's mean") +
                    (any_sd ? "; bars: \u00b11 s.d. over scenes" : "") + "; dots: single pairs",
                by_value ? "zoom factor (depth ratio, \u00d7)"
                         : "zoom factor (depth ratio, \u00d7; 8 equal-width bins)",
                metric_axis_label(m)};
  Chart c;
  draw_axes(c, f, &xt, yt, text);
  for (size_t i = 0; i < configs.size(); ++i)
    for (const auto& p : configs[i].pairs) {
      auto it = p.values.find(m.name);
      if (it != p.values.end() && std::isfinite(it->second))
        c.add(
            Chart::Circle{f.px(p.zoom) + dodge(i), f.py(it->second), 2.2, chart_palette(i), 0.28});
    }
  for (size_t i = 0; i < configs.size(); ++i) {
    Chart::Polyline line{{}, chart_palette(i), 2};
    Points unused;
    for (const auto& [zx, s] : curves[i].points) {
      const double x = f.px(zx) + dodge(i);
      line.points.push_back({x, f.py(s.mean)});
      if (s.n > 1)
        error_bar(c, x, f.py(s.mean - s.sd), f.py(s.mean + s.sd), chart_palette(i), &unused);
    }
    c.add(line);
    for (const auto& [x, y] : line.points)
      c.add(Chart::Circle{x, y, 3.5, chart_palette(i), 1, 0xffffff});
  }
  draw_legend(c, legend, entries);
  return c;
}

// ---- Per-scene bars ----------------------------------------------------------------------------
Chart chart_scene_bars(const std::vector<ConfigResult>& configs, const MetricColumn& m) {
  const std::string title = std::string(m.title) + " per scene";
  std::set<std::string> scene_set;
  double ylo = 0, yhi = -1e300;
  for (const ConfigResult& c : configs)
    for (const auto& [scene, means] : c.scene_means) {
      auto it = means.find(m.name);
      if (it == means.end() || !std::isfinite(it->second)) continue;
      scene_set.insert(scene);
      ylo = std::min(ylo, it->second), yhi = std::max(yhi, it->second);
    }
  if (scene_set.empty()) return not_computed_chart(title, not_computed_reason(configs, m));
  const std::vector<std::string> scenes(scene_set.begin(), scene_set.end());
  // Whiskers: min-max over each scene's pairs.
  std::vector<std::map<std::string, std::pair<double, double>>> range(configs.size());
  std::vector<std::map<std::string, size_t>> count(configs.size());
  bool any_whisker = false;
  for (size_t i = 0; i < configs.size(); ++i)
    for (const auto& p : configs[i].pairs) {
      auto it = p.values.find(m.name);
      if (it == p.values.end() || !std::isfinite(it->second)) continue;
      auto [r, fresh] = range[i].try_emplace(p.scene, it->second, it->second);
      r->second.first = std::min(r->second.first, it->second);
      r->second.second = std::max(r->second.second, it->second);
      if (++count[i][p.scene] > 1) any_whisker = true;
      ylo = std::min(ylo, it->second), yhi = std::max(yhi, it->second);
    }
  // Scene names without their common prefix ("synthclose_03" -> "03"), the prefix in the label.
  std::string prefix = scenes.size() > 1 ? scenes[0] : "";
  for (const std::string& s : scenes)
    while (!prefix.empty() && (s.size() <= prefix.size() || s.compare(0, prefix.size(), prefix)))
      prefix.pop_back();
  if (prefix.size() < 3) prefix.clear();
  const double nconf = double(std::max<size_t>(configs.size(), 1));
  double label_w = 0;
  for (const std::string& s : scenes)
    label_w = std::max(label_w, text_width(s.substr(prefix.size()), 11));
  const double slot = std::max(nconf * 13 + 16, label_w + 10);
  const Ticks yt = nice_ticks(ylo, yhi + 0.04 * (yhi - ylo));
  PlotFrame f;
  f.w = std::max(640, int(f.left + f.right + slot * double(scenes.size())));
  f.x0 = 0, f.x1 = double(scenes.size()), f.y0 = yt.first, f.y1 = yt.last;
  const double bar = std::min(30.0, (f.px(1) - f.px(0) - 16) / nconf);
  const auto bar_x = [&](size_t s, size_t i) {
    return f.px(double(s) + 0.5) - bar * nconf / 2 + bar * double(i);
  };
  Points occupied;
  for (size_t s = 0; s < scenes.size(); ++s)
    for (size_t i = 0; i < configs.size(); ++i) {
      auto sc = configs[i].scene_means.find(scenes[s]);
      if (sc == configs[i].scene_means.end() || !sc->second.count(m.name)) continue;
      double top = sc->second.at(m.name);
      if (auto r = range[i].find(scenes[s]); r != range[i].end())
        top = std::max(top, r->second.second);
      for (double y = std::max(0.0, f.y0);; y += (top - std::max(0.0, f.y0)) / 8) {
        occupied.push_back({bar_x(s, i) + bar / 2, f.py(y)});
        if (y >= top) break;
      }
    }
  std::vector<LegendEntry> entries;
  for (size_t i = 0; i < configs.size(); ++i)
    entries.push_back({LegendEntry::kBox, configs[i].label, chart_palette(i)});
  const LegendBox legend = place_legend(f, entries, occupied);
  AxisText text{title,
                std::string("bars: the scene's mean over its pairs") +
                    (any_whisker ? "; whiskers: min\u2013max over the scene's pairs" : ""),
                prefix.empty() ? "scene" : "scene (" + prefix + "\u2026)", metric_axis_label(m)};
  Chart c;
  draw_axes(c, f, nullptr, yt, text);
  const double base = f.py(std::clamp(0.0, f.y0, f.y1));
  for (size_t s = 0; s < scenes.size(); ++s) {
    c.add(Chart::Line{f.px(double(s) + 0.5), f.plot_bottom(), f.px(double(s) + 0.5),
                      f.plot_bottom() + 4, kChartInk, 1});
    c.add(Chart::Text{f.px(double(s) + 0.5), f.plot_bottom() + 17, scenes[s].substr(prefix.size()),
                      kChartInk, 0, 11});
    for (size_t i = 0; i < configs.size(); ++i) {
      auto sc = configs[i].scene_means.find(scenes[s]);
      if (sc == configs[i].scene_means.end()) continue;
      auto it = sc->second.find(m.name);
      if (it == sc->second.end() || !std::isfinite(it->second)) continue;
      const double x = bar_x(s, i), y = f.py(it->second);
      c.add(Chart::Rect{x, std::min(y, base), bar - 1.5, std::fabs(base - y), chart_palette(i)});
      auto r = range[i].find(scenes[s]);
      if (r != range[i].end() && count[i][scenes[s]] > 1) {
        const double cx = x + (bar - 1.5) / 2;
        c.add(Chart::Line{cx, f.py(r->second.first), cx, f.py(r->second.second), kChartInk, 1});
        c.add(Chart::Line{cx - 2.5, f.py(r->second.first), cx + 2.5, f.py(r->second.first),
                          kChartInk, 1});
        c.add(Chart::Line{cx - 2.5, f.py(r->second.second), cx + 2.5, f.py(r->second.second),
                          kChartInk, 1});
      }
    }
  }
  draw_legend(c, legend, entries);
  return c;
}

}  // namespace macro::enhance
