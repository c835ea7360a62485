// Render one camera to files (see render_job.h).
#include "gs/raster/render_job.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/progress.h"
#include "gs/image_io.h"

namespace macro::gs {
namespace {

Status check_output(const char* kind, const std::string& path) {
  if (path.empty()) return Status::ok();
  namespace fs = std::filesystem;
  // Symlinks are followed (the file they point to is replaced); a device or FIFO is written in
  // place (file_io.h), so only it needs to be writable.
  auto resolved = resolve_output(path);
  if (!resolved) return resolved.status().with_context(kind);
  const OutputTarget& target = *resolved;
  if (target.kind == OutputTarget::kSpecial) {
    if (::access(target.path.c_str(), W_OK) != 0)
      return Status::error(std::string(kind) + ": " + path + ": is not writable");
    return Status::ok();
  }
  const fs::path folder = fs::path(target.path).parent_path();
  const std::string parent = folder.empty() ? std::string(".") : folder.string();
  if (is_directory(path)) {
    return Status::error(std::string(kind) + ": " + path + ": is a folder, expected a file path");
  }
  if (!is_directory(parent)) {
    return Status::error(std::string(kind) + ": " + path + ": folder '" + parent +
                         "' does not exist");
  }
  if (::access(parent.c_str(), W_OK) != 0) {
    return Status::error(std::string(kind) + ": " + path + ": folder '" + parent +
                         "' is not writable");
  }
  return Status::ok();
}

}  // namespace

const char* raster_mode_name(RasterMode mode) {
  switch (mode) {
    case RasterMode::kClassic:
      return "classic";
    case RasterMode::kAntialiased:
      return "antialiased";
    case RasterMode::kMip:
      return "mip";
  }
  return "?";
}

Result<RasterMode> parse_raster_mode(const std::string& text) {
  if (text == "classic") return RasterMode::kClassic;
  if (text == "antialiased") return RasterMode::kAntialiased;
  if (text == "mip") return RasterMode::kMip;
  return Status::error("--mode: expected classic, antialiased or mip, found '" + text + "'");
}

Status check_render_outputs(const RenderOutputs& o) {
  MACRO_TRY(check_output("--out-png", o.png));
  MACRO_TRY(check_output("--out-exr", o.exr));
  MACRO_TRY(check_output("--out-tensors", o.tensors));
  MACRO_TRY(check_output("--out-depth-png", o.depth_png));
  const std::string* all[] = {&o.png, &o.exr, &o.tensors, &o.depth_png};
  for (int a = 0; a < 4; ++a) {
    for (int b = a + 1; b < 4; ++b) {
      if (!all[a]->empty() && *all[a] == *all[b]) {
        return Status::error("output " + *all[a] + " is requested twice");
      }
    }
  }
  return Status::ok();
}

Status write_render_outputs(const RenderResult& r, const RenderOutputs& o, const std::string& scene,
                            const std::string& camera, RasterMode mode,
                            std::vector<std::string>* written_out) {
  const int w = r.width, h = r.height;
  const size_t n = size_t(w) * size_t(h);
  if (w <= 0 || h <= 0 || r.color.size() != n * 3 || r.alpha.size() != n ||
      r.depth_sum.size() != n || r.inv_depth_sum.size() != n) {
    return Status::error("render result: buffers do not match the image size " + std::to_string(w) +
                         "x" + std::to_string(h));
  }
  std::vector<std::string> written;
  // Undo removes only regular files named directly: never a device or FIFO (/dev/null!), never
  // a symlink or the file it points to.
  auto undo = [&](Status s) {
    for (const std::string& p : written) {
      struct stat st {};
      if (::lstat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode)) std::remove(p.c_str());
    }
    return s;
  };
  if (!o.png.empty()) {
    Image img(w, h, 3);
    img.data = r.color;
    if (Status s = write_png(o.png, img); !s) return undo(s);
    written.push_back(o.png);
  }
  if (!o.exr.empty()) {
    std::vector<float> red(n), green(n), blue(n), depth(n);
    for (size_t p = 0; p < n; ++p) {
      red[p] = r.color[p * 3];
      green[p] = r.color[p * 3 + 1];
      blue[p] = r.color[p * 3 + 2];
      depth[p] = r.alpha[p] >= kMinDepthAlpha ? r.depth_sum[p] / r.alpha[p] : 0.f;
    }
    Status s = write_exr(o.exr, w, h,
                         {{"R", red.data()},
                          {"G", green.data()},
                          {"B", blue.data()},
                          {"A", r.alpha.data()},
                          {"depth", depth.data()},
                          {"invdepth", r.inv_depth_sum.data()}});
    if (!s) return undo(s);
    written.push_back(o.exr);
  }
  if (!o.tensors.empty()) {
    const int64_t H = h, W = w;
    Status s =
        write_safetensors(o.tensors,
                          {{"color", DType::kF32, {H, W, 3}, r.color.data()},
                           {"alpha", DType::kF32, {H, W}, r.alpha.data()},
                           {"depth_sum", DType::kF32, {H, W}, r.depth_sum.data()},
                           {"inv_depth_sum", DType::kF32, {H, W}, r.inv_depth_sum.data()}},
                          {{"camera", camera}, {"scene", scene}, {"mode", raster_mode_name(mode)}});
    if (!s) return undo(s);
    written.push_back(o.tensors);
  }
  if (!o.depth_png.empty()) {
    float mx = 0.f;
    for (float v : r.inv_depth_sum) {
      if (std::isfinite(v)) mx = std::max(mx, v);
    }
    Image img(w, h, 3);
    for (size_t p = 0; p < n; ++p) {
      colormap(mx > 0.f ? r.inv_depth_sum[p] / mx : 0.f, &img.data[p * 3]);
    }
    if (Status s = write_png(o.depth_png, img); !s) return undo(s);
    written.push_back(o.depth_png);
  }
  if (written_out) *written_out = written;
  return Status::ok();
}

