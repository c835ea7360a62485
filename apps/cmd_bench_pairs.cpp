// macro bench pairs: a COLMAP scene -> a close-up split JSON (the paper's appendix D), readable by
// `macro bench run`. The construction is enhance/pair_construction.h; docs/benchmark.md
// "Pair construction" describes it.
#include <cstdio>
#include <filesystem>

#include "apps/args.h"
#include "apps/bench_commands.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "enhance/pair_construction.h"
#include "gs/colmap_points.h"

namespace macro::cli {
namespace {
namespace fs = std::filesystem;

constexpr const char* kUsage =
    "       macro bench pairs --scene DIR --out split.json [--training-views 16]\n"
    "                         [--min-depth-ratio 2] [--min-iou 0.4] [--angle 10,60] [--seed S]\n"
    "                         [--name SCENE] [--copy-gt]\n"
    "  pairs   close-up pairs from a COLMAP scene (DIR, DIR/sparse/0, ...: cameras, images,\n"
    "          points3D), the paper's appendix D; --copy-gt copies DIR/images/<close-up> to\n"
    "          closeup_gt/ beside the output, so `bench run` can score the pairs.\n";

Result<uint64_t> parse_seed(const std::string& text) {
  errno = 0;
  char* end = nullptr;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || text[0] == '-' || *end != '\0' || errno != 0)
    return Status::error("--seed: expected a non-negative integer, found '" + text + "'");
  return uint64_t(v);
}

// DIR/images/<frame> -> OUT_DIR/closeup_gt/<frame>, atomically.
Status copy_gt(const std::string& scene, const std::string& out_dir, const std::string& frame) {
  const fs::path src = fs::path(scene) / "images" / frame;
  const fs::path dst = fs::path(out_dir) / "closeup_gt" / frame;
  if (!file_exists(src.string()))
    return Status::error(src.string() + ": close-up image not found (--copy-gt)");
  std::error_code ec;
  fs::create_directories(dst.parent_path(), ec);
  if (ec)
    return Status::error(dst.parent_path().string() + ": cannot create folder: " + ec.message());
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(src.string()));
  return write_file_atomic(dst.string(), bytes.data(), bytes.size());
}

int run_pairs(Args& args) {
  enhance::PairParams p;
  const std::string scene = args.required("--scene");
  const std::string out = args.required("--out");
  p.training_views = args.int_or("--training-views", p.training_views, 1, 100000);
  p.min_depth_ratio = args.double_or("--min-depth-ratio", p.min_depth_ratio, 1.0, 1e9);
  p.min_iou = args.double_or("--min-iou", p.min_iou, 0.0, 1.0);
  const std::vector<double> angle =
      args.doubles_or("--angle", {p.min_angle_deg, p.max_angle_deg}, 2);
  const auto seed_text = args.value("--seed");
  std::string name = args.value_or("--name", "");
  const bool want_gt = args.flag("--copy-gt");
  if (Status s = args.finish(); !s) return fail("bench pairs", s);
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
  if (name.empty()) {  // the scene folder's name ("/data/scene/" -> "scene")
    fs::path dir = fs::absolute(scene).lexically_normal();
    if (dir.filename().empty()) dir = dir.parent_path();
    name = dir.filename().string();
  }

  auto model = gs::find_colmap_model_folder(scene);
  if (!model) return fail("bench pairs", model.status());
  auto cameras = gs::load_colmap_sparse(*model);
  if (!cameras) return fail("bench pairs", cameras.status());
  auto points = gs::load_colmap_points(*model);
  if (!points) return fail("bench pairs", points.status());
  if (points->size() == 0)
    return fail("bench pairs", Status::error(points->source + ": holds no 3D points (the pair "
                                                              "depths come from them)"));
  log_info("bench pairs", std::to_string(cameras->cameras.size()) + " cameras, " +
                              std::to_string(points->size()) + " points from " + *model);
  auto pc = enhance::construct_pairs(*cameras, points->xyz, p);
  if (!pc) return fail("bench pairs", pc.status().with_context(*model));
  if (Status s = enhance::check_pairs_found(*pc, p); !s)
    return fail("bench pairs", s.with_context(*model));
  if (pc->training.size() < size_t(p.training_views))
    log_info("bench pairs", "warning: the training pool holds " +
                                std::to_string(pc->train_pool.size()) + " cameras, fewer than " +
                                std::to_string(p.training_views) + " training views; all are used");
  const std::string json = enhance::split_json(*cameras, *pc, p, name, int64_t(points->size()));
  if (Status s = write_file_atomic(out, json); !s) return fail("bench pairs", s);
  if (want_gt) {
    const std::string out_dir = fs::absolute(out).parent_path().string();
    for (const enhance::PairMeasure& m : pc->eval_pairs)
      if (Status s = copy_gt(scene, out_dir, cameras->cameras[size_t(m.close)].name); !s)
        return fail("bench pairs", s);
  }
  std::printf(
      "bench pairs: %zu cameras (%zu without points), %zu candidate pairs, scene score %.6g; "
      "%zu training views, %zu close-up pairs (%zu test frames unpaired) -> %s\n",
      cameras->cameras.size(), pc->no_depth.size(), pc->candidates.size(), pc->score.score,
      pc->training.size(), pc->eval_pairs.size(), pc->unpaired_tests.size(), out.c_str());
  return 0;
}

const bool registered = register_bench_command({"pairs", kUsage, run_pairs});

}  // namespace
}  // namespace macro::cli
