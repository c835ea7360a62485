// Benchmark tables and charts (bench_report.h).
#include "enhance/bench/bench_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>
#include <tuple>

#include "attention/runtime/file_io.h"

namespace macro::enhance {
namespace fs = std::filesystem;

const std::vector<MetricColumn>& metric_columns() {
  static const std::vector<MetricColumn> cols = {
      {"psnr", "PSNR", true, false},         {"ssim", "SSIM", true, false},
      {"lpips_alex", "LPIPS", false, false}, {"dinov2", "DINOv2", false, true},
      {"dreamsim", "DreamSim", false, true},
      {"grad_ratio", "GradE ratio", false, true, true},
  };
  return cols;
}

namespace {
constexpr const char* kSeconds = "seconds_per_closeup";

struct Accum {
  double sum = 0;
  size_t n = 0;
  void add(double v) { sum += v, ++n; }
  double mean() const { return sum / double(n); }
};
}  // namespace

const char* scene_failure_rule_name(SceneFailureRule r) {
  return r == SceneFailureRule::kPair ? "pair" : "released";
}
Result<SceneFailureRule> parse_scene_failure_rule(const std::string& t) {
  if (t == "released") return SceneFailureRule::kReleased;
  if (t == "pair") return SceneFailureRule::kPair;
  return Status::error("--scene-failure: expected released or pair, found '" + t + "'");
}

std::vector<ConfigResult> aggregate_records(const std::vector<BenchRecord>& records,
                                            SceneFailureRule rule) {
  // Released rule: (config, scene) pairs with an empty k-means bin anywhere drop out whole.
  std::set<std::tuple<std::string, std::string, std::string>> failed;
  if (rule == SceneFailureRule::kReleased)
    for (const BenchRecord& r : records)
      if (r.ok && r.planes_dropped > 0)
        failed.insert({r.method, canonical_options(r.options), r.scene});
  // config key -> scene -> metric -> accumulated pair values
  std::map<std::pair<std::string, std::string>, ConfigResult> configs;
  std::map<std::pair<std::string, std::string>, std::map<std::string, std::map<std::string, Accum>>>
      per_scene;
  for (const BenchRecord& r : records) {
    const auto key = std::make_pair(r.method, canonical_options(r.options));
    ConfigResult& c = configs[key];
    if (c.method.empty()) {
      c.method = r.method;
      c.options_text = key.second;
      c.options_hash = r.options_hash;
      c.label = key.second.empty() ? r.method : r.method + " " + key.second;
      c.rule = rule;
    }
    if (failed.count({key.first, key.second, r.scene})) {
      ++c.pairs_skipped;  // its scene failed under the released rule
      continue;
    }
    if (!r.ok) {
      ++c.pairs_skipped;
      continue;
    }
    ++c.pairs_ok;
    auto& scene = per_scene[key][r.scene];
    std::map<std::string, double> pair_values;
    for (const MetricValue& m : r.metrics) {
      if (!m.computed) continue;  // n/c: never averaged
      scene[m.name].add(m.value);
      pair_values[m.name] = m.value;
    }
    scene[kSeconds].add(r.seconds_per_closeup);
    c.pairs.push_back({r.depth_ratio, pair_values});
  }
  std::vector<ConfigResult> out;
  for (const auto& f : failed) {
    auto it = configs.find({std::get<0>(f), std::get<1>(f)});
    if (it != configs.end()) ++it->second.scenes_failed;
  }
  for (auto& [key, c] : configs) {
    std::map<std::string, Accum> of_means;
    for (auto& [scene, metrics] : per_scene[key]) {
      ++c.scenes;
      for (auto& [name, acc] : metrics) {
        c.scene_means[scene][name] = acc.mean();
        of_means[name].add(acc.mean());
      }
    }
    for (auto& [name, acc] : of_means) {
      if (name == kSeconds) {
        c.seconds_per_closeup = acc.mean();
      } else {
        c.metric[name] = acc.mean();
      }
    }
    out.push_back(std::move(c));
  }
  return out;
}

std::string format_metric(const std::string& name, std::optional<double> value) {
  if (!value) return "n/c";
  if (std::isinf(*value)) return *value > 0 ? "inf" : "-inf";
  char buf[64];
  const int decimals = (name == "psnr" || name == kSeconds) ? 2 : 3;
  std::snprintf(buf, sizeof buf, "%.*f", decimals, *value);
  return buf;
}

namespace {
std::vector<MetricColumn> shown_columns(const std::vector<ConfigResult>& configs) {
  std::vector<MetricColumn> cols;
  for (const MetricColumn& m : metric_columns()) {
    bool any = !m.optional;
    for (const ConfigResult& c : configs) any = any || c.metric.count(m.name);
    if (any) cols.push_back(m);
  }
  return cols;
}
std::optional<double> metric_of(const ConfigResult& c, const std::string& name) {
  auto it = c.metric.find(name);
  if (it == c.metric.end()) return std::nullopt;
  return it->second;
}
std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char ch : s) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
  return q + "\"";
}
}  // namespace

