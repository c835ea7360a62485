// Shared plot pieces (plot.h).
#include "enhance/figures/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace macro::enhance {
namespace {
constexpr uint32_t kPalette[] = {0x1f77b4, 0xd62728, 0x2ca02c, 0xff7f0e, 0x9467bd,
                                 0x8c564b, 0xe377c2, 0x17becf, 0xbcbd22, 0x7f7f7f};
constexpr double kTickFont = 11, kLabelFont = 12, kTitleFont = 14, kSubtitleFont = 10.5;
constexpr double kLegendFont = 11, kLegendRow = 17, kLegendPad = 7, kLegendSwatch = 20;
}  // namespace

uint32_t chart_palette(size_t i) {
  return kPalette[i % (sizeof kPalette / sizeof kPalette[0])];
}

Ticks nice_ticks(double lo, double hi, int target) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0, hi = 1;
  if (hi < lo) std::swap(lo, hi);
  if (hi - lo <= 1e-12 * std::max(1.0, std::fabs(lo))) {
    const double d = lo != 0 ? 0.05 * std::fabs(lo) : 0.5;
    lo -= d, hi += d;
  }
  target = std::max(target, 1);
  const double span = hi - lo;
  const double mag = std::pow(10.0, std::floor(std::log10(span / target)));
  Ticks t;
  for (double f : {1.0, 2.0, 5.0, 10.0}) {
    t.step = f * mag;
    if (span / t.step <= target + 1e-9) break;
  }
  const double k0 = std::floor(lo / t.step + 1e-9), k1 = std::ceil(hi / t.step - 1e-9);
  t.first = k0 * t.step, t.last = k1 * t.step;
  for (double k = k0; k <= k1 + 0.5; k += 1) t.values.push_back(k * t.step);
  t.decimals = std::max(0, int(-std::floor(std::log10(t.step) + 1e-9)));
  return t;
}

std::string tick_label(double v, int decimals) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  std::string s = buf;
  if (s.find_first_not_of("-0.") == std::string::npos && s[0] == '-') s.erase(0, 1);  // "-0"
  return s;
}

void draw_axes(Chart& c, const PlotFrame& f, const Ticks* xt, const Ticks& yt,
               const AxisText& text) {
  c.width = f.w, c.height = f.h;
  c.title = text.title;
  const double l = f.left, r = f.plot_right(), t = f.top, b = f.plot_bottom();
  for (double y : yt.values) {
    c.add(Chart::Line{l, f.py(y), r, f.py(y), kChartGrid, 1});
    c.add(Chart::Line{l - 4, f.py(y), l, f.py(y), kChartInk, 1});
    c.add(Chart::Text{l - 7, f.py(y) + 4, tick_label(y, yt.decimals), kChartInk, 1, kTickFont});
  }
  if (xt)
    for (double x : xt->values) {
      c.add(Chart::Line{f.px(x), t, f.px(x), b, kChartGrid, 1});
      c.add(Chart::Line{f.px(x), b, f.px(x), b + 4, kChartInk, 1});
      c.add(Chart::Text{f.px(x), b + 17, tick_label(x, xt->decimals), kChartInk, 0, kTickFont});
    }
  c.add(Chart::Line{l, b, r, b, kChartInk, 1.2});
  c.add(Chart::Line{l, t, l, b, kChartInk, 1.2});
  c.add(Chart::Text{l, 20, text.title, kChartInk, -1, kTitleFont, true});
  if (!text.subtitle.empty())
    c.add(Chart::Text{l, 37, text.subtitle, kChartMuted, -1, kSubtitleFont});
  c.add(Chart::Text{(l + r) / 2, f.h - 14.0, text.xlabel, kChartInk, 0, kLabelFont});
  c.add(Chart::Text{18, (t + b) / 2, text.ylabel, kChartInk, 0, kLabelFont, false, true});
}

size_t points_inside(const LegendBox& box, const std::vector<std::pair<double, double>>& pts,
                     double margin) {
  size_t n = 0;
  for (const auto& [x, y] : pts)
    if (x >= box.x - margin && x <= box.x + box.w + margin && y >= box.y - margin &&
        y <= box.y + box.h + margin)
      ++n;
  return n;
}