Status resolve_scene_folder(std::string& scene_path, std::string& cameras_path) {
  // A SOG folder (meta.json and its images) is a scene by itself; it needs --cameras.
  if (is_directory(scene_path) && !file_exists(scene_path + "/meta.json")) {
    const std::string folder = scene_path;
    scene_path = folder + "/scene.ply";
    if (!file_exists(scene_path)) {
      return Status::error("--scene: folder " + folder + " has no scene.ply (nor a SOG meta.json)");
    }
    if (cameras_path.empty()) {
      cameras_path = folder + "/cameras.json";
      if (!file_exists(cameras_path)) {
        return Status::error("--cameras: not given, and folder " + folder + " has no cameras.json");
      }
    }
  }
  if (cameras_path.empty()) {
    return Status::error("--cameras: required unless --scene is a folder holding cameras.json");
  }
  return Status::ok();
}

Result<RenderJobResult> run_render_job(const RenderJob& job) {
  MACRO_TRY(check_render_outputs(job.outputs));
  std::string scene_path = job.scene_path, cameras_path = job.cameras_path;
  MACRO_TRY(resolve_scene_folder(scene_path, cameras_path));
  auto t0 = std::chrono::steady_clock::now();
  RenderJobResult out;
  auto cloud = load_scene(scene_path, job.limits);
  if (!cloud) return cloud.status().with_context("--scene");
  auto cameras = load_cameras(cameras_path, job.camera_options);
  if (!cameras) return cameras.status().with_context("--cameras");
  auto camera = cameras->find(job.camera_name);
  if (!camera) return camera.status().with_context("--camera " + job.camera_name);
  if (Status s = camera->validate(); !s) return s.with_context(cameras_path);
  for (const RejectedCamera& r : cameras->rejected) {
    out.warnings.push_back("entry " + std::to_string(r.index) +
                           (r.name.empty() ? std::string() : " '" + r.name + "'") +
                           " left out (--strict makes this an error): " + r.message);
  }
  if (camera->has_distortion()) {
    if (!job.ignore_distortion) {
      return refuse_distorted(*camera, "macro render",
                              "undistort the scene first (macro undistort --scene-dir DIR --out "
                              "NEW_DIR) and render NEW_DIR's cameras, or pass "
                              "--ignore-distortion to render it as a pinhole anyway")
          .with_context(cameras_path);
    }
    out.warnings.push_back("camera '" + camera->name + "' is " + camera->model_text() +
                           ": rendered as a pinhole, its distortion ignored (--ignore-distortion)");
  }
  out.camera = *camera;
  out.gaussians = cloud->size();
  out.ms_load = ms_since(t0);

  MACRO_ASSIGN_OR_RETURN(out.image, render(*cloud, out.camera, job.options));

  auto t1 = std::chrono::steady_clock::now();
  MACRO_TRY(write_render_outputs(out.image, job.outputs, scene_path, job.camera_name,
                                 job.options.mode, &out.written));
  out.ms_write = ms_since(t1);
  return out;
}

std::string render_summary(const RenderJobResult& r) {
  const RenderStats& s = r.image.stats;
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "%s: %dx%d, %zu Gaussians, %zu visible; load %.1f ms, project %.1f, bin %.1f, "
                "blend %.1f, render total %.1f ms; write %.1f ms",
                r.camera.name.c_str(), r.image.width, r.image.height, r.gaussians, s.visible,
                r.ms_load, s.ms_project, s.ms_bin, s.ms_blend, s.ms_total, r.ms_write);
  return buf;
}

}  // namespace macro::gs