std::string table_markdown(const std::vector<ConfigResult>& configs) {
  const auto cols = shown_columns(configs);
  std::string s = "| Method |";
  std::string rule = "|---|";
  for (const MetricColumn& m : cols) {
    s += ' ';
    s += m.title;
    s += m.target_one ? " →1 |" : m.higher_better ? " ↑ |" : " ↓ |";
    rule += "---:|";
  }
  s += " s / close-up | scenes | pairs ok | skipped |\n";
  rule += "---:|---:|---:|---:|\n";
  s += rule;
  for (const ConfigResult& c : configs) {
    const auto cell = [&s](const std::string& text) {
      s += ' ';
      s += text;
      s += " |";
    };
    s += "|";
    cell(c.label);
    for (const MetricColumn& m : cols) cell(format_metric(m.name, metric_of(c, m.name)));
    cell(format_metric(kSeconds, c.seconds_per_closeup));
    cell(std::to_string(c.scenes));
    cell(std::to_string(c.pairs_ok));
    cell(std::to_string(c.pairs_skipped));
    s += '\n';
  }
  s += "\nMean over scenes of the per-scene mean over pairs; n/c = not computed.\n";
  size_t dropped = 0;
  for (const ConfigResult& c : configs) dropped += c.scenes_failed;
  if (configs.empty() || configs.front().rule == SceneFailureRule::kReleased) {
    s += "Scene failures: released rule (--scene-failure released): a scene with an empty "
         "k-means bin in any pair drops out of that method's average; " +
         std::to_string(dropped) + " (method, scene) dropped, their pairs counted as skipped.\n";
  } else {
    s += "Scene failures: pair rule (--scene-failure pair): an empty k-means bin drops the plane "
         "and the pair counts; only skipped pairs are left out.\n";
  }
  return s;
}

std::string table_csv(const std::vector<ConfigResult>& configs) {
  const auto cols = shown_columns(configs);
  std::string s = "method,options";
  for (const MetricColumn& m : cols) {
    s += ',';
    s += m.name;
  }
  s += ",seconds_per_closeup,scenes,pairs_ok,pairs_skipped\n";
  for (const ConfigResult& c : configs) {
    s += csv_field(c.method) + "," + csv_field(c.options_text);
    for (const MetricColumn& m : cols) {
      auto v = metric_of(c, m.name);
      char buf[64];
      if (v && std::isfinite(*v)) std::snprintf(buf, sizeof buf, "%.9g", *v);
      s += ',';
      s += v ? (std::isfinite(*v) ? std::string(buf) : format_metric(m.name, v)) : "n/c";
    }
    char buf[64] = "n/c";
    if (c.seconds_per_closeup) std::snprintf(buf, sizeof buf, "%.6g", *c.seconds_per_closeup);
    s += std::string(",") + buf + "," + std::to_string(c.scenes) + "," +
         std::to_string(c.pairs_ok) + "," + std::to_string(c.pairs_skipped) + "\n";
  }
  return s;
}