LegendBox place_legend(PlotFrame& f, const std::vector<LegendEntry>& entries,
                       const std::vector<std::pair<double, double>>& occupied, bool allow_outside) {
  LegendBox box;
  double text = 0;
  for (const LegendEntry& e : entries) text = std::max(text, text_width(e.label, kLegendFont));
  box.w = kLegendPad * 2 + kLegendSwatch + 6 + text;
  box.h = kLegendPad * 2 + kLegendRow * double(entries.size()) - 4;
  constexpr double kInset = 8;
  const double xs[2] = {f.plot_right() - kInset - box.w, f.left + kInset};
  const double ys[2] = {f.top + kInset, f.plot_bottom() - kInset - box.h};
  size_t best = SIZE_MAX;
  for (int corner = 0; corner < 4; ++corner) {
    LegendBox b = box;
    b.x = xs[corner % 2], b.y = ys[corner / 2], b.corner = corner;
    const size_t n = points_inside(b, occupied);
    if (n < best) best = n, box = b;
  }
  if (best > 0 && allow_outside) {
    const double extra = box.w + 16;
    f.w += int(std::ceil(extra));
    f.right += std::ceil(extra);
    box.x = f.plot_right() + 12, box.y = f.top, box.corner = 4;
  }
  return box;
}

void draw_legend(Chart& c, const LegendBox& box, const std::vector<LegendEntry>& entries) {
  c.add(Chart::Rect{box.x, box.y, box.w, box.h, 0xffffff, 0.9, 0xbbbbbb, 0.8});
  for (size_t i = 0; i < entries.size(); ++i) {
    const LegendEntry& e = entries[i];
    const double cy = box.y + kLegendPad + kLegendRow * double(i) + 6;
    const double sx = box.x + kLegendPad;
    switch (e.kind) {
      case LegendEntry::kLine:
        c.add(Chart::Line{sx, cy, sx + kLegendSwatch, cy, e.rgb, 2});
        c.add(Chart::Circle{sx + kLegendSwatch / 2, cy, 3.5, e.rgb, 1, 0xffffff});
        break;
      case LegendEntry::kMarker:
        c.add(Chart::Circle{sx + kLegendSwatch / 2, cy, 4.5, e.rgb, 1, 0xffffff});
        break;
      case LegendEntry::kBox:
        c.add(Chart::Rect{sx + 3, cy - 5, kLegendSwatch - 6, 10, e.rgb});
        break;
    }
    c.add(Chart::Text{sx + kLegendSwatch + 6, cy + 4, e.label, kChartInk, -1, kLegendFont});
  }
}

Chart not_computed_chart(const std::string& title, const std::string& reason, int w, int h) {
  Chart c;
  c.width = w, c.height = h;
  c.title = title + " (not computed)";
  PlotFrame f;
  f.w = w, f.h = h;
  c.add(Chart::Text{f.left, 20, title, kChartInk, -1, kTitleFont, true});
  c.add(Chart::Rect{f.left, f.top, f.plot_right() - f.left, f.plot_bottom() - f.top, 0xf6f6f6, 1,
                    0xcccccc, 1});
  // Word-wrapped to the frame's width, centred.
  constexpr double kSize = 12.5, kLine = 18;
  const double room = f.plot_right() - f.left - 32;
  std::vector<std::string> lines{""};
  std::string word;
  const std::string text = "not computed: " + reason + " ";
  for (char ch : text) {
    if (ch != ' ') {
      word += ch;
      continue;
    }
    const std::string joined = lines.back().empty() ? word : lines.back() + " " + word;
    if (!lines.back().empty() && text_width(joined, kSize) > room) {
      lines.push_back(word);
    } else {
      lines.back() = joined;
    }
    word.clear();
  }
  double y = (f.top + f.plot_bottom()) / 2 - kLine * double(lines.size() - 1) / 2 + 4;
  for (const std::string& l : lines) {
    c.add(Chart::Text{(f.left + f.plot_right()) / 2, y, l, kChartMuted, 0, kSize});
    y += kLine;
  }
  return c;
}

}  // namespace macro::enhance
