// The evaluation harness (docs/spec/macro-method.md §7): enumerate the close-up pairs of a
// benchmark root, run each method and option set on each pair, score it against closeup_gt/<frame>,
// and append one JSON record per (pair, method, options) to a results file that a later run
// resumes.
//
// Benchmark root: either one scene folder (it holds split.json) or a folder of scene folders
// (every direct sub-folder holding split.json, sorted by name). Scene folder layout: see
// enhance/scene_input.h (DL3DV-Closeup; MobileClose's train_frames / closeup_frames are read by
// gs::load_closeup_split).
//
// Work list: scenes by name, then split.json's closeup_eval_pairs in file order (pair_index), then
// method name, then the option set's canonical text; every run (and every shard) derives it the
// same way. --shard i/N takes the items whose position in that list is i mod N (round-robin).
//
// Skip rules (released evaluate.py): a pair whose GT image is missing, whose close-up pose cannot
// be resolved, or whose method produced no output is recorded with status "skipped" and the reason;
// it never enters an average.
//
// Record (one line of JSON, keys in this order):
//   {"scene", "pair_index", "training_frame", "closeup_frame", "depth_ratio", "method",
//    "options": {"K": "3", ...} (only the keys the method uses), "options_hash": 16 hex digits
//    (FNV-1a 64 of the canonical options text), "status": "ok" | "skipped", "reason",
//    "metrics": {"psnr": 26.2, "ssim": ..., "lpips_alex": ...}  (computed ones only; +inf as
//    "inf"), "not_computed": {"dinov2": "<reason>", ...}, "seconds": {"load": ..., "render": ...,
//    <method stages>..., "metrics": ...}, "seconds_per_closeup": the method's stages only (render +
//    enhance), not load or metrics, "reconstruction_seconds": the training time of the
//    reconstruction the method starts from (the last step's "seconds" of its training log in the
//    scene folder, BenchMethod::reconstruction_log; absent when the folder has no log),
//    "full_seconds_per_closeup": reconstruction_seconds + seconds_per_closeup, what a user pays
//    for one close-up of a new scene (absent with it), "width", "height": the GT size}
// Key of a record: scene, closeup_frame, method, options_hash.
//
// Appending: each record is one write(2) of the whole line (newline included) on a descriptor
// opened with O_APPEND, then fsync. A kill can therefore leave at most a torn last line (only if
// the write itself was cut short, e.g. a full disk); opening the file for appending truncates a
// last line that has no newline, so the record is simply run again. Several processes may append
// to the same file (each line is one O_APPEND write), but separate files per shard plus
// `macro bench merge` is the documented way.
#pragma once

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "enhance/bench/methods.h"
#include "enhance/metrics/metrics.h"
#include "enhance/scene_input.h"
#include "gs/image_io.h"