// ---- Charts ------------------------------------------------------------------------------------
namespace {

constexpr uint32_t kPalette[] = {0x1f77b4, 0xd62728, 0x2ca02c, 0xff7f0e, 0x9467bd,
                                 0x8c564b, 0xe377c2, 0x17becf, 0xbcbd22, 0x7f7f7f};
uint32_t palette(size_t i) {
  return kPalette[i % (sizeof kPalette / sizeof kPalette[0])];
}
constexpr uint32_t kInk = 0x222222, kGrid = 0xdddddd;

struct Frame {  // plot area and data ranges
  double left = 70, top = 40, right = 20, bottom = 50;
  double x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  int w = 640, h = 420;
  double px(double x) const { return left + (x - x0) / (x1 - x0) * (w - left - right); }
  double py(double y) const { return h - bottom - (y - y0) / (y1 - y0) * (h - top - bottom); }
};

void pad_range(double& lo, double& hi) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0, hi = 1;
  if (hi - lo < 1e-12) lo -= 0.5, hi += 0.5;
  const double m = 0.08 * (hi - lo);
  lo -= m, hi += m;
}

std::string tick_text(double v) {
  char buf[32];
  const double a = std::fabs(v);
  std::snprintf(buf, sizeof buf,
                a >= 100  ? "%.0f"
                : a >= 10 ? "%.1f"
                : a >= 1  ? "%.2f"
                          : "%.3f",
                v);
  return buf;
}

void axes(Chart& c, const Frame& f, const std::string& title, const std::string& xlabel,
          const std::string& ylabel, bool x_ticks) {
  c.width = f.w, c.height = f.h;
  c.rects.push_back({0, 0, double(f.w), double(f.h), 0xffffff});
  for (int i = 0; i <= 4; ++i) {
    const double y = f.y0 + (f.y1 - f.y0) * i / 4;
    c.lines.push_back({f.left, f.py(y), f.w - f.right, f.py(y), kGrid, 1});
    c.texts.push_back({f.left - 6, f.py(y) + 4, tick_text(y), kInk, 1});
    if (x_ticks) {
      const double x = f.x0 + (f.x1 - f.x0) * i / 4;
      c.lines.push_back({f.px(x), double(f.top), f.px(x), f.h - f.bottom, kGrid, 1});
      c.texts.push_back({f.px(x), f.h - f.bottom + 16, tick_text(x), kInk, 0});
    }
  }
  c.lines.push_back({f.left, f.h - f.bottom, f.w - f.right, f.h - f.bottom, kInk, 1.5});
  c.lines.push_back({f.left, double(f.top), f.left, f.h - f.bottom, kInk, 1.5});
  c.texts.push_back({f.w / 2.0, 15, title, kInk, 0});
  c.texts.push_back({(f.left + f.w - f.right) / 2, f.h - 12.0, xlabel, kInk, 0});
  c.texts.push_back({8, f.top - 8, ylabel, kInk, -1});
}

std::string metric_axis_label(const MetricColumn& m) {
  if (m.target_one) return std::string(m.title) + " (1 is best)";
  return std::string(m.title) + (m.higher_better ? " (higher is better)" : " (lower is better)");
}

}  // namespace

