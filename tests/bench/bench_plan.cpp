// bench plan: MACRO planning stage on a synthetic DL3DV-Closeup folder (enhance/macro/plan.h).
// Per close-up: time of the whole plan (median), and what the options change: --planes auto
// (views and attention pairs vs P = 3) and --crop tight (view pixels vs full crops).
// Baseline: the released defaults (K = 3, P = 3, full crops), measured in the same run.
#include <unistd.h>
#include <cstdio>
#include <filesystem>
#include <string>

#include "bench_registry.h"
#include "enhance/macro/plan.h"
#include "enhance/datasets/synth_scene_folder.h"

namespace macro::bench {
namespace {

int64_t mask_pairs(const enhance::MacroPlan& p) {
  int64_t a = 0;
  for (const auto& m : p.masks.masks) a += m.allowed_pairs();
  return a;
}
int64_t view_pixels(const enhance::MacroPlan& p) {
  int64_t a = int64_t(p.model.w) * p.model.h;
  for (const auto& c : p.crops) a += int64_t(c.view.w) * c.view.h;
  return a;
}

int run(int argc, char** argv) {
  int reps = 3;
  for (int i = 1; i + 1 < argc; ++i)
    if (std::string(argv[i]) == "--reps") reps = std::max(1, std::atoi(argv[i + 1]));
  const std::string dir =
      (std::filesystem::temp_directory_path() / ("macro-bench-plan-" + std::to_string(::getpid())))
          .string();
  gs::SynthParams sp;  // the generator defaults: 480x270, 120k Gaussians, 8 training views
  sp.closeup_views = 4;
  auto scene = gs::generate_synthetic_scene(sp);
  if (!scene) return std::fprintf(stderr, "%s\n", scene.status().message().c_str()), 1;
  if (Status s = enhance::write_closeup_scene_folder(*scene, dir); !s)
    return std::fprintf(stderr, "%s\n", s.message().c_str()), 1;
  std::printf(
      "plan bench: synthetic %dx%d, %zu Gaussians, %d candidates, %d threads; medians of %d\n",
      sp.width, sp.height, scene->cloud.size(), sp.training_views, ThreadPool::global().size(),
      reps);
  std::printf("%-14s %9s %6s %6s %9s | %-26s | %-22s\n", "closeup", "plan ms", "P", "crops",
              "pairs", "auto: P crops pairs ratio", "tight: pixels ratio");
  enhance::PlanTimings last;
  for (const auto& cu : scene->geometry.closeups) {
    enhance::SceneInputOptions io;
    io.scene_dir = dir;
    io.closeup = cu.camera + ".png";
    auto in = enhance::load_scene_inputs(io);
    if (!in) return std::fprintf(stderr, "%s\n", in.status().message().c_str()), 1;
    enhance::PlanOptions base;
    Result<enhance::MacroPlan> p = Status::error("not run");
    const double t = median_seconds(reps, [&] { p = enhance::build_plan(*in, base); });
    if (!p) return std::fprintf(stderr, "%s\n", p.status().message().c_str()), 1;
    enhance::PlanOptions autop = base;
    autop.planes.automatic = true;
    autop.planes.planes = 5;
    auto a = enhance::build_plan(*in, autop);
    enhance::PlanOptions tight = base;
    tight.crops.crop = enhance::CropMode::kTight;
    auto tt = enhance::build_plan(*in, tight);
    if (!a || !tt) return 1;
    last = p->timings;
    std::printf("%-14s %9.1f %6zu %6zu %9lld | %3zu %5zu %9lld %6.3f | %9lld %6.3f\n",
                cu.camera.c_str(), t * 1e3, p->planes.planes.size(), p->crops.size(),
                (long long)mask_pairs(*p), a->planes.planes.size(), a->crops.size(),
                (long long)mask_pairs(*a), double(mask_pairs(*a)) / double(mask_pairs(*p)),
                (long long)view_pixels(*tt), double(view_pixels(*tt)) / double(view_pixels(*p)));
  }
  std::printf(
      "stages of the last plan (ms): close-up render %.1f, candidate depths + coverage %.1f, "
      "selection %.1f, planes %.1f, crops %.1f, masks %.1f\n",
      last.ms_closeup, last.ms_candidates, last.ms_select, last.ms_planes, last.ms_crops,
      last.ms_masks);
  std::filesystem::remove_all(dir);
  return 0;
}

const bool registered = register_benchmark(
    {"plan", "MACRO planning stage; --planes auto and --crop tight effects", run});

}  // namespace
}  // namespace macro::bench
