// The evaluation harness: work list, records, resume, shards, merge (bench_harness.h); the
// methods it runs are enhance/bench/methods.h.
#include "enhance/bench/bench_harness.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "gs/cameras/undistort_scene.h"

namespace macro::enhance {
namespace fs = std::filesystem;
using Json = nlohmann::ordered_json;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

uint64_t fnv1a64(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

}  // namespace

// ---- Work list ---------------------------------------------------------------------------------
std::string canonical_options(const BenchOptions& options) {
  std::string s;
  for (const auto& [k, v] : options) {
    if (!s.empty()) s += ',';
    s += k + "=" + v;
  }
  return s;
}

std::string options_hash(const BenchOptions& options) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx",
                static_cast<unsigned long long>(fnv1a64(canonical_options(options))));
  return buf;
}

std::string record_key(const std::string& scene, const std::string& closeup_frame,
                       const std::string& method, const std::string& hash) {
  return scene + "\t" + closeup_frame + "\t" + method + "\t" + hash;
}

std::string BenchWorkItem::key() const {
  return record_key(pair.scene, pair.pair.closeup_frame, method, options_hash);
}
std::string BenchRecord::key() const {
  return record_key(scene, closeup_frame, method, options_hash);
}

Result<std::vector<std::string>> list_scene_dirs(const std::string& root) {
  std::error_code ec;
  if (!fs::is_directory(root, ec)) return Status::error(root + ": benchmark root not found");
  if (fs::exists(fs::path(root) / "split.json", ec)) return std::vector<std::string>{root};
  std::vector<std::string> dirs;
  for (fs::directory_iterator it(root, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_directory(ec) && fs::exists(it->path() / "split.json", ec))
      dirs.push_back(it->path().string());
  }
  if (ec) return Status::error(root + ": cannot list: " + ec.message());
  if (dirs.empty())
    return Status::error(root +
                         ": no scene folder (expected split.json in it or in its "
                         "sub-folders)");
  std::sort(dirs.begin(), dirs.end());
  return dirs;
}

std::vector<BenchOptions> expand_option_grid(
    const std::map<std::string, std::vector<std::string>>& grid) {
  std::vector<BenchOptions> out = {{}};
  for (const auto& [key, values] : grid) {
    if (values.empty()) continue;
    std::vector<BenchOptions> next;
    for (const BenchOptions& o : out)
      for (const std::string& v : values) {
        BenchOptions n = o;
        n[key] = v;
        next.push_back(std::move(n));
      }
    out = std::move(next);
  }
  return out;
}

namespace {
bool work_order(const BenchWorkItem& a, const BenchWorkItem& b) {
  if (a.pair.scene != b.pair.scene) return a.pair.scene < b.pair.scene;
  if (a.pair.pair_index != b.pair.pair_index) return a.pair.pair_index < b.pair.pair_index;
  if (a.method != b.method) return a.method < b.method;
  return canonical_options(a.options) < canonical_options(b.options);
}
bool record_order(const BenchRecord& a, const BenchRecord& b) {
  if (a.scene != b.scene) return a.scene < b.scene;
  if (a.pair_index != b.pair_index) return a.pair_index < b.pair_index;
  if (a.method != b.method) return a.method < b.method;
  return canonical_options(a.options) < canonical_options(b.options);
}
}  // namespace