Chart chart_time_vs_metric(const std::vector<ConfigResult>& configs, const MetricColumn& metric) {
  Frame f;
  double xlo = 1e300, xhi = -1e300, ylo = 1e300, yhi = -1e300;
  for (const ConfigResult& c : configs) {
    auto v = metric_of(c, metric.name);
    if (!v || !c.seconds_per_closeup || !std::isfinite(*v)) continue;
    xlo = std::min(xlo, *c.seconds_per_closeup), xhi = std::max(xhi, *c.seconds_per_closeup);
    ylo = std::min(ylo, *v), yhi = std::max(yhi, *v);
  }
  if (xlo > xhi) xlo = 0, xhi = 1, ylo = 0, yhi = 1;
  pad_range(xlo, xhi);
  pad_range(ylo, yhi);
  f.x0 = 0, f.x1 = xhi, f.y0 = ylo, f.y1 = yhi;
  Chart c;
  axes(c, f, std::string("Seconds per close-up vs ") + metric.title, "seconds per close-up",
       metric_axis_label(metric), true);
  for (size_t i = 0; i < configs.size(); ++i) {
    auto v = metric_of(configs[i], metric.name);
    if (!v || !configs[i].seconds_per_closeup || !std::isfinite(*v)) continue;
    const double x = f.px(*configs[i].seconds_per_closeup), y = f.py(*v);
    c.circles.push_back({x, y, 5, palette(i)});
    // Labels right of the point in the left half, left of it in the right half.
    const bool right_half = x > f.w / 2.0;
    c.texts.push_back(
        {right_half ? x - 8 : x + 8, y - 6, configs[i].label, palette(i), right_half ? 1 : -1});
  }
  return c;
}

// Right margin that fits the legend labels (8 px per character in both renderers' fonts).
static double legend_margin(const std::vector<ConfigResult>& configs) {
  size_t longest = 0;
  for (const ConfigResult& c : configs) longest = std::max(longest, c.label.size());
  return std::max(150.0, 40.0 + 8.0 * double(longest));
}

Chart chart_metric_vs_zoom(const std::vector<ConfigResult>& configs, const MetricColumn& metric) {
  Frame f;
  f.right = legend_margin(configs);
  f.w = int(640 + f.right - 150);
  double xlo = 1e300, xhi = -1e300, ylo = 1e300, yhi = -1e300;
  for (const ConfigResult& c : configs)
    for (const auto& [zoom, values] : c.pairs) {
      auto it = values.find(metric.name);
      if (it == values.end() || !std::isfinite(it->second)) continue;
      xlo = std::min(xlo, zoom), xhi = std::max(xhi, zoom);
      ylo = std::min(ylo, it->second), yhi = std::max(yhi, it->second);
    }
  if (xlo > xhi) xlo = 0, xhi = 1, ylo = 0, yhi = 1;
  pad_range(xlo, xhi);
  pad_range(ylo, yhi);
  f.x0 = xlo, f.x1 = xhi, f.y0 = ylo, f.y1 = yhi;
  Chart c;
  axes(c, f, std::string(metric.title) + " vs zoom factor", "zoom factor (depth ratio)",
       metric_axis_label(metric), true);
  constexpr int kBins = 6;
  for (size_t i = 0; i < configs.size(); ++i) {
    Accum bins[kBins];
    Accum zooms[kBins];
    for (const auto& [zoom, values] : configs[i].pairs) {
      auto it = values.find(metric.name);
      if (it == values.end() || !std::isfinite(it->second)) continue;
      c.circles.push_back({f.px(zoom), f.py(it->second), 2.5, palette(i)});
      const int b = std::clamp(int((zoom - f.x0) / (f.x1 - f.x0) * kBins), 0, kBins - 1);
      bins[b].add(it->second);
      zooms[b].add(zoom);
    }
    double px = -1, py = -1;
    for (int b = 0; b < kBins; ++b) {
      if (!bins[b].n) continue;
      const double x = f.px(zooms[b].mean()), y = f.py(bins[b].mean());
      if (px >= 0) c.lines.push_back({px, py, x, y, palette(i), 2});
      px = x, py = y;
    }
    const double ly = f.top + 14.0 + 18.0 * double(i);
    c.lines.push_back({f.w - f.right + 10.0, ly - 3, f.w - f.right + 28.0, ly - 3, palette(i), 2});
    c.texts.push_back({f.w - f.right + 32.0, ly + 1, configs[i].label, palette(i), -1});
  }
  return c;
}

