// Benchmark tables and charts from harness records (enhance/bench/bench_harness.h).
//
// Protocol (docs/spec/macro-method.md §7, scripts/aggregate_results.py): for each configuration
// (method + option set), each scene's mean over its "ok" pairs, then the mean of the scene means. A
// metric that was never computed for a pair is not part of that pair's contribution; a scene with
// no computed value of a metric has no scene mean for it, and a configuration whose scenes have
// none prints "n/c" (never a number). Skipped pairs never enter a mean (they are counted). Scene
// failures (SceneFailureRule): under kReleased (the default, paper-comparable) a scene with any
// pair whose plan dropped an empty k-means bin (record planes_dropped > 0; the release raises there
// and the whole scene's pass fails, docs/benchmark.md) drops out of that configuration's average;
// under kPair (ours) those pairs count like any other. table.md says which rule was used and how
// many scenes it dropped.
//
// Outputs of write_report(DIR):
//   table.md, table.csv          methods as rows; PSNR (up), SSIM (up), LPIPS (down), DINOv2 and
//                                DreamSim (down; columns only when some configuration computed
//                                them), seconds per close-up, full seconds per close-up
//                                (reconstruction training included; a configuration has it when
//                                every ok pair's record does, else n/a), scenes, pairs ok /
//                                skipped
//   time_vs_<metric>.png/.svg/.pdf  seconds per close-up (x) vs the metric (y), one labelled
//                                point per configuration, +-1 s.d. of the scene means
//   cost_vs_<metric>.png/.svg/.pdf  the same with the full cost per close-up (x): the
//                                reconstruction's training + the method's seconds (records'
//                                full_seconds_per_closeup); only when some configuration has it
//   zoom_<metric>.png/.svg/.pdf  the metric vs the pair's zoom factor (depth_ratio): faint
//                                per-pair dots and a line per configuration through zoom-bin
//                                means over scenes, +-1 s.d. over scenes
//   scenes_<metric>.png/.svg/.pdf  per-scene bars (scene means), one bar per configuration,
//                                min-max over the scene's pairs
// The charts are built in enhance/bench/report_charts.h and drawn by enhance/figures/chart.h
// (cairo); a metric that no configuration computed gets "not computed: <reason>" charts.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "enhance/bench/bench_harness.h"
#include "gs/image_io.h"

namespace macro::enhance {

// The metrics in table order, with their column titles and direction.
struct MetricColumn {
  const char* name;   // record name: "psnr", "ssim", "lpips_alex", "dinov2", "dreamsim"
  const char* title;  // "PSNR", ...
  bool higher_better;
  bool optional;            // a column only when computed somewhere (DINOv2, DreamSim)
  bool target_one = false;  // best at 1 (grad_ratio: gradient energy / the GT's)
};
const std::vector<MetricColumn>& metric_columns();

enum class SceneFailureRule { kReleased, kPair };
const char* scene_failure_rule_name(SceneFailureRule rule);                  // "released", "pair"
Result<SceneFailureRule> parse_scene_failure_rule(const std::string& text);  // --scene-failure

struct ConfigResult {
  std::string method, options_text, options_hash;
  std::string label;  // "3dgs" or "macro K=3,P=4"
  // metric name -> mean of scene means (absent = not computed anywhere)
  std::map<std::string, double> metric;
  std::optional<double> seconds_per_closeup;
  std::optional<double> full_seconds_per_closeup;  // when every ok pair's record has it
  // scene -> metric name -> scene mean ("seconds_per_closeup" and "full_seconds_per_closeup"
  // included)
  std::map<std::string, std::map<std::string, double>> scene_means;
  size_t scenes = 0;  // scenes with at least one ok pair
  size_t pairs_ok = 0, pairs_skipped = 0;
  SceneFailureRule rule = SceneFailureRule::kReleased;
  size_t scenes_failed = 0;  // scenes dropped by the released rule (kPair: always 0)
  // every ok pair: its scene, zoom (depth_ratio) and computed metrics
  struct PairValues {
    std::string scene;
    double zoom = 0;
    std::map<std::string, double> values;
  };
  std::vector<PairValues> pairs;
  // metric name -> why it was not computed (the first reason seen), for metrics some pair of
  // this configuration did not compute
  std::map<std::string, std::string> not_computed;
};

// Configurations in order of first appearance in the (work-list ordered) records... sorted by
// method then options text.
std::vector<ConfigResult> aggregate_records(const std::vector<BenchRecord>& records,
                                            SceneFailureRule rule = SceneFailureRule::kReleased);

// "16.22" style formatting per metric (PSNR 2 decimals, others 3, seconds 2) or "n/c".
std::string format_metric(const std::string& name, std::optional<double> value);

std::string table_markdown(const std::vector<ConfigResult>& configs);
std::string table_csv(const std::vector<ConfigResult>& configs);

// The metric columns shown: every non-optional one, optional ones when some configuration
// computed them.
std::vector<MetricColumn> shown_columns(const std::vector<ConfigResult>& configs);

// Writes every file listed at the top into `dir` (created if missing), atomically. `written`
// receives the paths.
Status write_report(const std::vector<BenchRecord>& records, const std::string& dir,
                    std::vector<std::string>* written = nullptr,
                    SceneFailureRule rule = SceneFailureRule::kReleased);

}  // namespace macro::enhance
