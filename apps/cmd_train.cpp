// macro train: 3DGS training on the CPU (gsplat's definitions), a fixed set of Gaussians.
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
    "usage: macro train --images DIR --cameras C --init FILE.ply --out OUT.ply --steps N\n"
    "         --strategy none --lr-schedule constant --view-order sequential\n"
    "         --sh-degree-interval 0 [--scene-scale S] [--seed S] [--log LOG.jsonl]\n"
    "         [--threads N] [--quiet]\n"
    "  --images    folder of photos: camera NAME is DIR/NAME, or DIR/NAME.png|.jpg|.jpeg|.exr\n"
    "  --cameras   our cameras.json, a COLMAP sparse folder, transforms.json; every camera is a\n"
    "              view, step s uses view s % views in file order\n"
    "  --init      Inria-layout .ply to start from (raw parameters)\n"
    "  --out       the trained Gaussians, Inria-layout .ply\n"
    "  --steps     Adam steps (default 30000)\n"
    "  --scene-scale  multiplies the means' learning rate 1.6e-4 (default: 1.1 x the cameras'\n"
    "              extent, as gsplat)\n"
    "  --log       JSONL, one line per step: step, loss, l1, ssim, num_gaussians, seconds\n"
    "  Implemented so far: --strategy none, --lr-schedule constant, --view-order sequential,\n"
    "  --sh-degree-interval 0, --mode classic; other values (gsplat's defaults included) are\n"
    "  refused as not implemented yet (docs/training.md).\n";

int run_train(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("train", s);
  gs::train::TrainJob job;
  job.images_dir = args.required("--images");
  job.cameras_path = args.required("--cameras");
  job.init_path = args.required("--init");
  job.out_path = args.required("--out");
  job.log_path = args.value_or("--log", "");
  job.steps = args.int_or("--steps", job.steps, 0, 1000000000);
  job.strategy = args.value_or("--strategy", job.strategy);
  job.lr_schedule = args.value_or("--lr-schedule", job.lr_schedule);
  job.view_order = args.value_or("--view-order", job.view_order);
  job.sh_degree_interval =
      args.int_or("--sh-degree-interval", job.sh_degree_interval, 0, 1000000000);
  job.mode = args.value_or("--mode", job.mode);
  const std::optional<std::string> scene_scale = args.value("--scene-scale");
  const std::optional<std::string> scene_dir = args.value("--scene-dir");
  const std::optional<std::string> seed = args.value("--seed");
  if (Status s = args.finish(); !s)
    return fail("train", Status::error(s.message() + " (macro train --help for usage)"));
  if (scene_dir)
    return fail("train", Status::error("--scene-dir: not implemented yet (give --images, "
                                       "--cameras and --init; docs/training.md)"));
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
        "trained %zu Gaussians on %zu views for %d steps in %.1f s (last loss %.6f); "
        "wrote %s\n",
        result->gaussians, result->views, job.steps, result->seconds, loss, job.out_path.c_str());
  }
  return 0;
}

const bool registered = register_command(
    {"train", "3DGS training on the CPU (fixed Gaussians, gsplat's loss and Adam)", run_train});

}  // namespace
}  // namespace macro::cli