Chart chart_scene_bars(const std::vector<ConfigResult>& configs, const MetricColumn& metric) {
  std::set<std::string> scene_set;
  double ylo = 0, yhi = -1e300;
  for (const ConfigResult& c : configs)
    for (const auto& [scene, means] : c.scene_means) {
      scene_set.insert(scene);
      auto it = means.find(metric.name);
      if (it != means.end() && std::isfinite(it->second)) {
        yhi = std::max(yhi, it->second);
        ylo = std::min(ylo, it->second);
      }
    }
  const std::vector<std::string> scenes(scene_set.begin(), scene_set.end());
  Frame f;
  f.right = legend_margin(configs);
  f.bottom = 70;
  f.w = std::max(640, int(f.left + f.right) + int(scenes.size() * configs.size()) * 14 +
                          int(scenes.size()) * 20);
  if (yhi < ylo) yhi = 1;
  f.y0 = ylo, f.y1 = yhi + 0.08 * (yhi - ylo + 1e-12);
  f.x0 = 0, f.x1 = double(std::max<size_t>(scenes.size(), 1));
  Chart c;
  axes(c, f, std::string(metric.title) + " per scene (mean over pairs)", "scene",
       metric_axis_label(metric), false);
  const double slot = f.px(1) - f.px(0);
  const double bar = slot * 0.8 / double(std::max<size_t>(configs.size(), 1));
  for (size_t s = 0; s < scenes.size(); ++s) {
    std::string name = scenes[s].size() > 10 ? scenes[s].substr(0, 8) + ".." : scenes[s];
    c.texts.push_back({f.px(double(s) + 0.5), f.h - f.bottom + 16, name, kInk, 0});
    for (size_t i = 0; i < configs.size(); ++i) {
      auto sc = configs[i].scene_means.find(scenes[s]);
      if (sc == configs[i].scene_means.end()) continue;
      auto it = sc->second.find(metric.name);
      if (it == sc->second.end() || !std::isfinite(it->second)) continue;
      const double x = f.px(double(s)) + slot * 0.1 + bar * double(i);
      const double y_top = f.py(it->second), y_base = f.py(std::max(0.0, f.y0));
      c.rects.push_back(
          {x, std::min(y_top, y_base), bar * 0.9, std::fabs(y_base - y_top), palette(i)});
    }
  }
  for (size_t i = 0; i < configs.size(); ++i) {
    const double ly = f.top + 14.0 + 18.0 * double(i);
    c.rects.push_back({f.w - f.right + 10.0, ly - 8, 12, 10, palette(i)});
    c.texts.push_back({f.w - f.right + 28.0, ly + 1, configs[i].label, palette(i), -1});
  }
  return c;
}

// ---- SVG ---------------------------------------------------------------------------------------
namespace {
std::string hex(uint32_t rgb) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "#%06x", rgb & 0xffffff);
  return buf;
}
std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}
std::string xml_escape(const std::string& s) {
  std::string o;
  for (char ch : s) {
    switch (ch) {
      case '&':
        o += "&amp;";
        break;
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '"':
        o += "&quot;";
        break;
      default:
        o += ch;
    }
  }
  return o;
}
}  // namespace

std::string chart_to_svg(const Chart& c) {
  std::string s = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  s += "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + std::to_string(c.width) +
       "\" height=\"" + std::to_string(c.height) + "\" viewBox=\"0 0 " + std::to_string(c.width) +
       " " + std::to_string(c.height) + "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  for (const auto& r : c.rects)
    s += "<rect x=\"" + num(r.x) + "\" y=\"" + num(r.y) + "\" width=\"" + num(r.w) +
         "\" height=\"" + num(r.h) + "\" fill=\"" + hex(r.rgb) + "\"/>\n";
  for (const auto& l : c.lines)
    s += "<line x1=\"" + num(l.x0) + "\" y1=\"" + num(l.y0) + "\" x2=\"" + num(l.x1) + "\" y2=\"" +
         num(l.y1) + "\" stroke=\"" + hex(l.rgb) + "\" stroke-width=\"" + num(l.width) + "\"/>\n";
  for (const auto& p : c.circles)
    s += "<circle cx=\"" + num(p.x) + "\" cy=\"" + num(p.y) + "\" r=\"" + num(p.r) + "\" fill=\"" +
         hex(p.rgb) + "\"/>\n";
  for (const auto& t : c.texts) {
    const char* anchor = t.anchor < 0 ? "start" : t.anchor > 0 ? "end" : "middle";
    s += "<text x=\"" + num(t.x) + "\" y=\"" + num(t.y) + "\" fill=\"" + hex(t.rgb) +
         "\" text-anchor=\"" + anchor + "\">" + xml_escape(t.text) + "</text>\n";
  }
  s += "</svg>\n";
  return s;
}

