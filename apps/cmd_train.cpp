// macro train: 3DGS training on the CPU (gsplat's definitions).
// Thin main over gs::train::run_train_job (gs/train/train_job.h, docs/training.md).
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <optional>

#include "apps/args.h"
#include "attention/runtime/progress.h"
#include "gs/train/train_job.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro train --images DIR --cameras C --init FILE.ply --out OUT.ply [--steps N]\n"
    "       macro train --scene-dir DIR [--data-factor F] [--test-every 8]\n"
    "         [--init sfm|random|FILE.ply] --out OUT.ply [--steps N]\n"
    "         [--strategy default|mcmc|none] [--cap-max N] [--absgrad] [--grow-grad2d G]\n"
    "         [--mode classic|antialiased|mip]\n"
    "         [--lr-schedule gsplat|constant]\n"
    "         [--view-order shuffled|sequential] [--sh-degree-interval K] [--max-gaussians N]\n"
    "         [--scene-scale S] [--seed S] [--log LOG.jsonl] [--save-every N] [--resume CKPT]\n"
    "         [--precision float|double]\n"
    "         [--threads N] [--quiet]\n"
    "  --images    folder of photos: camera NAME is DIR/NAME, or DIR/NAME.png|.jpg|.jpeg|.exr\n"
    "  --cameras   our cameras.json, a COLMAP sparse folder, transforms.json; every camera is a\n"
    "              view\n"
    "  --init      Inria-layout .ply to start from (raw parameters); with --scene-dir also sfm\n"
    "              (the COLMAP points; default) or random (a cube of 3 x the scene scale)\n"
    "  --scene-dir COLMAP scene: images/ (images_F/), sparse/0, optional split.json (only its\n"
    "              training frames are used); every --test-every-th image by name is held out\n"
    "              and PSNR/SSIM on those are reported after training (0: none)\n"
    "  --data-factor  photos downscaled by F (images_F/ if present), intrinsics / F\n"
    "  --out       the trained Gaussians, Inria-layout .ply\n"
    "  --steps     Adam steps (default 30000)\n"
    "  --scene-scale  multiplies the means' learning rate 1.6e-4 (default: 1.1 x the cameras'\n"
    "              extent, as gsplat)\n"
    "  --strategy  default (gsplat DefaultStrategy: duplicate, split, prune, opacity reset;\n"
    "              the default), mcmc (gsplat MCMCStrategy: relocate dead Gaussians, grow 5% per\n"
    "              refinement up to --cap-max, position noise; opacity and scale regularisers\n"
    "              0.01; --scene-dir inits at opacity 0.5 and 0.1 x the 3-NN scale) or none\n"
    "  --cap-max   mcmc: the most Gaussians (default 1000000, at most --max-gaussians)\n"
    "  --absgrad   default strategy: grow on the absolute 2D-mean gradients (AbsGS, gsplat\n"
    "              absgrad; gsplat advises --grow-grad2d 0.0008 with it)\n"
    "  --grow-grad2d  default strategy: the gradient above which Gaussians grow (default 0.0002)\n"
    "  --mode      classic (default), antialiased (gsplat: opacity x sqrt(det S / det(S+0.3I)))\n"
    "              or mip (Mip-Splatting: 3D filter from the training cameras, 2D filter 0.1)\n"
    "  --lr-schedule  gsplat (means' rate decays to 0.01x over the run; default) or constant\n"
    "  --view-order   shuffled (a permutation per epoch from --seed; default) or sequential\n"
    "              (step s uses view s % views in file order)\n"
    "  --sh-degree-interval  one more SH band every K steps (default 1000; 0: all from the start)\n"
    "  --max-gaussians  the most Gaussians loaded or grown by densification (default 50M)\n"
    "  --seed      view order and split samples (default 42; not torch's generator)\n"
    "  --log       JSONL, one line per step: step, loss, l1, ssim, num_gaussians, view,\n"
    "              sh_degree, means_lr, [duplicated, split, pruned, opacity_reset],\n"
    "              [relocated, added], psnr, seconds\n"
    "  --save-every  write the checkpoint OUT.ckpt (atomically) every N steps\n"
    "  --resume    continue from a checkpoint, with the same inputs and flags; the result is\n"
    "              bit-identical to an uninterrupted run (docs/training.md)\n"
    "  --precision float (the SIMD float path of the machine's ISA; default) or double (the\n"
    "              scalar double-precision reference, docs/training.md)\n";

