// "Render one camera of a scene to files": load scene + cameras, render, write the outputs.
// The logic behind `macro render`, reusable by enhance/ and tests.
//
// Outputs (each optional, each written atomically; H x W image, row 0 at the top):
//   png        8-bit RGB colour (background included), clamped to [0, 1] and rounded
//   exr        32-bit float channels (uncompressed), linear values, no tone mapping:
//                R, G, B    colour = sum c_i w_i + T * background      (w_i = alpha_i T_i)
//                A          alpha = 1 - T
//                depth      expected view depth = depth_sum / alpha where alpha >= kMinDepthAlpha,
//                           else 0 (z = camera-space depth of each Gaussian's mean, metres of the
//                           scene's unit)
//                invdepth   inv_depth_sum = sum w_i / z_i, not divided by alpha (Inria's
//                           convention: 0 = nothing hit / infinitely far)
//   tensors    safetensors, F32, named as the rasterizer goldens: color [H,W,3], alpha [H,W],
//              depth_sum [H,W], inv_depth_sum [H,W]; metadata: camera, scene, mode
//   depth_png  inverse depth for viewing: inv_depth_sum / max over the image, colour-mapped
//              (gs/image_io.h colormap: dark = far or empty, bright = near)
// Every output folder is checked before loading anything; if a write fails after others
// succeeded, the outputs this job already wrote are removed, so a failed job leaves no files
// (regular files only: a device or FIFO output such as /dev/null, and a symlink and its target,
// are left as they are; file_io.h).
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/formats/scene_io.h"
#include "gs/raster/rasterizer.h"

namespace macro::gs {

inline constexpr float kMinDepthAlpha = 1e-6f;  // below: no Gaussian blended, depth written as 0

struct RenderOutputs {
  std::string png, exr, tensors, depth_png;  // empty = not written
  bool any() const {
    return !png.empty() || !exr.empty() || !tensors.empty() || !depth_png.empty();
  }
};

struct RenderJob {
  std::string scene_path;    // any format load_scene reads, or a folder holding scene.ply
  std::string cameras_path;  // any format load_cameras reads; empty = <scene folder>/cameras.json
  std::string camera_name;
  RenderOutputs outputs;
  RenderOptions options;
  LoadLimits limits;
  // Strictness of the camera file (an invalid entry fails the load, or is left out and warned).
  CameraLoadOptions camera_options;
  // A camera with lens distortion is refused (the renderer draws pinhole images) unless this is
  // set; then it is rendered as the pinhole with its fx fy cx cy, and a warning says so.
  bool ignore_distortion = false;
};

struct RenderJobResult {
  Camera camera;
  size_t gaussians = 0;
  RenderResult image;
  double ms_load = 0, ms_write = 0;
  std::vector<std::string> written;   // the output files, in the order written
  std::vector<std::string> warnings;  // rejected camera entries, distortion ignored
};

// Each output's folder exists and is writable and the paths are distinct. The message names the
// output by its `macro render` flag (--out-png, --out-exr, --out-tensors, --out-depth-png) and
// path.
Status check_render_outputs(const RenderOutputs& outputs);

// Writes the requested outputs of a render (see the table at the top). `scene` and `camera` go into
// the safetensors metadata.
Status write_render_outputs(const RenderResult& image, const RenderOutputs& outputs,
                            const std::string& scene, const std::string& camera, RasterMode mode,
                            std::vector<std::string>* written = nullptr);

// A scene folder (as `macro synth` writes and data/scenes/default is) becomes its scene.ply, and
// an empty cameras path its cameras.json. A SOG folder (holding meta.json) stays as it is. Errors
// name the folder and the missing file.
Status resolve_scene_folder(std::string& scene_path, std::string& cameras_path);

Result<RenderJobResult> run_render_job(const RenderJob& job);

// "closeup: 480x270, 51234 Gaussians, 40321 visible; load 30.1 ms, project 2.0, bin 1.5,
// blend 12.3, total 16.0 ms; write 20.4 ms"
std::string render_summary(const RenderJobResult& result);

const char* raster_mode_name(RasterMode mode);
Result<RasterMode> parse_raster_mode(const std::string& text);

}  // namespace macro::gs