// ---- Raster ------------------------------------------------------------------------------------
namespace {

// 3x5 glyphs, rows top to bottom, '#' = ink. Lower case is drawn as upper case; unknown
// characters as a blank.
const char* glyph(char ch) {
  if (ch >= 'a' && ch <= 'z') ch = char(ch - 'a' + 'A');
  switch (ch) {
    case '0':
      return "####.##.##.####";
    case '1':
      return ".#.##..#..#.###";
    case '2':
      return "###..#####..###";
    case '3':
      return "###..####..####";
    case '4':
      return "#.##.####..#..#";
    case '5':
      return "####..###..####";
    case '6':
      return "####..####.####";
    case '7':
      return "###..#..#..#..#";
    case '8':
      return "####.#####.####";
    case '9':
      return "####.####..####";
    case 'A':
      return ".#.#.#####.##.#";
    case 'B':
      return "##.#.###.#.###.";
    case 'C':
      return "####..#..#..###";
    case 'D':
      return "##.#.##.##.###.";
    case 'E':
      return "####..####..###";
    case 'F':
      return "####..####..#..";
    case 'G':
      return "####..#.##.####";
    case 'H':
      return "#.##.#####.##.#";
    case 'I':
      return "###.#..#..#.###";
    case 'J':
      return "..#..#..##.####";
    case 'K':
      return "#.##.###.#.##.#";
    case 'L':
      return "#..#..#..#..###";
    case 'M':
      return "#.#####.##.##.#";
    case 'N':
      return "##.#.##.##.##.#";
    case 'O':
      return "####.##.##.####";
    case 'P':
      return "####.#####..#..";
    case 'Q':
      return "####.##.####..#";
    case 'R':
      return "####.###.#.##.#";
    case 'S':
      return "####..###..####";
    case 'T':
      return "###.#..#..#..#.";
    case 'U':
      return "#.##.##.##.####";
    case 'V':
      return "#.##.##.##.#.#.";
    case 'W':
      return "#.##.##.#####.#";
    case 'X':
      return "#.##.#.#.#.##.#";
    case 'Y':
      return "#.##.#.#..#..#.";
    case 'Z':
      return "###..#.#.#..###";
    case '.':
      return "............#..";
    case ',':
      return "..........#.#..";
    case '-':
      return "......###......";
    case '+':
      return "....#.###.#....";
    case '=':
      return "...###...###...";
    case '/':
      return "..#..#.#.#..#..";
    case ':':
      return "....#.....#....";
    case '_':
      return "............###";
    case '(':
      return ".#.#..#..#...#.";
    case ')':
      return ".#...#..#..#.#.";
    default:
      return "...............";
  }
}

struct Raster {
  gs::Image img;
  void put(int x, int y, uint32_t rgb) {
    if (x < 0 || y < 0 || x >= img.width || y >= img.height) return;
    img.at(y, x, 0) = float((rgb >> 16) & 255) / 255.f;
    img.at(y, x, 1) = float((rgb >> 8) & 255) / 255.f;
    img.at(y, x, 2) = float(rgb & 255) / 255.f;
  }
  void fill_rect(double x, double y, double w, double h, uint32_t rgb) {
    const int x0 = int(std::lround(x)), y0 = int(std::lround(y));
    const int x1 = int(std::lround(x + w)), y1 = int(std::lround(y + h));
    for (int j = std::max(y0, 0); j < std::min(y1, img.height); ++j)
      for (int i = std::max(x0, 0); i < std::min(x1, img.width); ++i) put(i, j, rgb);
  }
  void disc(double cx, double cy, double r, uint32_t rgb) {
    for (int j = int(std::floor(cy - r)); j <= int(std::ceil(cy + r)); ++j)
      for (int i = int(std::floor(cx - r)); i <= int(std::ceil(cx + r)); ++i) {
        const double dx = i + 0.5 - cx, dy = j + 0.5 - cy;
        if (dx * dx + dy * dy <= r * r) put(i, j, rgb);
      }
  }
  void line(double x0, double y0, double x1, double y1, double width, uint32_t rgb) {
    const double len = std::hypot(x1 - x0, y1 - y0);
    const int steps = std::max(1, int(std::ceil(len * 2)));
    const double r = std::max(0.5, width / 2);
    for (int s = 0; s <= steps; ++s) {
      const double t = double(s) / steps;
      const double x = x0 + t * (x1 - x0), y = y0 + t * (y1 - y0);
      if (r <= 0.75) {
        put(int(std::floor(x)), int(std::floor(y)), rgb);
      } else {
        disc(x, y, r, rgb);
      }
    }
  }
  void text(double x, double y, const std::string& s, int anchor, uint32_t rgb) {
    constexpr int kScale = 2, kAdvance = 4 * kScale;
    const double w = double(s.size()) * kAdvance;
    double left = anchor < 0 ? x : anchor > 0 ? x - w : x - w / 2;
    const int top = int(std::lround(y)) - 5 * kScale;  // y is the baseline
    for (char ch : s) {
      const char* g = glyph(ch);
      for (int r = 0; r < 5; ++r)
        for (int col = 0; col < 3; ++col)
          if (g[r * 3 + col] == '#')
            fill_rect(left + col * kScale, top + r * kScale, kScale, kScale, rgb);
      left += kAdvance;
    }
  }
};

}  // namespace