Result<std::vector<BenchWorkItem>> build_work_list(const std::string& root,
                                                   const std::vector<std::string>& methods,
                                                   const std::vector<BenchOptions>& option_sets,
                                                   const MethodRegistry& registry) {
  if (methods.empty()) return Status::error("--methods: no method given");
  for (const std::string& m : methods) {
    if (!registry.find(m)) {
      std::string known;
      for (const std::string& n : registry.names()) known += (known.empty() ? "" : ", ") + n;
      return Status::error("--methods: unknown method '" + m + "' (known: " + known + ")");
    }
  }
  MACRO_ASSIGN_OR_RETURN(std::vector<std::string> dirs, list_scene_dirs(root));
  std::vector<BenchWorkItem> items;
  for (const std::string& dir : dirs) {
    const std::string split_path = (fs::path(dir) / "split.json").string();
    MACRO_ASSIGN_OR_RETURN(gs::CloseupSplit split, gs::load_closeup_split(split_path));
    const std::string scene = fs::path(dir).filename().string();
    for (size_t p = 0; p < split.closeup_eval_pairs.size(); ++p) {
      BenchPair bp{scene, dir, int(p), split.closeup_eval_pairs[p]};
      for (const std::string& m : methods) {
        const BenchMethod* method = registry.find(m);
        std::set<std::string> seen;
        for (const BenchOptions& o : option_sets) {
          BenchOptions used;
          for (const std::string& k : method->option_keys)
            if (auto it = o.find(k); it != o.end()) used[k] = it->second;
          if (!seen.insert(canonical_options(used)).second) continue;
          items.push_back({bp, m, used, options_hash(used)});
        }
      }
    }
  }
  std::stable_sort(items.begin(), items.end(), work_order);
  // Repeated --methods entries would give the same key twice.
  items.erase(std::unique(items.begin(), items.end(),
                          [](const BenchWorkItem& a, const BenchWorkItem& b) {
                            return a.key() == b.key();
                          }),
              items.end());
  return items;
}