namespace macro::enhance {

// The methods (BenchOptions, BenchPair, MethodRegistry, ...): enhance/bench/methods.h.

// ---- Work list ---------------------------------------------------------------------------------
struct BenchWorkItem {
  BenchPair pair;
  std::string method;
  BenchOptions options;  // restricted to the method's keys
  std::string options_hash;
  std::string key() const;  // scene \t closeup_frame \t method \t options_hash
};

// "K=3,P=4" (keys sorted); "" for none.
std::string canonical_options(const BenchOptions& options);
std::string options_hash(const BenchOptions& options);  // 16 lower-case hex digits
std::string record_key(const std::string& scene, const std::string& closeup_frame,
                       const std::string& method, const std::string& options_hash);

// The scene folders of a root (see the top), sorted by name.
Result<std::vector<std::string>> list_scene_dirs(const std::string& root);

// Cross product of the option values: {"K": {"1","3"}, "P": {"4"}} -> {K=1,P=4}, {K=3,P=4}.
std::vector<BenchOptions> expand_option_grid(
    const std::map<std::string, std::vector<std::string>>& grid);

// The sorted work list. Unknown methods are an error listing the known ones. Each method's option
// sets are the grid restricted to its option_keys, duplicates dropped.
Result<std::vector<BenchWorkItem>> build_work_list(const std::string& root,
                                                   const std::vector<std::string>& methods,
                                                   const std::vector<BenchOptions>& option_sets,
                                                   const MethodRegistry& registry);

struct Shard {
  int index = 0, count = 1;
};
Result<Shard> parse_shard(const std::string& text);  // "i/N", 0 <= i < N
std::vector<BenchWorkItem> take_shard(const std::vector<BenchWorkItem>& items, Shard shard);

// ---- Records -----------------------------------------------------------------------------------
struct BenchRecord {
  std::string scene;
  int pair_index = 0;
  std::string training_frame, closeup_frame;
  double depth_ratio = 0;
  std::string method;
  BenchOptions options;
  std::string options_hash;
  bool ok = false;
  std::string reason;                // why skipped
  std::vector<MetricValue> metrics;  // computed and not-computed entries
  std::vector<MethodStage> seconds;  // load, method stages, metrics
  double seconds_per_closeup = 0;
  std::optional<double> reconstruction_seconds;  // and full = it + seconds_per_closeup
  int width = 0, height = 0;
  std::string enhancer;    // JSON "enhancer", absent when empty
  int planes_dropped = 0;  // JSON "planes_dropped" (0 when absent)
  std::string key() const;
};

std::string record_to_json_line(const BenchRecord& record);  // ends with '\n'
Result<BenchRecord> record_from_json(const std::string& line, const std::string& where);

// Every complete record of a results file ("" or a missing file: none). A last line without a
// newline is ignored (torn); any other bad line is an error naming the file and line.
Result<std::vector<BenchRecord>> read_records(const std::string& path);

// Appends records to a results file (see the top). open() creates the file if missing and cuts a
// torn last line.
class RecordAppender {
 public:
  RecordAppender() = default;
  ~RecordAppender();
  RecordAppender(const RecordAppender&) = delete;
  RecordAppender& operator=(const RecordAppender&) = delete;
  Status open(const std::string& path);
  Status append(const BenchRecord& record);

 private:
  std::string path_;
  int fd_ = -1;
};

// Joins results files: records deduplicated by key (an "ok" record wins over a "skipped" one,
// else the first seen), sorted in work-list order (scene, pair_index, method, options text).
std::vector<BenchRecord> merge_records(const std::vector<std::vector<BenchRecord>>& inputs);
Status write_records_atomic(const std::string& path, const std::vector<BenchRecord>& records);

// ---- Running -----------------------------------------------------------------------------------
struct BenchRunOptions {
  std::string root;
  std::vector<std::string> methods = {"3dgs"};
  std::vector<BenchOptions> option_sets = {{}};
  std::string results;  // JSONL file appended to
  Shard shard;
  int limit = 0;  // at most this many new records (0 = no limit)
  MetricOptions metrics;
};

struct BenchRunSummary {
  size_t work_items = 0;  // in this shard
  size_t already_done = 0, ran = 0, ok = 0, skipped = 0;
};

// Runs the shard's items that the results file does not hold yet, appending each record as it
// finishes. Progress with ETA on stderr (attention/runtime/progress.h; --quiet silences it).
// A scene folder whose cameras (or split intrinsics) have lens distortion is first undistorted as
// gsplat does (`macro undistort`) into RESULTS.undistorted/<scene>, reused by later runs, and
// scored there: against its undistorted close-up ground truth.
Result<BenchRunSummary> run_benchmark(const BenchRunOptions& options,
                                      const MethodRegistry& registry);

// The scene inputs of the last pair run, reused by the next item of the same pair (items of one
// pair are consecutive in the work list, so methods and option sets share one load).
struct PairInputsCache {
  std::string key;  // scene_dir \t closeup_frame
  std::optional<SceneInputs> inputs;
};

// The last step's "seconds" of a `macro train` JSONL log (read from its end); nullopt when the
// file is missing or holds no step line.
std::optional<double> training_log_seconds(const std::string& path);

// One item, scored (never an error for a skip: the record says why). `cache` may be null.
BenchRecord run_work_item(const BenchWorkItem& item, const MethodRegistry& registry,
                          const MetricOptions& metric_options, PairInputsCache* cache = nullptr);

}  // namespace macro::enhance