gs::Image rasterize_chart(const Chart& c) {
  Raster r;
  r.img = gs::Image(c.width, c.height, 3);
  std::fill(r.img.data.begin(), r.img.data.end(), 1.f);
  for (const auto& x : c.rects) r.fill_rect(x.x, x.y, x.w, x.h, x.rgb);
  for (const auto& l : c.lines) r.line(l.x0, l.y0, l.x1, l.y1, l.width, l.rgb);
  for (const auto& p : c.circles) r.disc(p.x, p.y, p.r, p.rgb);
  for (const auto& t : c.texts) r.text(t.x, t.y, t.text, t.anchor, t.rgb);
  return r.img;
}

Status write_report(const std::vector<BenchRecord>& records, const std::string& dir,
                    std::vector<std::string>* written, SceneFailureRule rule) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir, ec))
    return Status::error(dir + ": cannot create the report folder: " + ec.message());
  const std::vector<ConfigResult> configs = aggregate_records(records, rule);
  const auto put = [&](const std::string& name, const std::string& text) -> Status {
    const std::string path = (fs::path(dir) / name).string();
    MACRO_TRY(write_file_atomic(path, text));
    if (written) written->push_back(path);
    return Status::ok();
  };
  const auto put_chart = [&](const std::string& stem, const Chart& chart) -> Status {
    MACRO_TRY(put(stem + ".svg", chart_to_svg(chart)));
    const std::string png = (fs::path(dir) / (stem + ".png")).string();
    MACRO_TRY(gs::write_png(png, rasterize_chart(chart)));
    if (written) written->push_back(png);
    return Status::ok();
  };
  MACRO_TRY(put("table.md", table_markdown(configs)));
  MACRO_TRY(put("table.csv", table_csv(configs)));
  for (const MetricColumn& m : shown_columns(configs)) {
    MACRO_TRY(put_chart(std::string("time_vs_") + m.name, chart_time_vs_metric(configs, m)));
    MACRO_TRY(put_chart(std::string("zoom_") + m.name, chart_metric_vs_zoom(configs, m)));
    MACRO_TRY(put_chart(std::string("scenes_") + m.name, chart_scene_bars(configs, m)));
  }
  return Status::ok();
}

}  // namespace macro::enhance
