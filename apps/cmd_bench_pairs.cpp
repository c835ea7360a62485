// macro bench pairs: a COLMAP scene -> a close-up split JSON (the paper's appendix D), readable by
// `macro bench run`. The construction is enhance/datasets/pair_construction.h; docs/benchmark.md
// "Pair construction" describes it.
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "apps/args.h"
#include "apps/bench_commands.h"
#include "attention/runtime/progress.h"
#include "enhance/datasets/pair_construction.h"
#include "enhance/datasets/scene_ranking.h"

namespace macro::cli {
namespace {
namespace fs = std::filesystem;

constexpr const char* kUsage =
    "       macro bench pairs --scene DIR --out split.json [--training-views 16]\n"
    "                         [--min-depth-ratio 2] [--min-iou 0.4] [--angle 10,60] [--seed S]\n"
    "                         [--name SCENE] [--copy-gt]\n"
    "       macro bench pairs --root DIR [--out-dir OUT] [--top N] [--min-score S]\n"
    "                         [--split-name split.json] [--overwrite] [--copy-gt] [--quiet]\n"
    "                         [--threads N] [construction flags as above]\n"
    "  pairs   close-up pairs from a COLMAP scene (DIR, DIR/sparse/0, ...: cameras, images,\n"
    "          points3D), the paper's appendix D; --copy-gt copies DIR/images/<close-up> to\n"
    "          closeup_gt/ beside the output, so `bench run` can score the pairs. With --root,\n"
    "          every sub-folder holding a COLMAP model, ranked by the scene score (D.4): splits\n"
    "          in DIR/<scene>/ (or OUT/<scene>/), ranking.{json,md,csv} in DIR (or OUT); exit 1\n"
    "          only when every scene fails.\n";

Result<uint64_t> parse_seed(const std::string& text) {
  errno = 0;
  char* end = nullptr;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || text[0] == '-' || *end != '\0' || errno != 0)
    return Status::error("--seed: expected a non-negative integer, found '" + text + "'");
  return uint64_t(v);
}

Result<int> parse_top(const std::string& text) {
  errno = 0;
  char* end = nullptr;
  const long v = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || errno != 0 || v < 1 || v > 1000000)
    return Status::error("--top: expected a number of scenes >= 1, found '" + text + "'");
  return int(v);
}

Result<double> parse_min_score(const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !(v >= 0.0) || !std::isfinite(v))
    return Status::error("--min-score: expected a finite number >= 0, found '" + text + "'");
  return v;
}

// --root DIR: every scene of DIR, ranked (enhance::rank_scenes).
int run_root(enhance::RootParams rp) {
  std::vector<std::string> ignored;
  auto scenes = enhance::list_scene_folders(rp.root, &ignored);
  if (!scenes) return fail("bench pairs", scenes.status().with_context("--root"));
  if (scenes->empty())
    return fail("bench pairs",
                Status::error("--root: " + rp.root +
                              ": no sub-folder holds a COLMAP model "
                              "(cameras.{bin,txt} or images.{bin,txt} in <scene>, "
                              "<scene>/sparse/0, <scene>/sparse or <scene>/colmap/sparse/0); " +
                              std::to_string(ignored.size()) + " other sub-folders"));
  rp.progress = !quiet();
  if (!rp.out_dir.empty())
    if (Status s = prepare_output_dir(rp.out_dir, "--out-dir"); !s) return fail("bench pairs", s);
  auto ranking = enhance::rank_scenes(rp);
  if (!ranking) return fail("bench pairs", ranking.status());
  if (Status s = enhance::write_ranking(*ranking, rp); !s) return fail("bench pairs", s);
  std::fputs(enhance::ranking_markdown(*ranking, rp).c_str(), stdout);
  const std::string dir = enhance::ranking_dir(rp);
  std::printf(
      "bench pairs: %s, %d with pairs, %d failed, %d selected -> %s/ranking.{json,md,csv}\n",
      count_noun(ranking->scenes.size(), "scene").c_str(), ranking->constructed, ranking->failed,
      ranking->selected, dir.c_str());
  if (ranking->constructed == 0)
    return fail("bench pairs",
                Status::error("every scene of " + rp.root + " failed (reasons above)"));
  return 0;
}

