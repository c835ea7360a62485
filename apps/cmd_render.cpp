// macro render: one camera of a splat scene to PNG / EXR / safetensors / inverse-depth PNG.
// Thin main over gs::run_render_job (gs/raster/render_job.h documents every output channel).
#include <cmath>
#include <cstdio>

#include "apps/args.h"
#include "attention/runtime/progress.h"
#include "gs/raster/render_job.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro render --scene FILE|DIR [--cameras FILE] --camera NAME\n"
    "         [--out-png F.png] [--out-exr F.exr] [--out-tensors F.safetensors]\n"
    "         [--out-depth-png F.png] [--mode classic|antialiased|mip] [--background r,g,b]\n"
    "         [--sh-degree D] [--max-gaussians N] [--strict] [--ignore-distortion]\n"
    "         [--threads N] [--quiet]\n"
    "  --scene      .ply (Inria/gsplat or SuperSplat compressed), .splat, .spz, .sog, a SOG\n"
    "               folder (meta.json), a gsplat checkpoint (.pt), or a folder\n"
    "               holding scene.ply (and cameras.json), e.g. data/scenes/default\n"
    "  --cameras    our cameras.json, a COLMAP sparse folder, transforms.json or a DL3DV split\n"
    "  --camera     its name, path or name without extension (frame_00001 for frame_00001.png)\n"
    "  --strict     any invalid entry in the camera file is an error (default: left out, warned)\n"
    "  --ignore-distortion  render a camera with lens distortion as a pinhole (default: refused;\n"
    "               macro undistort makes a pinhole scene)\n"
    "  --out-exr    float channels R,G,B (colour), A (alpha), depth (depth_sum/alpha, 0 if\n"
    "               empty), invdepth (sum w/z)\n"
    "  --out-tensors  color [H,W,3], alpha, depth_sum, inv_depth_sum [H,W], F32\n"
    "  --out-depth-png  colour-mapped inverse depth (bright = near)\n";

int run_render(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("render", s);
  gs::RenderJob job;
  job.scene_path = args.required("--scene");
  job.cameras_path = args.value_or("--cameras", "");
  job.camera_name = args.required("--camera");
  job.camera_options.strict = args.flag("--strict");
  job.ignore_distortion = args.flag("--ignore-distortion");
  job.outputs.png = args.value_or("--out-png", "");
  job.outputs.exr = args.value_or("--out-exr", "");
  job.outputs.tensors = args.value_or("--out-tensors", "");
  job.outputs.depth_png = args.value_or("--out-depth-png", "");
  const std::string mode = args.value_or("--mode", "classic");
  const std::vector<double> bg = args.doubles_or("--background", {0, 0, 0}, 3);
  job.options.sh_degree_cap = args.int_or("--sh-degree", 3, 0, 3);
  job.limits.max_gaussians =
      size_t(args.int_or("--max-gaussians", int(job.limits.max_gaussians), 1, 2147483647));
  if (Status s = args.finish(); !s) {
    return fail("render", Status::error(s.message() + " (macro render --help for usage)"));
  }
  auto parsed_mode = gs::parse_raster_mode(mode);
  if (!parsed_mode) return fail("render", parsed_mode.status());
  job.options.mode = *parsed_mode;
  for (int c = 0; c < 3; ++c) {
    if (!std::isfinite(bg[size_t(c)]) || bg[size_t(c)] < 0 || bg[size_t(c)] > 1) {
      return fail("render", Status::error("--background: expected three numbers in [0, 1], found " +
                                          std::to_string(bg[size_t(c)])));
    }
    job.options.background[size_t(c)] = float(bg[size_t(c)]);
  }
  if (!job.outputs.any()) {
    return fail("render", Status::error("no output requested: give at least one of --out-png, "
                                        "--out-exr, --out-tensors, --out-depth-png"));
  }
  auto result = gs::run_render_job(job);
  if (!result) return fail("render", result.status());
  for (const std::string& w : result->warnings)
    std::fprintf(stderr, "macro render: warning: %s\n", w.c_str());
  if (!quiet()) {
    std::printf("%s\n", gs::render_summary(*result).c_str());
    for (const auto& f : result->written) std::printf("  wrote %s\n", f.c_str());
  }
  return 0;
}

const bool registered = register_command(
    {"render", "render a camera of a splat scene to PNG/EXR/safetensors", run_render});

}  // namespace
}  // namespace macro::cli
