// macro bench synth: the SynthClose benchmark (enhance/datasets/synth_close.h) written as
// DL3DV-Closeup scene folders, ready for `macro bench run --root DIR`.
#include <chrono>
#include <cstdio>
#include <memory>

#include "apps/args.h"
#include "apps/bench_commands.h"
#include "attention/runtime/progress.h"
#include "enhance/datasets/synth_close.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "       macro bench synth --out DIR [--scenes N] [--seed S] [--size tiny|demo|full]\n"
    "                         [--recon train|merge] [--train-steps N] [--sfm-points N] [--mip]\n"
    "                         [--no-gt-ply] [--quiet]\n"
    "  synth   SynthClose: synthetic close-up scenes with exact GT (DIR/synthclose_NN; the demo\n"
    "          size writes one scene folder into DIR). Photos from a dense GT splat (gt.ply);\n"
    "          SfM-like points in sparse/0/points3D.txt; scene.ply the reconstruction: train\n"
    "          (default) = macro train on the training photos from those points (gsplat default\n"
    "          recipe, --train-steps: tiny 300, else 3000; the merged cloud kept as\n"
    "          scene_merged.ply), merge = the GT merged into fewer, larger Gaussians; --mip also\n"
    "          trains scene_mip.ply in mip mode (the mip-splatting method); full: 10 scenes, 50\n"
    "          pairs, 960x536.\n";

int run_synth(Args& args) {
  enhance::SynthCloseOptions o;
  const std::string out = args.required("--out");
  o.scenes = args.int_or("--scenes", 0, 1, 1000);  // absent: the size's own count
  o.seed = uint64_t(args.int_or("--seed", 1, 0, 2147483647));
  const std::string size = args.value_or("--size", "full");
  o.write_gt_ply = !args.flag("--no-gt-ply");
  const std::string recon = args.value_or("--recon", "train");
  o.train_steps = args.int_or("--train-steps", 0, 1, 1000000000);
  o.sfm_points = size_t(args.int_or("--sfm-points", 0, 1, 100000000));
  o.train_mip = args.flag("--mip");
  if (Status s = args.finish(); !s) return fail("bench synth", s);
  auto parsed = enhance::parse_synthclose_size(size);
  if (!parsed) return fail("bench synth", parsed.status());
  o.size = *parsed;
  auto parsed_recon = enhance::parse_synthclose_recon(recon);
  if (!parsed_recon) return fail("bench synth", parsed_recon.status());
  o.recon = *parsed_recon;
  if (o.train_mip && o.recon != enhance::SynthCloseRecon::kTrain)
    return fail("bench synth", Status::error("--mip: only with --recon train"));
  if (Status s = prepare_output_dir(out, "--out"); !s) return fail("bench synth", s);
  std::unique_ptr<Progress> progress;
  o.progress = [&](size_t done, size_t total) {
    if (!progress) progress = std::make_unique<Progress>("bench synth", total);
    progress->set(done);
  };
  const auto t0 = std::chrono::steady_clock::now();
  auto summary = enhance::write_synthclose(out, o);
  if (progress) progress->finish();
  if (!summary) return fail("bench synth", summary.status());
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf(
      "bench synth: %s, %s, %zu GT / %zu reconstruction Gaussians (%s), %zu SfM points, %.1f s "
      "(training %.1f s) -> %s\n",
      count_noun(size_t(summary->scenes), "scene").c_str(),
      count_noun(size_t(summary->pairs), "close-up pair").c_str(), summary->gt_gaussians,
      summary->recon_gaussians, enhance::synthclose_recon_name(o.recon), summary->sfm_points, secs,
      summary->train_seconds, out.c_str());
  return 0;
}

const bool registered = register_bench_command({"synth", kUsage, run_synth});

}  // namespace
}  // namespace macro::cli
