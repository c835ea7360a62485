// macro render: one camera of a splat scene to PNG / EXR / safetensors / inverse-depth PNG.
// Thin main over gs::run_render_job (gs/raster/render_job.h documents every output channel).
#include <cmath>
#include <cstdio>

#include "apps/args.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "enhance/scene_input.h"
#include "gs/cameras/camera.h"
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
    "               folder (meta.json), a gsplat checkpoint (.pt), or a scene folder:\n"
    "               scene.ply (or the trained splat of a DL3DV-Closeup folder, found like\n"
    "               macro enhance finds it) with its cameras: cameras.json, else the COLMAP model\n"
    "               (sparse/0) or transforms.json, else split.json's close-up poses, the first\n"
    "               that holds --camera; e.g. data/scenes/default, data/scenes/synthclose\n"
    "  --cameras    our cameras.json, a COLMAP sparse folder, transforms.json or a DL3DV split\n"
    "  --camera     its name, path or name without extension (frame_00001 for frame_00001.png)\n"
    "  --strict     any invalid entry in the camera file is an error (default: left out, warned)\n"
    "  --ignore-distortion  render a camera with lens distortion as a pinhole (default: refused;\n"
    "               macro undistort makes a pinhole scene)\n"
    "  --out-exr    float channels R,G,B (colour), A (alpha), depth (depth_sum/alpha, 0 if\n"
    "               empty), invdepth (sum w/z)\n"
    "  --out-tensors  color [H,W,3], alpha, depth_sum, inv_depth_sum [H,W], F32\n"
    "  --out-depth-png  colour-mapped inverse depth (bright = near)\n";

// --scene DIR: the splat and, without --cameras, the first camera file of the folder that holds
// `camera` (cameras.json, the COLMAP model / transforms.json, split.json's close-up poses).
Status resolve_scene_dir(const std::string& camera, std::string& scene, std::string& cameras) {
  if (!is_directory(scene)) return Status::ok();
  const std::string dir = scene;
  const bool closeup_layout = file_exists(dir + "/split.json") || is_directory(dir + "/sparse");
  if (file_exists(dir + "/scene.ply")) {
    scene = dir + "/scene.ply";
  } else if (closeup_layout) {
    auto found = enhance::find_scene_ply(dir);
    if (!found) return found.status().with_context("--scene " + dir);
    scene = *found;
  } else {
    return Status::error("--scene: folder " + dir +
                         " has no scene.ply (and no split.json or sparse/ of a DL3DV-Closeup "
                         "folder to find the trained splat by)");
  }
  if (!cameras.empty()) return Status::ok();
  std::vector<std::string> tried;
  std::string first_error;
  const std::string sources[] = {dir + "/cameras.json", dir, dir + "/split.json"};
  for (const std::string& source : sources) {
    if (source != dir && !file_exists(source)) continue;
    if (source == dir && !is_directory(dir + "/sparse") && !file_exists(dir + "/transforms.json") &&
        !file_exists(dir + "/cameras.txt") && !file_exists(dir + "/cameras.bin"))
      continue;
    tried.push_back(source == dir ? dir + " (COLMAP model / transforms.json)" : source);
    auto set = gs::load_cameras(source);
    if (!set) {
      if (first_error.empty()) first_error = set.status().message();
      continue;
    }
    if (set->index_of(camera) >= 0) {
      cameras = source;
      return Status::ok();
    }
  }
  if (tried.empty())
    return Status::error("--cameras: not given, and folder " + dir +
                         " has no cameras.json, COLMAP model (sparse/0), transforms.json or "
                         "split.json");
  std::string list;
  for (const std::string& t : tried) list += (list.empty() ? "" : ", ") + t;
  return Status::error("--camera '" + camera + "': not found in " + list +
                       (first_error.empty() ? std::string() : " (" + first_error + ")"));
}

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
  const struct {
    const char* flag;
    const std::string& path;
    std::vector<std::string> extensions;
  } outputs[] = {{"--out-png", job.outputs.png, {".png"}},
                 {"--out-exr", job.outputs.exr, {".exr"}},
                 {"--out-tensors", job.outputs.tensors, {".safetensors"}},
                 {"--out-depth-png", job.outputs.depth_png, {".png"}}};
  for (const auto& o : outputs)
    if (!o.path.empty())
      if (Status s = check_output_name(o.path, o.flag, o.extensions); !s) return fail("render", s);
  if (Status s = resolve_scene_dir(job.camera_name, job.scene_path, job.cameras_path); !s)
    return fail("render", s);
  for (const auto& o : outputs)
    if (!o.path.empty())
      if (Status s = prepare_output(o.path, o.flag, o.extensions); !s) return fail("render", s);
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
