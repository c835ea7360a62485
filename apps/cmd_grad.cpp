// macro grad: one forward and backward of the training loss on one view, to safetensors.
// Thin main over gs::train::run_grad_job (gs/train/train_job.h lists every tensor written).
#include <cstdio>

#include "apps/args.h"
#include "attention/runtime/progress.h"
#include "gs/train/train_job.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro grad --scene S.ply --cameras C --camera NAME --target IMG --out G.safetensors\n"
    "         [--mode classic|antialiased|mip] [--precision float|double] [--threads N] [--quiet]\n"
    "  --scene    Inria-layout .ply, read as raw parameters (log scales, logit opacities,\n"
    "             raw quaternions)\n"
    "  --target   the photo to fit: PNG/JPEG (byte / 255) or EXR (R, G, B), the camera's size\n"
    "  --out      loss, l1, ssim [1], color [H,W,3], alpha [H,W], grad.means [N,3],\n"
    "             grad.scales [N,3], grad.quats [N,4], grad.opacities [N], grad.sh0 [N,1,3],\n"
    "             grad.shN [N,K-1,3], grad.means2d [N,2] (F32, gsplat names)\n"
    "  --mode     classic (default), antialiased (gsplat's opacity compensation) or mip\n"
    "             (Mip-Splatting: 3D filter from every camera of --cameras, 2D filter 0.1)\n"
    "  --precision float (the SIMD float path; default) or double (the scalar reference)\n"
    "  loss = 0.8 L1 + 0.2 (1 - SSIM), SSIM 11x11 valid (docs/training.md)\n";

int run_grad(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("grad", s);
  gs::train::GradJob job;
  job.scene_path = args.required("--scene");
  job.cameras_path = args.required("--cameras");
  job.camera_name = args.required("--camera");
  job.target_path = args.required("--target");
  job.out_path = args.required("--out");
  job.mode = args.value_or("--mode", "classic");
  job.precision = args.value_or("--precision", job.precision);
  if (Status s = args.finish(); !s)
    return fail("grad", Status::error(s.message() + " (macro grad --help for usage)"));
  auto result = gs::train::run_grad_job(job);
  if (!result) return fail("grad", result.status());
  if (!quiet())
    std::printf("%s: %zu Gaussians, loss %.6f (l1 %.6f, ssim %.6f), %.1f ms; wrote %s\n",
                result->camera.name.c_str(), result->gaussians, result->loss.loss, result->loss.l1,
                result->loss.ssim, result->ms, job.out_path.c_str());
  return 0;
}

const bool registered = register_command(
    {"grad", "loss and parameter gradients of one training view, to safetensors", run_grad});

}  // namespace
}  // namespace macro::cli