Result<Shard> parse_shard(const std::string& text) {
  const size_t slash = text.find('/');
  const auto bad = [&]() {
    return Status::error("--shard: expected i/N with 0 <= i < N, found '" + text + "'");
  };
  if (slash == std::string::npos) return bad();
  const std::string a = text.substr(0, slash), b = text.substr(slash + 1);
  const auto digits = [](const std::string& s) {
    return !s.empty() && s.size() <= 6 &&
           std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  if (!digits(a) || !digits(b)) return bad();
  Shard s{std::stoi(a), std::stoi(b)};
  if (s.count < 1 || s.index >= s.count) return bad();
  return s;
}

std::vector<BenchWorkItem> take_shard(const std::vector<BenchWorkItem>& items, Shard shard) {
  std::vector<BenchWorkItem> out;
  for (size_t i = 0; i < items.size(); ++i)
    if (int(i % size_t(shard.count)) == shard.index) out.push_back(items[i]);
  return out;
}

// ---- Records -----------------------------------------------------------------------------------
std::string record_to_json_line(const BenchRecord& r) {
  Json j;
  j["scene"] = r.scene;
  j["pair_index"] = r.pair_index;
  j["training_frame"] = r.training_frame;
  j["closeup_frame"] = r.closeup_frame;
  j["depth_ratio"] = r.depth_ratio;
  j["method"] = r.method;
  Json opts = Json::object();
  for (const auto& [k, v] : r.options) opts[k] = v;
  j["options"] = opts;
  j["options_hash"] = r.options_hash;
  j["status"] = r.ok ? "ok" : "skipped";
  j["reason"] = r.reason;
  Json metrics = Json::object(), not_computed = Json::object();
  for (const MetricValue& m : r.metrics) {
    if (!m.computed) {
      not_computed[m.name] = m.reason;
    } else if (std::isfinite(m.value)) {
      metrics[m.name] = m.value;
    } else {
      metrics[m.name] = m.value > 0 ? "inf" : "-inf";
    }
  }
  j["metrics"] = metrics;
  j["not_computed"] = not_computed;
  Json secs = Json::object();
  for (const MethodStage& s : r.seconds) secs[s.name] = s.seconds;
  j["seconds"] = secs;
  j["seconds_per_closeup"] = r.seconds_per_closeup;
  if (r.reconstruction_seconds) {
    j["reconstruction_seconds"] = *r.reconstruction_seconds;
    j["full_seconds_per_closeup"] = *r.reconstruction_seconds + r.seconds_per_closeup;
  }
  j["width"] = r.width;
  j["height"] = r.height;
  if (!r.enhancer.empty()) j["enhancer"] = r.enhancer;
  if (r.planes_dropped) j["planes_dropped"] = r.planes_dropped;
  return j.dump() + "\n";
}

Result<BenchRecord> record_from_json(const std::string& line, const std::string& where) {
  Json j = Json::parse(line, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) return Status::error(where + ": not a JSON object");
  BenchRecord r;
  const auto str = [&](const char* k, std::string& out) -> Status {
    if (!j.contains(k) || !j[k].is_string())
      return Status::error(where + ": field '" + k + "': expected a string");
    out = j[k].get<std::string>();
    return Status::ok();
  };
  const auto num = [&](const Json& v, const std::string& k, double& out) -> Status {
    if (v.is_number()) {
      out = v.get<double>();
    } else if (v.is_string() && (v == "inf" || v == "-inf")) {
      out = v == "inf" ? std::numeric_limits<double>::infinity()
                       : -std::numeric_limits<double>::infinity();
    } else {
      return Status::error(where + ": field '" + k + "': expected a number");
    }
    return Status::ok();
  };
  MACRO_TRY(str("scene", r.scene));
  MACRO_TRY(str("closeup_frame", r.closeup_frame));
  MACRO_TRY(str("method", r.method));
  MACRO_TRY(str("options_hash", r.options_hash));
  std::string status;
  MACRO_TRY(str("status", status));
  if (status != "ok" && status != "skipped")
    return Status::error(where + ": field 'status': expected \"ok\" or \"skipped\", found \"" +
                         status + "\"");
  r.ok = status == "ok";
  if (j.contains("training_frame") && j["training_frame"].is_string())
    r.training_frame = j["training_frame"].get<std::string>();
  if (j.contains("reason") && j["reason"].is_string()) r.reason = j["reason"].get<std::string>();
  if (j.contains("enhancer") && j["enhancer"].is_string())
    r.enhancer = j["enhancer"].get<std::string>();
  double d = 0;
  if (j.contains("pair_index")) {
    MACRO_TRY(num(j["pair_index"], "pair_index", d));
    r.pair_index = int(d);
  }
  if (j.contains("planes_dropped")) {
    MACRO_TRY(num(j["planes_dropped"], "planes_dropped", d));
    r.planes_dropped = int(d);
  }
  if (j.contains("depth_ratio")) MACRO_TRY(num(j["depth_ratio"], "depth_ratio", r.depth_ratio));
  if (j.contains("options") && j["options"].is_object())
    for (auto& [k, v] : j["options"].items())
      r.options[k] = v.is_string() ? v.get<std::string>() : v.dump();
  if (j.contains("metrics") && j["metrics"].is_object())
    for (auto& [k, v] : j["metrics"].items()) {
      MetricValue m;
      m.name = k;
      m.computed = true;
      MACRO_TRY(num(v, "metrics." + k, m.value));
      r.metrics.push_back(m);
    }
  if (j.contains("not_computed") && j["not_computed"].is_object())
    for (auto& [k, v] : j["not_computed"].items()) {
      MetricValue m;
      m.name = k;
      m.reason = v.is_string() ? v.get<std::string>() : v.dump();
      r.metrics.push_back(m);
    }
  if (j.contains("seconds") && j["seconds"].is_object())
    for (auto& [k, v] : j["seconds"].items()) {
      MethodStage s{k, 0};
      MACRO_TRY(num(v, "seconds." + k, s.seconds));
      r.seconds.push_back(s);
    }
  if (j.contains("seconds_per_closeup"))
    MACRO_TRY(num(j["seconds_per_closeup"], "seconds_per_closeup", r.seconds_per_closeup));
  if (j.contains("reconstruction_seconds")) {
    double v = 0;
    MACRO_TRY(num(j["reconstruction_seconds"], "reconstruction_seconds", v));
    r.reconstruction_seconds = v;
  }
  if (j.contains("width") && j["width"].is_number_integer()) r.width = j["width"].get<int>();
  if (j.contains("height") && j["height"].is_number_integer()) r.height = j["height"].get<int>();
  return r;
}

Result<std::vector<BenchRecord>> read_records(const std::string& path) {
  std::vector<BenchRecord> out;
  if (path.empty() || !file_exists(path)) return out;
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path));
  size_t pos = 0;
  int line_no = 0;
  while (pos < text.size()) {
    const size_t nl = text.find('\n', pos);
    ++line_no;
    if (nl == std::string::npos) break;  // torn last line: ignored
    const std::string line = text.substr(pos, nl - pos);
    pos = nl + 1;
    if (line.empty()) continue;
    MACRO_ASSIGN_OR_RETURN(BenchRecord r,
                           record_from_json(line, path + " line " + std::to_string(line_no)));
    out.push_back(std::move(r));
  }
  return out;
}

