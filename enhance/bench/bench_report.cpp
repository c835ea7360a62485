// Benchmark tables and charts (bench_report.h).
#include "enhance/bench/bench_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>
#include <tuple>

#include "attention/runtime/file_io.h"
#include "enhance/bench/report_charts.h"

namespace macro::enhance {
namespace fs = std::filesystem;

const std::vector<MetricColumn>& metric_columns() {
  static const std::vector<MetricColumn> cols = {
      {"psnr", "PSNR", true, false},         {"ssim", "SSIM", true, false},
      {"lpips_alex", "LPIPS", false, false}, {"dinov2", "DINOv2", false, true},
      {"dreamsim", "DreamSim", false, true}, {"grad_ratio", "GradE ratio", false, true, true},
  };
  return cols;
}

namespace {
constexpr const char* kSeconds = "seconds_per_closeup";
constexpr const char* kFullSeconds = "full_seconds_per_closeup";

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
  std::map<std::pair<std::string, std::string>, size_t> full_pairs;  // ok pairs with a full cost
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
      if (!m.computed) {  // n/c: never averaged
        c.not_computed.emplace(m.name, m.reason.empty() ? "no reason recorded" : m.reason);
        continue;
      }
      scene[m.name].add(m.value);
      pair_values[m.name] = m.value;
    }
    scene[kSeconds].add(r.seconds_per_closeup);
    if (r.reconstruction_seconds) {
      scene[kFullSeconds].add(*r.reconstruction_seconds + r.seconds_per_closeup);
      ++full_pairs[key];
    }
    c.pairs.push_back({r.scene, r.depth_ratio, pair_values});
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
      } else if (name == kFullSeconds) {
        if (full_pairs[key] == c.pairs_ok) c.full_seconds_per_closeup = acc.mean();
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
  const int decimals = (name == "psnr" || name == kSeconds || name == kFullSeconds) ? 2 : 3;
  std::snprintf(buf, sizeof buf, "%.*f", decimals, *value);
  return buf;
}

std::vector<MetricColumn> shown_columns(const std::vector<ConfigResult>& configs) {
  std::vector<MetricColumn> cols;
  for (const MetricColumn& m : metric_columns()) {
    bool any = !m.optional;
    for (const ConfigResult& c : configs) any = any || c.metric.count(m.name);
    if (any) cols.push_back(m);
  }
  return cols;
}

namespace {
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
  bool any_full = false;
  for (const ConfigResult& c : configs) any_full = any_full || c.full_seconds_per_closeup;
  s += any_full ? " s / close-up | full s / close-up | scenes | pairs ok | skipped |\n"
                : " s / close-up | scenes | pairs ok | skipped |\n";
  rule += any_full ? "---:|---:|---:|---:|---:|\n" : "---:|---:|---:|---:|\n";
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
    if (any_full)
      cell(c.full_seconds_per_closeup ? format_metric(kFullSeconds, c.full_seconds_per_closeup)
                                      : "n/a");
    cell(std::to_string(c.scenes));
    cell(std::to_string(c.pairs_ok));
    cell(std::to_string(c.pairs_skipped));
    s += '\n';
  }
  s += "\nMean over scenes of the per-scene mean over pairs; n/c = not computed.\n";
  if (any_full)
    s += "Full s / close-up: the reconstruction's training (its log in the scene folder) plus the "
         "method's seconds, what one close-up of a new scene costs; n/a where a record has no "
         "training log.\n";
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
  s += ",seconds_per_closeup,full_seconds_per_closeup,scenes,pairs_ok,pairs_skipped\n";
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
    char full[64] = "n/a";
    if (c.full_seconds_per_closeup)
      std::snprintf(full, sizeof full, "%.6g", *c.full_seconds_per_closeup);
    s += std::string(",") + buf + "," + full + "," + std::to_string(c.scenes) + "," +
         std::to_string(c.pairs_ok) + "," + std::to_string(c.pairs_skipped) + "\n";
  }
  return s;
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
    return write_chart(chart, (fs::path(dir) / stem).string(), written);
  };
  MACRO_TRY(put("table.md", table_markdown(configs)));
  MACRO_TRY(put("table.csv", table_csv(configs)));
  bool any_full = false;
  for (const ConfigResult& c : configs) any_full = any_full || c.full_seconds_per_closeup;
  for (const MetricColumn& m : shown_columns(configs)) {
    MACRO_TRY(put_chart(std::string("time_vs_") + m.name, chart_time_vs_metric(configs, m)));
    if (any_full)
      MACRO_TRY(
          put_chart(std::string("cost_vs_") + m.name, chart_time_vs_metric(configs, m, true)));
    MACRO_TRY(put_chart(std::string("zoom_") + m.name, chart_metric_vs_zoom(configs, m)));
    MACRO_TRY(put_chart(std::string("scenes_") + m.name, chart_scene_bars(configs, m)));
  }
  return Status::ok();
}

}  // namespace macro::enhance