int run_train(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("train", s);
  gs::train::TrainJob job;
  const std::optional<std::string> scene_dir = args.value("--scene-dir");
  job.scene_dir = scene_dir.value_or("");
  job.images_dir = scene_dir ? args.value_or("--images", "") : args.required("--images");
  job.cameras_path = scene_dir ? args.value_or("--cameras", "") : args.required("--cameras");
  job.init_path = scene_dir ? args.value_or("--init", "sfm") : args.required("--init");
  job.data_factor = args.int_or("--data-factor", 1, 1, 64);
  job.test_every = args.int_or("--test-every", 8, 0, 1000000);
  job.out_path = args.required("--out");
  job.log_path = args.value_or("--log", "");
  job.steps = args.int_or("--steps", job.steps, 0, 1000000000);
  job.strategy = args.value_or("--strategy", job.strategy);
  job.lr_schedule = args.value_or("--lr-schedule", job.lr_schedule);
  job.view_order = args.value_or("--view-order", job.view_order);
  job.sh_degree_interval =
      args.int_or("--sh-degree-interval", job.sh_degree_interval, 0, 1000000000);
  job.mode = args.value_or("--mode", job.mode);
  job.cap_max = size_t(args.int_or("--cap-max", int(job.cap_max), 1, 2000000000));
  job.absgrad = args.flag("--absgrad");
  job.grow_grad2d = args.double_or("--grow-grad2d", job.grow_grad2d, 0, 1e6);
  job.save_every = args.int_or("--save-every", 0, 0, 1000000000);
  job.resume_path = args.value_or("--resume", "");
  job.precision = args.value_or("--precision", job.precision);
  const std::optional<std::string> scene_scale = args.value("--scene-scale");
  const std::optional<std::string> seed = args.value("--seed");
  if (Status s = args.finish(); !s)
    return fail("train", Status::error(s.message() + " (macro train --help for usage)"));
  if (scene_scale) {
    char* end = nullptr;
    const double x = std::strtod(scene_scale->c_str(), &end);
    if (scene_scale->empty() || *end != '\0')
      return fail("train", Status::error("--scene-scale: expected a positive number, found '" +
                                         *scene_scale + "'"));
    job.scene_scale = x;  // run_train_job refuses <= 0 and non-finite values
  }
  if (seed) {
    errno = 0;
    char* end = nullptr;
    job.seed = std::strtoull(seed->c_str(), &end, 10);
    if (seed->empty() || (*seed)[0] == '-' || *end != '\0' || errno != 0)
      return fail("train",
                  Status::error("--seed: expected a non-negative integer, found '" + *seed + "'"));
  }
  auto result = gs::train::run_train_job(job);
  if (!result) return fail("train", result.status());
  if (!quiet()) {
    const double loss = result->records.empty() ? 0 : result->records.back().loss;
    std::printf(
        "trained %zu Gaussians (from %zu) on %zu views for %d steps in %.1f s (last loss %.6f); "
        "wrote %s\n",
        result->gaussians, result->initial_gaussians, result->views, job.steps, result->seconds,
        loss, job.out_path.c_str());
    if (result->evaluated)
      std::printf("test views (%zu): PSNR %.3f dB, SSIM %.4f\n", result->test_views.size(),
                  result->test_psnr, result->test_ssim);
  }
  return 0;
}

const bool registered = register_command(
    {"train", "3DGS training on the CPU (gsplat's loss, Adam, schedules and default strategy)",
     run_train});

}  // namespace
}  // namespace macro::cli