RecordAppender::~RecordAppender() {
  if (fd_ >= 0) ::close(fd_);
}

Status RecordAppender::open(const std::string& path) {
  path_ = path;
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd_ < 0) return Status::error(path + ": cannot open for appending: " + std::strerror(errno));
  // Cut a torn last line (no newline) so the next record starts on a line of its own.
  const off_t size = ::lseek(fd_, 0, SEEK_END);
  if (size > 0) {
    off_t keep = size;
    char buf[4096];
    bool found = false;
    while (keep > 0 && !found) {
      const off_t chunk = std::min<off_t>(keep, off_t(sizeof buf));
      if (::pread(fd_, buf, size_t(chunk), keep - chunk) != chunk)
        return Status::error(path + ": read failed: " + std::strerror(errno));
      for (off_t i = chunk; i > 0; --i)
        if (buf[i - 1] == '\n') {
          keep = keep - chunk + i;
          found = true;
          break;
        }
      if (!found) keep -= chunk;
    }
    if (keep != size) {
      log_info("bench",
               path + ": dropping a torn last line (" + std::to_string(size - keep) + " bytes)");
      if (::ftruncate(fd_, keep) != 0)
        return Status::error(path +
                             ": cannot truncate the torn last line: " + std::strerror(errno));
    }
  }
  return Status::ok();
}

Status RecordAppender::append(const BenchRecord& record) {
  if (fd_ < 0) return Status::error("bench results: append before open");
  const std::string line = record_to_json_line(record);
  const ssize_t n = ::write(fd_, line.data(), line.size());
  if (n != ssize_t(line.size()))
    return Status::error(
        path_ + ": write failed: " + (n < 0 ? std::string(std::strerror(errno)) : "short write"));
  if (::fsync(fd_) != 0) return Status::error(path_ + ": fsync failed: " + std::strerror(errno));
  return Status::ok();
}

std::vector<BenchRecord> merge_records(const std::vector<std::vector<BenchRecord>>& inputs) {
  std::map<std::string, BenchRecord> by_key;
  for (const auto& list : inputs)
    for (const BenchRecord& r : list) {
      auto it = by_key.find(r.key());
      if (it == by_key.end()) {
        by_key.emplace(r.key(), r);
      } else if (!it->second.ok && r.ok) {
        it->second = r;
      }
    }
  std::vector<BenchRecord> out;
  for (auto& [k, r] : by_key) out.push_back(std::move(r));
  std::stable_sort(out.begin(), out.end(), record_order);
  return out;
}

Status write_records_atomic(const std::string& path, const std::vector<BenchRecord>& records) {
  std::string text;
  for (const BenchRecord& r : records) text += record_to_json_line(r);
  return write_file_atomic(path, text);
}

// ---- Running -----------------------------------------------------------------------------------
std::optional<double> training_log_seconds(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return std::nullopt;
  // The last lines: a step line is a few hundred bytes; the final evaluation line can list many
  // views, so read up to 64 KiB from the end.
  std::string tail;
  if (std::fseek(f, 0, SEEK_END) == 0) {
    const long size = std::ftell(f);
    const long from = std::max(0L, size - 65536L);
    if (size > 0 && std::fseek(f, from, SEEK_SET) == 0) {
      tail.resize(size_t(size - from));
      tail.resize(std::fread(tail.data(), 1, tail.size(), f));
    }
  }
  std::fclose(f);
  std::optional<double> seconds;
  size_t start = 0;
  while (start < tail.size()) {
    size_t end = tail.find('\n', start);
    if (end == std::string::npos) end = tail.size();
    const Json j = Json::parse(tail.substr(start, end - start), nullptr, false);
    if (j.is_object() && j.contains("step") && j.contains("seconds") && j["seconds"].is_number())
      seconds = j["seconds"].get<double>();
    start = end + 1;
  }
  return seconds;
}

