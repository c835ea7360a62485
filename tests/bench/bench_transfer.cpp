// bench transfer: the weight-free transfer enhancer (enhance/transfer/transfer.h) end to end on a
// synthetic 960x536 close-up, K = P = 3: render + plan + transfer, wall and process CPU medians,
// with the stage split of the last run. Baseline in the same run: the raw 3DGS render alone
// (method 3dgs), so the ratio is what the enhancer costs on top of rendering.
// Options: --reps N (default 3), --key-stride S (default: TransferParams, 4), --source crops|whole.
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include "attention/runtime/progress.h"
#include "bench_registry.h"
#include "enhance/enhance.h"
#include "enhance/datasets/synth_scene_folder.h"

namespace macro::bench {
namespace {

int run(int argc, char** argv) {
  int reps = 3, key_stride = enhance::TransferParams{}.key_stride;
  std::string source = "crops";
  for (int i = 1; i + 1 < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--reps") reps = std::max(1, std::atoi(argv[i + 1]));
    if (a == "--key-stride") key_stride = std::max(1, std::atoi(argv[i + 1]));
    if (a == "--source") source = argv[i + 1];
  }
  const std::string dir = (std::filesystem::temp_directory_path() /
                           ("macro-bench-transfer-" + std::to_string(::getpid())))
                              .string();
  gs::SynthParams sp;
  sp.width = 960;
  sp.height = 536;
  sp.closeup_views = 1;
  auto scene = gs::generate_synthetic_scene(sp);
  if (!scene) return std::fprintf(stderr, "%s\n", scene.status().message().c_str()), 1;
  if (Status s = enhance::write_closeup_scene_folder(*scene, dir); !s)
    return std::fprintf(stderr, "%s\n", s.message().c_str()), 1;
  enhance::SceneInputOptions io;
  io.scene_dir = dir;
  io.closeup = scene->geometry.closeups.at(0).camera + ".png";
  auto in = enhance::load_scene_inputs(io);
  if (!in) return std::fprintf(stderr, "%s\n", in.status().message().c_str()), 1;
  auto src = enhance::parse_transfer_source(source);
  if (!src) return std::fprintf(stderr, "%s\n", src.status().message().c_str()), 1;
  set_quiet(true);

  enhance::EnhanceOptions base;
  base.method = enhance::EnhanceMethod::k3dgs;
  enhance::EnhanceOptions tr;
  tr.method = enhance::EnhanceMethod::kMacro;
  tr.enhancer = enhance::Enhancer::kTransfer;
  tr.plan.refs = 3;
  tr.plan.planes.planes = 3;
  tr.transfer.key_stride = key_stride;
  tr.transfer.source = *src;

  Result<enhance::EnhanceResult> r = Status::error("not run");
  const Timing t_base = median_timing(reps, [&] { r = enhance::enhance_closeup(*in, base); });
  if (!r) return std::fprintf(stderr, "%s\n", r.status().message().c_str()), 1;
  const Timing t = median_timing(reps, [&] { r = enhance::enhance_closeup(*in, tr); });
  if (!r) return std::fprintf(stderr, "%s\n", r.status().message().c_str()), 1;
  std::printf(
      "transfer bench: synthetic %dx%d close-up, %zu Gaussians, K=3 P=3, source %s, key stride "
      "%d, %d threads, medians of %d\n",
      in->closeup.width, in->closeup.height, scene->cloud.size(), source.c_str(), key_stride,
      ThreadPool::global().size(), reps);
  std::printf("%-28s %10s %10s %8s\n", "case", "wall ms", "cpu ms", "ratio");
  std::printf("%-28s %10.1f %10.1f %8s\n", "3dgs render (baseline)", 1e3 * t_base.wall,
              1e3 * t_base.cpu, "1.00");
  std::printf("%-28s %10.1f %10.1f %8.2f\n", "render + plan + transfer", 1e3 * t.wall, 1e3 * t.cpu,
              t.wall / std::max(t_base.wall, 1e-9));
  const auto& tm = r->timings;
  std::printf(
      "last run: render %.0f ms, plan %.0f ms, transfer %.0f ms (%d sources, mean "
      "confidence %.3f)\n",
      tm.ms_render, tm.ms_plan, tm.ms_transfer, r->views, r->transfer_confidence);
  std::filesystem::remove_all(dir);
  return 0;
}

const bool registered = register_benchmark(
    {"transfer", "transfer enhancer at 960x536, K=P=3, vs the 3dgs render", run});

}  // namespace
}  // namespace macro::bench
