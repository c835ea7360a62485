// Evaluation harness: records, resume, shards, merge, the averaging protocol, the report files and
// an end-to-end `macro bench` run on synthetic DL3DV-Closeup folders.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/bench/bench_report.h"
#include "enhance/datasets/synth_scene_folder.h"
#include "enhance/scene_input.h"
#include "gs/cameras/camera.h"
#include "gs/image_io.h"
#include "gs/synth/synth.h"
#include "tests/test_support.h"

namespace macro {
namespace {
namespace fs = std::filesystem;
using namespace enhance;

// Two tiny scenes: "scene_a" (GT = the render: PSNR +inf) and "scene_b" (GT brightened by
// 0.02, so 3dgs scores a finite PSNR), each with 3 close-up pairs. If drop_gt, scene_b loses the GT
// of its second close-up (a skip).
void make_root(const std::string& root, bool drop_gt = false) {
  for (int s = 0; s < 2; ++s) {
    gs::SynthParams p;
    p.seed = 11 + uint64_t(s);
    p.kind = gs::SynthKind::kPlanes;
    p.background = false;
    p.gaussians = 6'000;
    p.width = 96;
    p.height = 64;
    p.training_views = 4;
    p.closeup_views = 3;
    auto scene = gs::generate_synthetic_scene(p);
    REQUIRE(scene.is_ok());
    const std::string dir = root + (s == 0 ? "/scene_a" : "/scene_b");
    REQUIRE(write_closeup_scene_folder(*scene, dir).is_ok());
    if (s == 1) {
      std::vector<std::string> gts;
      for (const auto& e : fs::directory_iterator(dir + "/closeup_gt")) gts.push_back(e.path());
      std::sort(gts.begin(), gts.end());
      for (const std::string& g : gts) {
        auto img = gs::read_image(g);
        REQUIRE(img.is_ok());
        for (float& v : img->data) v = std::min(1.f, v + 0.02f);
        REQUIRE(gs::write_png(g, *img).is_ok());
      }
      if (drop_gt) fs::remove(gts[1]);
    }
  }
}

std::vector<std::string> lines_of(const std::string& path) {
  std::ifstream f(path);
  std::vector<std::string> out;
  for (std::string l; std::getline(f, l);) out.push_back(l);
  return out;
}

const MetricValue* find_metric(const BenchRecord& r, const std::string& name) {
  for (const MetricValue& m : r.metrics)
    if (m.name == name) return &m;
  return nullptr;
}

// A cheap method for shard/merge tests: a flat grey image; uses option K.
MethodRegistry test_registry() {
  MethodRegistry r = default_method_registry();
  REQUIRE(r.add({"grey",
                 "flat grey",
                 {"K"},
                 [](const MethodContext& c) -> Result<MethodOutput> {
                   MethodOutput o;
                   const float level =
                       c.options.count("K") ? 0.1f * std::stof(c.options.at("K")) : 0.5f;
                   o.image = gs::Image(c.inputs.closeup.width, c.inputs.closeup.height, 3);
                   std::fill(o.image.data.begin(), o.image.data.end(), level);
                   o.stages.push_back({"enhance", 0.001});
                   return o;
                 }})
              .is_ok());
  return r;
}

TEST_CASE("bench harness: records append, resume, torn last line, skip rules", "[harness]") {
  set_quiet(true);
  test::TempDir tmp("bench-resume");
  make_root(tmp.file("root"), /*drop_gt=*/true);
  BenchRunOptions o;
  o.root = tmp.file("root");
  o.results = tmp.file("results.jsonl");
  const MethodRegistry reg = default_method_registry();

  auto first = run_benchmark(o, reg);
  REQUIRE(first.is_ok());
  CHECK(first->work_items == 6);
  CHECK(first->ran == 6);
  CHECK(first->skipped == 1);
  auto recs = read_records(o.results);
  REQUIRE(recs.is_ok());
  REQUIRE(recs->size() == 6);
  size_t skipped = 0;
  for (const BenchRecord& r : *recs) {
    CHECK(r.method == "3dgs");
    CHECK(r.options.empty());
    if (!r.ok) {
      ++skipped;
      CHECK(r.scene == "scene_b");
      CHECK(r.reason.find("missing GT") != std::string::npos);
      continue;
    }
    const MetricValue* psnr = find_metric(r, "psnr");
    REQUIRE(psnr);
    REQUIRE(psnr->computed);
    if (r.scene == "scene_a") {
      CHECK(std::isinf(psnr->value));  // GT is the render itself, bit-exact after 8-bit rounding
    } else {
      // GT = render + 0.02 (clamped, 8-bit): PSNR near 20 log10(1 / 0.02) = 34 dB.
      CHECK(psnr->value > 30.0);
      CHECK(psnr->value < 36.0);
    }
    CHECK(r.width == 96);
    CHECK(r.height == 64);
    CHECK(r.seconds_per_closeup > 0);
    const MetricValue* dino = find_metric(r, "dinov2");
    REQUIRE(dino);
    CHECK_FALSE(dino->computed);
    CHECK_FALSE(dino->reason.empty());
  }
  CHECK(skipped == 1);

  // Second run: nothing to do, file unchanged.
  const std::string before = *read_text_file(o.results);
  auto second = run_benchmark(o, reg);
  REQUIRE(second.is_ok());
  CHECK(second->ran == 0);
  CHECK(second->already_done == 6);
  CHECK(*read_text_file(o.results) == before);

  // Kill during the last write: the last line torn. The rerun cuts it and runs that item again.
  const auto size = fs::file_size(o.results);
  fs::resize_file(o.results, size - 25);
  auto third = run_benchmark(o, reg);
  REQUIRE(third.is_ok());
  CHECK(third->ran == 1);
  const auto lines = lines_of(o.results);
  CHECK(lines.size() == 6);
  auto again = read_records(o.results);
  REQUIRE(again.is_ok());
  std::set<std::string> keys;
  for (const BenchRecord& r : *again) keys.insert(r.key());
  CHECK(keys.size() == 6);
  CHECK(read_text_file(o.results)->back() == '\n');

  // --limit: at most N new records.
  BenchRunOptions lim = o;
  lim.results = tmp.file("limited.jsonl");
  lim.limit = 2;
  auto l = run_benchmark(lim, reg);
  REQUIRE(l.is_ok());
  CHECK(l->ran == 2);
}

TEST_CASE("bench harness: shards cover the work list once, merge reproduces the unsharded run",
          "[harness]") {
  set_quiet(true);
  test::TempDir tmp("bench-shard");
  make_root(tmp.file("root"));
  const MethodRegistry reg = test_registry();
  const std::vector<BenchOptions> grid = expand_option_grid({{"K", {"1", "3"}}, {"P", {"4"}}});
  REQUIRE(grid.size() == 2);
  auto work = build_work_list(tmp.file("root"), {"grey", "3dgs"}, grid, reg);
  REQUIRE(work.is_ok());
  // 2 scenes x 3 pairs x (3dgs once + grey K=1, K=3)
  REQUIRE(work->size() == 18);
  for (int n : {1, 2, 3, 5, 7, 40}) {
    std::multiset<std::string> seen;
    for (int i = 0; i < n; ++i)
      for (const BenchWorkItem& w : take_shard(*work, {i, n})) seen.insert(w.key());
    CHECK(seen.size() == work->size());
    CHECK(std::set<std::string>(seen.begin(), seen.end()).size() == work->size());
  }
  CHECK_FALSE(parse_shard("3/3").is_ok());
  CHECK_FALSE(parse_shard("a/2").is_ok());
  CHECK_FALSE(parse_shard("1").is_ok());
  CHECK(parse_shard("2/3")->index == 2);
  CHECK_FALSE(build_work_list(tmp.file("root"), {"nope"}, grid, reg).is_ok());

  BenchRunOptions o;
  o.root = tmp.file("root");
  o.methods = {"3dgs", "grey"};
  o.option_sets = grid;
  o.metrics.feature_metrics = false;
  o.results = tmp.file("all.jsonl");
  REQUIRE(run_benchmark(o, reg).is_ok());
  std::vector<std::vector<BenchRecord>> parts;
  for (int i = 0; i < 3; ++i) {
    BenchRunOptions s = o;
    s.shard = {i, 3};
    s.results = tmp.file("shard" + std::to_string(i) + ".jsonl");
    auto sum = run_benchmark(s, reg);
    REQUIRE(sum.is_ok());
    CHECK(sum->ran == 6);
    parts.push_back(*read_records(s.results));
  }
  parts.push_back(parts[0]);  // a file given twice: deduplicated
  const auto merged = merge_records(parts);
  const auto all = merge_records({*read_records(o.results)});
  REQUIRE(merged.size() == 18);
  REQUIRE(all.size() == 18);
  for (size_t i = 0; i < merged.size(); ++i) {
    CHECK(merged[i].key() == all[i].key());
    CHECK(merged[i].ok == all[i].ok);
    for (const char* m : {"psnr", "ssim"}) {
      const MetricValue* a = find_metric(merged[i], m);
      const MetricValue* b = find_metric(all[i], m);
      REQUIRE(a);
      REQUIRE(b);
      CHECK(a->value == b->value);  // deterministic: bit-identical
    }
  }
  // Merged file: atomic write, one record per line, readable.
  REQUIRE(write_records_atomic(tmp.file("merged.jsonl"), merged).is_ok());
  CHECK(lines_of(tmp.file("merged.jsonl")).size() == 18);
  CHECK(read_records(tmp.file("merged.jsonl"))->size() == 18);
}

TEST_CASE("bench harness: enhance methods registered, options recorded, missing weights skip",
          "[harness]") {
  set_quiet(true);
  test::TempDir tmp("bench-enhance");
  make_root(tmp.file("root"));
  BenchMethodSettings settings;
  settings.difix_weights = tmp.file("no-weights");
  const MethodRegistry reg = default_method_registry(settings);
  for (const char* m : {"3dgs", "difix", "macro", "macro-unmasked"}) CHECK(reg.find(m));
  const auto grid =
      expand_option_grid({{"K", {"1", "3"}}, {"mask", {"on"}}, {"precision", {"bf16"}}});
  auto work = build_work_list(tmp.file("root"), {"macro", "difix"}, grid, reg);
  REQUIRE(work.is_ok());
  REQUIRE(work->size() == 2 * 3 * 3);  // per pair: difix once (precision), macro K=1 and K=3
  CHECK((*work)[0].method == "difix");
  CHECK(canonical_options((*work)[0].options) == "precision=bf16");
  CHECK(canonical_options((*work)[1].options) == "K=1,mask=on,precision=bf16");
  BenchRecord r = run_work_item((*work)[1], reg, {});
  CHECK_FALSE(r.ok);
  CHECK(r.reason.find("no output") == 0);
  CHECK(r.options.at("K") == "1");
  // A bad option value is a skip naming the option.
  BenchWorkItem bad = (*work)[1];
  bad.options["K"] = "x";
  r = run_work_item(bad, reg, {});
  CHECK(r.reason.find("option K") != std::string::npos);
}

BenchRecord hand_record(const std::string& scene, int pair, const std::string& method,
                        std::map<std::string, double> metrics, double seconds, bool ok = true) {
  BenchRecord r;
  r.scene = scene;
  r.pair_index = pair;
  r.closeup_frame = "c" + std::to_string(pair) + ".png";
  r.method = method;
  r.options_hash = options_hash({});
  r.ok = ok;
  r.depth_ratio = 2.0 + pair;
  r.seconds_per_closeup = seconds;
  for (const char* name : {"psnr", "ssim", "lpips_alex", "dinov2", "dreamsim"}) {
    MetricValue m;
    m.name = name;
    if (auto it = metrics.find(name); it != metrics.end()) {
      m.computed = true;
      m.value = it->second;
    } else {
      m.reason = "weights not found";
    }
    r.metrics.push_back(m);
  }
  if (!ok) r.metrics.clear(), r.reason = "missing GT";
  return r;
}

TEST_CASE("bench report: scene means then the mean of scene means, n/c never averaged",
          "[harness]") {
  std::vector<BenchRecord> recs = {
      hand_record("A", 0, "m", {{"psnr", 10}, {"ssim", 0.5}, {"lpips_alex", 0.2}}, 1.0),
      hand_record("A", 1, "m", {{"psnr", 20}, {"ssim", 0.7}}, 3.0),
      hand_record("B", 0, "m", {{"psnr", 30}, {"ssim", 0.9}}, 6.0),
      hand_record("B", 1, "m", {{"psnr", 99}}, 0, /*ok=*/false),
      hand_record("A", 0, "x", {{"psnr", 12}, {"ssim", 0.4}, {"dinov2", 0.3}}, 2.0),
  };
  // Round trip through JSON lines first: the report reads what the harness writes.
  for (BenchRecord& r : recs) {
    auto back = record_from_json(record_to_json_line(r), "test");
    REQUIRE(back.is_ok());
    r = *back;
  }
  const auto configs = aggregate_records(recs);
  REQUIRE(configs.size() == 2);
  const ConfigResult& m = configs[0];
  REQUIRE(m.method == "m");
  CHECK(m.metric.at("psnr") == Approx(22.5));  // (mean(10, 20) + 30) / 2, not mean of pairs (20)
  CHECK(m.metric.at("ssim") == Approx((0.6 + 0.9) / 2));
  CHECK(m.metric.at("lpips_alex") == Approx(0.2));  // only scene A has it
  CHECK(m.metric.count("dinov2") == 0);
  CHECK(*m.seconds_per_closeup == Approx((2.0 + 6.0) / 2));
  CHECK(m.scenes == 2);
  CHECK(m.pairs_ok == 3);
  CHECK(m.pairs_skipped == 1);
  CHECK(m.scene_means.at("A").at("psnr") == Approx(15));

  const std::string md = table_markdown(configs);
  CHECK(md.find("| m | 22.50 | 0.750 | 0.200 | n/c |") != std::string::npos);
  CHECK(md.find("| x | 12.00 | 0.400 | n/c | 0.300 |") != std::string::npos);
  CHECK(md.find("DreamSim") == std::string::npos);  // never computed: no column
  const std::string csv = table_csv(configs);
  CHECK(csv.find("method,options,psnr,ssim,lpips_alex,dinov2,seconds_per_closeup") == 0);
  CHECK(csv.find("m,,22.5,0.75,0.2,n/c,4,n/a,2,3,1") != std::string::npos);
  CHECK(format_metric("psnr", std::nullopt) == "n/c");
  CHECK(md.find("full s / close-up") == std::string::npos);  // no record has a training log
}

TEST_CASE("bench report: the full cost adds the reconstruction's training to each close-up",
          "[harness]") {
  test::TempDir tmp("bench-full-cost");
  // The log's last step line gives the cost, wherever the final evaluation line is.
  REQUIRE(write_file_atomic(tmp.file("log.jsonl"),
                            "{\"scene_dir\": \"x\"}\n{\"step\": 0, \"seconds\": 0.5}\n"
                            "{\"step\": 1, \"seconds\": 100.25}\n{\"eval\": \"test\", "
                            "\"psnr\": 20}\n")
              .is_ok());
  REQUIRE(training_log_seconds(tmp.file("log.jsonl")).has_value());
  CHECK(*training_log_seconds(tmp.file("log.jsonl")) == 100.25);
  CHECK(!training_log_seconds(tmp.file("missing.jsonl")).has_value());
  REQUIRE(write_file_atomic(tmp.file("empty.jsonl"), "{\"scene_dir\": \"x\"}\n").is_ok());
  CHECK(!training_log_seconds(tmp.file("empty.jsonl")).has_value());

  std::vector<BenchRecord> recs = {
      hand_record("A", 0, "m", {{"psnr", 10}}, 1.0), hand_record("A", 1, "m", {{"psnr", 20}}, 3.0),
      hand_record("B", 0, "m", {{"psnr", 30}}, 6.0), hand_record("A", 0, "x", {{"psnr", 12}}, 2.0),
      hand_record("B", 0, "x", {{"psnr", 12}}, 2.0)};
  recs[0].reconstruction_seconds = recs[1].reconstruction_seconds = 100;
  recs[2].reconstruction_seconds = 50;
  recs[3].reconstruction_seconds = 100;  // x: scene B has no log, so no full cost for x
  for (BenchRecord& r : recs) {
    const std::string line = record_to_json_line(r);
    if (r.reconstruction_seconds)
      CHECK(line.find("\"full_seconds_per_closeup\":") != std::string::npos);
    else
      CHECK(line.find("reconstruction_seconds") == std::string::npos);
    auto back = record_from_json(line, "test");
    REQUIRE(back.is_ok());
    CHECK(back->reconstruction_seconds == r.reconstruction_seconds);
    r = *back;
  }
  const auto configs = aggregate_records(recs);
  REQUIRE(configs.size() == 2);
  REQUIRE(configs[0].full_seconds_per_closeup.has_value());
  // Scene means (102 and 56), then their mean.
  CHECK(*configs[0].full_seconds_per_closeup == Approx((102.0 + 56.0) / 2));
  CHECK(!configs[1].full_seconds_per_closeup.has_value());
  const std::string md = table_markdown(configs);
  CHECK(md.find("| s / close-up | full s / close-up |") != std::string::npos);
  CHECK(md.find("| 4.00 | 79.00 |") != std::string::npos);
  CHECK(md.find("| 2.00 | n/a |") != std::string::npos);
  std::vector<std::string> written;
  REQUIRE(write_report(recs, tmp.file("rep"), &written, SceneFailureRule::kReleased).is_ok());
  CHECK(file_exists(tmp.file("rep/cost_vs_psnr.svg")));
  // Without any full cost there is no such chart.
  recs[0].reconstruction_seconds.reset();
  REQUIRE(write_report(recs, tmp.file("rep2"), &written, SceneFailureRule::kReleased).is_ok());
  CHECK(file_exists(tmp.file("rep2/time_vs_psnr.svg")));
  CHECK(!file_exists(tmp.file("rep2/cost_vs_psnr.svg")));
}

TEST_CASE(
    "bench report: --scene-failure released drops a scene with an empty k-means bin, pair "
    "keeps it",
    "[harness]") {
  std::vector<BenchRecord> recs = {
      hand_record("A", 0, "m", {{"psnr", 10}}, 1.0),
      hand_record("A", 1, "m", {{"psnr", 20}}, 1.0),
      hand_record("B", 0, "m", {{"psnr", 30}}, 1.0),
      hand_record("A", 0, "x", {{"psnr", 12}}, 1.0),
  };
  recs[1].planes_dropped = 1;  // the release raises on this pair: scene A fails for "m"
  recs[1].enhancer = "transfer (weight-free)";
  for (BenchRecord& r : recs) {
    auto back = record_from_json(record_to_json_line(r), "test");
    REQUIRE(back.is_ok());
    r = *back;
  }
  CHECK(recs[1].planes_dropped == 1);
  CHECK(recs[1].enhancer == "transfer (weight-free)");
  CHECK(record_to_json_line(recs[0]).find("planes_dropped") == std::string::npos);

  const auto released = aggregate_records(recs);  // the default
  REQUIRE(released.size() == 2);
  CHECK(released[0].rule == SceneFailureRule::kReleased);
  CHECK(released[0].metric.at("psnr") == Approx(30));  // scene A out of m's average
  CHECK(released[0].scenes == 1);
  CHECK(released[0].scenes_failed == 1);
  CHECK(released[0].pairs_ok == 1);
  CHECK(released[0].pairs_skipped == 2);
  CHECK(released[1].metric.at("psnr") == Approx(12));  // x had no failure in A
  CHECK(released[1].scenes_failed == 0);
  CHECK(table_markdown(released).find("Scene failures: released rule") != std::string::npos);

  const auto pair = aggregate_records(recs, SceneFailureRule::kPair);
  CHECK(pair[0].metric.at("psnr") == Approx(22.5));  // (mean(10, 20) + 30) / 2
  CHECK(pair[0].scenes_failed == 0);
  CHECK(table_markdown(pair).find("Scene failures: pair rule") != std::string::npos);
  CHECK(*parse_scene_failure_rule("pair") == SceneFailureRule::kPair);
  CHECK_THAT(parse_scene_failure_rule("scene").status().message(),
             Catch::Contains("--scene-failure"));
}

// The report's SVG (cairo's): the prolog, one <svg> root with a <title>, and tags that nest and
// close (a minimal well-formedness check: a stack of element names, quotes paired).
void check_svg(const std::string& path) {
  const auto text = read_text_file(path);
  REQUIRE(text.is_ok());
  const std::string& s = *text;
  CHECK(s.rfind("<?xml", 0) == 0);
  CHECK(s.find("<svg xmlns=\"http://www.w3.org/2000/svg\"") != std::string::npos);
  CHECK(s.find("<title>") != std::string::npos);
  std::vector<std::string> open;
  size_t elements = 0;
  for (size_t i = s.find('<'); i != std::string::npos; i = s.find('<', i + 1)) {
    const size_t end = s.find('>', i);
    REQUIRE(end != std::string::npos);
    const std::string tag = s.substr(i + 1, end - i - 1);
    CHECK(std::count(tag.begin(), tag.end(), '"') % 2 == 0);
    if (tag[0] == '?' || tag[0] == '!') continue;
    ++elements;
    const std::string name =
        tag.substr(tag[0] == '/', tag.find_first_of(" /", 1) - (tag[0] == '/'));
    if (tag[0] == '/') {
      REQUIRE_FALSE(open.empty());
      CHECK(open.back() == name);
      open.pop_back();
    } else if (tag.back() != '/') {
      open.push_back(name);
    }
    i = end;
  }
  CHECK(open.empty());
  CHECK(elements > 10);
}

TEST_CASE("bench report files: table, SVG well formed, PDF, PNG at twice the chart size",
          "[harness]") {
  test::TempDir tmp("bench-report");
  std::vector<BenchRecord> recs = {
      hand_record("A", 0, "m", {{"psnr", 10}, {"ssim", 0.5}}, 1.0),
      hand_record("B", 1, "m<&>", {{"psnr", 14}, {"ssim", 0.6}}, 4.0),
  };
  std::vector<std::string> written;
  REQUIRE(write_report(recs, tmp.file("rep"), &written).is_ok());
  for (const char* f : {"table.md", "table.csv", "time_vs_psnr.svg", "time_vs_psnr.png",
                        "zoom_ssim.svg", "zoom_ssim.png", "scenes_lpips_alex.svg",
                        "scenes_psnr.png", "time_vs_psnr.pdf", "scenes_lpips_alex.pdf"})
    CHECK(file_exists(tmp.file(std::string("rep/") + f)));
  CHECK_FALSE(file_exists(tmp.file("rep/time_vs_dinov2.svg")));
  for (const std::string& p : written) {
    if (p.size() > 4 && p.substr(p.size() - 4) == ".svg") check_svg(p);
  }
  auto png = gs::read_image(tmp.file("rep/time_vs_psnr.png"));
  REQUIRE(png.is_ok());
  CHECK(png->width == 2 * 640);  // charts are 640 x 420 units, PNGs drawn at scale 2
  CHECK(png->height == 2 * 420);
  CHECK(read_text_file(tmp.file("rep/time_vs_psnr.pdf"))->rfind("%PDF-", 0) == 0);
  // Not blank: the point colours appear.
  size_t coloured = 0;
  for (size_t i = 0; i < png->pixels(); ++i) {
    const float* p = &png->data[i * 3];
    if (std::fabs(p[0] - p[1]) > 0.2f || std::fabs(p[1] - p[2]) > 0.2f) ++coloured;
  }
  CHECK(coloured > 50);
}

TEST_CASE("bench run scores a scene with lens distortion on its undistorted copy", "[harness]") {
  test::TempDir tmp("bench-distorted");
  make_root(tmp.file("root"));
  fs::remove_all(tmp.file("root/scene_b"));
  const std::string dir = tmp.file("root/scene_a");
  // The scene's cameras and the split's intrinsics become OPENCV with a small k1.
  auto cams = gs::load_cameras(dir);
  REQUIRE(cams.is_ok());
  for (gs::Camera& c : cams->cameras) {
    c.model = gs::CameraModel::kOpenCV;
    c.distortion = {0.05, 0, 0, 0};
  }
  REQUIRE(gs::save_colmap_text(*cams, dir + "/sparse/0").is_ok());
  std::string split = *read_text_file(dir + "/split.json");
  const size_t at = split.find("\"intrinsics\"");
  REQUIRE(at != std::string::npos);
  const size_t brace = split.find('{', at);
  split.insert(brace + 1, "\"k1\": 0.05, \"camera_model\": \"OPENCV\", ");
  REQUIRE(write_file_atomic(dir + "/split.json", split).is_ok());
  // Loading it directly is refused; the benchmark undistorts it first and scores every pair.
  SceneInputOptions so;
  so.scene_dir = dir;
  so.closeup = gs::load_closeup_split(dir + "/split.json")->closeup_eval_pairs.at(0).closeup_frame;
  auto refused = load_scene_inputs(so);
  REQUIRE_FALSE(refused.is_ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("macro undistort"));
  BenchRunOptions o;
  o.root = tmp.file("root");
  o.results = tmp.file("r.jsonl");
  set_quiet(true);
  auto summary = run_benchmark(o, default_method_registry());
  REQUIRE(summary.is_ok());
  CHECK(summary->ran == 3);
  CHECK(summary->ok == 3);
  const std::string copy = tmp.file("r.jsonl.undistorted/scene_a");
  auto undistorted = gs::load_cameras(copy);
  REQUIRE(undistorted.is_ok());
  for (const gs::Camera& c : undistorted->cameras) CHECK_FALSE(c.has_distortion());
  auto records = read_records(o.results);
  REQUIRE(records.is_ok());
  REQUIRE(!records->empty());
  auto gt = gs::read_image(copy + "/closeup_gt/" + records->front().closeup_frame);
  REQUIRE(gt.is_ok());
  // The copy's pinhole camera is OpenCV's new K, not the distorted camera's.
  CHECK(std::abs(undistorted->cameras.front().fx - cams->cameras.front().fx) > 1e-3);
  auto split_copy = gs::load_closeup_split(copy + "/split.json");
  REQUIRE(split_copy.is_ok());
  CHECK_FALSE(split_copy->closeups.cameras.front().has_distortion());
  CHECK(gt->width == split_copy->closeups.cameras.front().width);
  for (const BenchRecord& r : *records) CHECK(r.width == gt->width);
  // A second run reuses the copy (the marker names the source).
  const auto stamp = fs::last_write_time(copy + "/.undistorted-from");
  o.results = tmp.file("r.jsonl");
  fs::remove(tmp.file("r.jsonl"));
  REQUIRE(run_benchmark(o, default_method_registry()).is_ok());
  CHECK(fs::last_write_time(copy + "/.undistorted-from") == stamp);
}

TEST_CASE("macro bench run, merge and report end to end on synthetic scene folders",
          "[harness][cli]") {
  test::TempDir tmp("bench-e2e");
  make_root(tmp.file("root"));
  const std::string exe = test::macro_exe();
  const auto sh = [&](const std::string& args) {
    return std::system(
        (exe + " bench " + args + " --quiet > " + tmp.file("out.txt") + " 2>&1").c_str());
  };
  for (int i = 0; i < 2; ++i)
    REQUIRE(sh("run --root " + tmp.file("root") + " --methods 3dgs --shard " + std::to_string(i) +
               "/2 --results " + tmp.file("s" + std::to_string(i) + ".jsonl")) == 0);
  REQUIRE(std::system((exe + " bench merge " + tmp.file("s0.jsonl") + " " + tmp.file("s1.jsonl") +
                       " --out " + tmp.file("all.jsonl") + " > /dev/null")
                          .c_str()) == 0);
  CHECK(lines_of(tmp.file("all.jsonl")).size() == 6);
  REQUIRE(sh("report --results " + tmp.file("all.jsonl") + " --out " + tmp.file("report")) == 0);
  const std::string md = *read_text_file(tmp.file("report/table.md"));
  CHECK(md.find("| Method | PSNR ↑ | SSIM ↑ | LPIPS ↓ |") == 0);
  CHECK(md.find("| 3dgs |") != std::string::npos);
  CHECK(md.find("| 2 | 6 | 0 |") != std::string::npos);  // scenes, pairs ok, skipped
  check_svg(tmp.file("report/time_vs_psnr.svg"));
  CHECK(gs::read_image(tmp.file("report/scenes_ssim.png")).is_ok());
  // Bad input: clear errors, exit code 1.
  CHECK(sh("run --root " + tmp.file("nowhere") + " --results " + tmp.file("x.jsonl")) != 0);
  CHECK(read_text_file(tmp.file("out.txt"))->find("benchmark root not found") != std::string::npos);
  CHECK(sh("run --root " + tmp.file("root") + " --methods nope --results " + tmp.file("x.jsonl")) !=
        0);
  CHECK(read_text_file(tmp.file("out.txt"))->find("unknown method 'nope'") != std::string::npos);
  CHECK(sh("frobnicate") != 0);
}

}  // namespace
}  // namespace macro