BenchRecord run_work_item(const BenchWorkItem& item, const MethodRegistry& registry,
                          const MetricOptions& metric_options, PairInputsCache* cache) {
  BenchRecord r;
  r.scene = item.pair.scene;
  r.pair_index = item.pair.pair_index;
  r.training_frame = item.pair.pair.training_frame;
  r.closeup_frame = item.pair.pair.closeup_frame;
  r.depth_ratio = item.pair.pair.depth_ratio;
  r.method = item.method;
  r.options = item.options;
  r.options_hash = item.options_hash;
  const auto skip = [&](const std::string& reason) {
    r.ok = false;
    r.reason = reason;
    return r;
  };
  const BenchMethod* method = registry.find(item.method);
  if (!method) return skip("unknown method '" + item.method + "'");

  // GT first: a missing GT skips the pair before anything is loaded.
  const std::string gt_path =
      (fs::path(item.pair.scene_dir) / "closeup_gt" / item.pair.pair.closeup_frame).string();
  if (!file_exists(gt_path)) return skip("missing GT: " + gt_path);
  auto t0 = std::chrono::steady_clock::now();
  Result<gs::Image> gt = gs::read_image(gt_path);
  if (!gt) return skip("unreadable GT: " + gt.status().message());
  r.width = gt->width;
  r.height = gt->height;

  const std::string pair_key = item.pair.scene_dir + "\t" + item.pair.pair.closeup_frame;
  PairInputsCache local;
  if (!cache) cache = &local;
  if (cache->key != pair_key || !cache->inputs) {
    cache->key.clear();
    cache->inputs.reset();
    SceneInputOptions so;
    so.scene_dir = item.pair.scene_dir;
    so.closeup = item.pair.pair.closeup_frame;
    Result<SceneInputs> inputs = load_scene_inputs(so);
    if (!inputs) return skip("missing pose or scene input: " + inputs.status().message());
    cache->inputs = std::move(*inputs);
    cache->key = pair_key;
  }
  r.seconds.push_back({"load", seconds_since(t0)});  // GT read (+ scene load when not cached)

  const MethodContext context{item.pair, *cache->inputs, item.options};
  Result<MethodOutput> out = method->run(context);
  if (!out) return skip("no output: " + out.status().message());
  if (out->image.data.empty()) return skip("no output: the method produced an empty image");
  r.enhancer = out->enhancer;
  r.planes_dropped = out->planes_dropped;
  for (const MethodStage& s : out->stages) {
    r.seconds.push_back(s);
    if (s.per_closeup) r.seconds_per_closeup += s.seconds;
  }
  if (!method->reconstruction_log.empty())
    r.reconstruction_seconds =
        training_log_seconds((fs::path(item.pair.scene_dir) / method->reconstruction_log).string());

  t0 = std::chrono::steady_clock::now();
  Result<std::vector<MetricValue>> metrics = compute_metrics(out->image, *gt, metric_options);
  if (!metrics) return skip("metrics failed: " + metrics.status().message());
  r.seconds.push_back({"metrics", seconds_since(t0)});
  r.metrics = std::move(*metrics);
  {
    // Sharpness against the GT (metrics.h gradient_energy_ratio), on the prediction at GT size.
    MetricValue g{"grad_ratio", false, 0.0, "", ""};
    Result<gs::Image> sized = match_size(out->image, gt->width, gt->height);
    Result<double> ratio =
        sized ? gradient_energy_ratio(*sized, *gt) : Result<double>(sized.status());
    if (ratio) {
      g.computed = true;
      g.value = *ratio;
    } else {
      g.reason = ratio.status().message();
    }
    r.metrics.push_back(g);
  }
  r.ok = true;
  return r;
}