int run_pairs(Args& args) {
  enhance::PairParams p;
  enhance::RootParams rp;
  const auto scene_arg = args.value("--scene");
  const auto root_arg = args.value("--root");
  const auto out_arg = args.value("--out");
  // --root only:
  const auto out_dir = args.value("--out-dir");
  const auto split_name = args.value("--split-name");
  const auto top_text = args.value("--top");
  const auto min_score_text = args.value("--min-score");
  rp.overwrite = args.flag("--overwrite");
  p.training_views = args.int_or("--training-views", p.training_views, 1, 100000);
  p.min_depth_ratio = args.double_or("--min-depth-ratio", p.min_depth_ratio, 1.0, 1e9);
  p.min_iou = args.double_or("--min-iou", p.min_iou, 0.0, 1.0);
  const std::vector<double> angle =
      args.doubles_or("--angle", {p.min_angle_deg, p.max_angle_deg}, 2);
  const auto seed_text = args.value("--seed");
  std::string name = args.value_or("--name", "");
  const bool want_gt = args.flag("--copy-gt");
  if (Status s = args.finish(); !s) return fail("bench pairs", s);
  if (scene_arg && root_arg)
    return fail("bench pairs", Status::error("--scene and --root: give one (--scene: one scene, "
                                             "--root: a folder of scenes)"));
  if (!scene_arg && !root_arg)
    return fail("bench pairs", Status::error("--scene or --root: expected one of them, found "
                                             "neither"));
  if (scene_arg) {
    if (!out_arg) return fail("bench pairs", Status::error("--out: required with --scene"));
    const std::pair<const char*, bool> root_only[] = {{"--out-dir", bool(out_dir)},
                                                      {"--split-name", bool(split_name)},
                                                      {"--top", bool(top_text)},
                                                      {"--min-score", bool(min_score_text)},
                                                      {"--overwrite", rp.overwrite}};
    for (const auto& [flag, given] : root_only)
      if (given)
        return fail("bench pairs", Status::error(std::string(flag) + ": only with --root"));
  } else {
    if (out_arg)
      return fail("bench pairs", Status::error("--out: only with --scene (with --root the splits "
                                               "go to DIR/<scene>/, or --out-dir)"));
    if (!name.empty())
      return fail("bench pairs", Status::error("--name: only with --scene (with --root each "
                                               "scene is named after its folder)"));
    if (root_arg->empty())
      return fail("bench pairs", Status::error("--root: expected a folder, found ''"));
    if (top_text) {
      auto v = parse_top(*top_text);
      if (!v) return fail("bench pairs", v.status());
      rp.top = *v;
    }
    if (min_score_text) {
      auto v = parse_min_score(*min_score_text);
      if (!v) return fail("bench pairs", v.status());
      rp.min_score = *v;
    }
    if (out_dir) {
      if (out_dir->empty())
        return fail("bench pairs", Status::error("--out-dir: expected a folder, found ''"));
      rp.out_dir = *out_dir;
    }
    if (split_name) rp.split_name = *split_name;
  }
  if (angle.size() != 2 || !(angle[0] >= 0 && angle[0] <= angle[1] && angle[1] <= 180))
    return fail("bench pairs", Status::error("--angle: expected MIN,MAX degrees with 0 <= MIN <= "
                                             "MAX <= 180"));
  p.min_angle_deg = angle[0];
  p.max_angle_deg = angle[1];
  if (seed_text) {
    auto seed = parse_seed(*seed_text);
    if (!seed) return fail("bench pairs", seed.status());
    p.seed = *seed;
  }
  p.progress = !quiet();
  if (root_arg) {
    if (rp.split_name.empty() || rp.split_name.find('/') != std::string::npos ||
        rp.split_name == "." || rp.split_name == "..")
      return fail("bench pairs", Status::error("--split-name: expected a plain file name, found '" +
                                               rp.split_name + "'"));
    rp.pair = p;
    rp.root = *root_arg;
    rp.copy_gt = want_gt;
    return run_root(rp);
  }

  const std::string scene = *scene_arg;
  const std::string out = *out_arg;
  if (Status s = check_output_name(out, "--out", {".json"}); !s) return fail("bench pairs", s);
  if (name.empty()) {  // the scene folder's name ("/data/scene/" -> "scene")
    fs::path dir = fs::absolute(scene).lexically_normal();
    if (dir.filename().empty()) dir = dir.parent_path();
    name = dir.filename().string();
  }
  auto built = enhance::load_and_construct(scene, name, p);
  if (!built) return fail("bench pairs", built.status());
  log_info("bench pairs", count_noun(built->cameras.cameras.size(), "camera") + ", " +
                              count_noun(size_t(built->num_points), "point") + " from " +
                              built->model);
  const enhance::PairConstruction& pc = built->pc;
  if (Status s = enhance::check_pairs_found(pc, p); !s)
    return fail("bench pairs", s.with_context(built->model));
  if (pc.training.size() < size_t(p.training_views))
    log_info("bench pairs", "warning: the training pool holds " +
                                count_noun(pc.train_pool.size(), "camera") + ", fewer than " +
                                count_noun(size_t(p.training_views), "training view") +
                                "; all are used");
  if (Status s = prepare_output(out, "--out", {".json"}); !s) return fail("bench pairs", s);
  if (Status s = enhance::write_scene_split(*built, p, out, want_gt); !s)
    return fail("bench pairs", s);
  std::printf(
      "bench pairs: %s (%zu without points), %s, scene score %.6g; %s, %s (%zu test frames "
      "unpaired) -> %s\n",
      count_noun(built->cameras.cameras.size(), "camera").c_str(), pc.no_depth.size(),
      count_noun(pc.candidates.size(), "candidate pair").c_str(), pc.score.score,
      count_noun(pc.training.size(), "training view").c_str(),
      count_noun(pc.eval_pairs.size(), "close-up pair").c_str(), pc.unpaired_tests.size(),
      out.c_str());
  return 0;
}

const bool registered = register_bench_command({"pairs", kUsage, run_pairs});

}  // namespace
}  // namespace macro::cli