namespace {

// The first camera of a scene folder (its reference cameras, then the split's close-up
// intrinsics) with lens distortion, as "camera 'NAME' (MODEL k1=...)"; "" when none has any.
Result<std::string> distorted_camera(const std::string& dir) {
  gs::CameraLoadOptions lenient;
  MACRO_ASSIGN_OR_RETURN(gs::CameraSet set, gs::load_cameras(dir, lenient));
  for (const gs::Camera& c : set.cameras)
    if (c.has_distortion()) return "camera '" + c.name + "' (" + c.model_text() + ")";
  const std::string split = (fs::path(dir) / "split.json").string();
  if (file_exists(split)) {
    MACRO_ASSIGN_OR_RETURN(gs::CloseupSplit sp, gs::load_closeup_split(split, lenient));
    if (!sp.closeups.cameras.empty() && sp.closeups.cameras.front().has_distortion())
      return "the split's intrinsics (" + sp.closeups.cameras.front().model_text() + ")";
  }
  return std::string();
}

// A distorted scene is scored as gsplat trains and evaluates it: undistorted once (gs/cameras/
// undistort_scene.h, gsplat's K hand-over) into CACHE/<scene>, which later runs reuse (its marker
// file names the source folder and is written last). Returns the folder to read.
Result<std::string> undistorted_scene(const std::string& dir, const std::string& cache) {
  MACRO_ASSIGN_OR_RETURN(std::string which, distorted_camera(dir));
  if (which.empty()) return dir;
  const std::string out = (fs::path(cache) / fs::path(dir).filename()).string();
  const std::string marker = out + "/.undistorted-from";
  const std::string source = fs::absolute(dir).lexically_normal().string() + "\n";
  if (auto m = read_text_file(marker); m && *m == source) return out;
  log_info("bench", dir + ": " + which +
                        " has lens distortion: undistorting it as gsplat does "
                        "into " +
                        out);
  MACRO_TRY(gs::undistort_scene_folder(dir, out).status().with_context("bench: " + dir));
  MACRO_TRY(write_file_atomic(marker, source));
  return out;
}

}  // namespace

Result<BenchRunSummary> run_benchmark(const BenchRunOptions& options,
                                      const MethodRegistry& registry) {
  if (options.results.empty()) return Status::error("--results: a results file is required");
  MACRO_ASSIGN_OR_RETURN(
      std::vector<BenchWorkItem> all,
      build_work_list(options.root, options.methods, options.option_sets, registry));
  const std::vector<BenchWorkItem> items = take_shard(all, options.shard);
  BenchRunSummary summary;
  summary.work_items = items.size();

  RecordAppender appender;
  MACRO_TRY(appender.open(options.results));  // cuts a torn last line first
  MACRO_ASSIGN_OR_RETURN(std::vector<BenchRecord> existing, read_records(options.results));
  std::set<std::string> done;
  for (const BenchRecord& r : existing) done.insert(r.key());

  std::vector<const BenchWorkItem*> todo;
  for (const BenchWorkItem& it : items) {
    if (done.count(it.key())) {
      ++summary.already_done;
    } else {
      todo.push_back(&it);
    }
  }
  if (options.limit > 0 && todo.size() > size_t(options.limit)) todo.resize(size_t(options.limit));

  if (todo.empty()) return summary;
  // Scenes with lens distortion are read from their undistorted copies.
  std::map<std::string, std::string> scene_dirs;
  for (const BenchWorkItem* it : todo) {
    const std::string& dir = it->pair.scene_dir;
    if (scene_dirs.count(dir)) continue;
    MACRO_ASSIGN_OR_RETURN(scene_dirs[dir],
                           undistorted_scene(dir, options.results + ".undistorted"));
  }
  Progress progress("bench", todo.size());
  PairInputsCache cache;
  for (const BenchWorkItem* it : todo) {
    BenchWorkItem item = *it;
    item.pair.scene_dir = scene_dirs.at(item.pair.scene_dir);
    BenchRecord r = run_work_item(item, registry, options.metrics, &cache);
    MACRO_TRY(appender.append(r));
    ++summary.ran;
    if (r.ok) {
      ++summary.ok;
    } else {
      ++summary.skipped;
      log_info("bench",
               r.scene + " " + r.closeup_frame + " " + r.method + ": skipped: " + r.reason);
    }
    progress.advance();
  }
  progress.finish();
  return summary;
}

}  // namespace macro::enhance
