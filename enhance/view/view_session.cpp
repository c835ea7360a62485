// The viewed scene: loading, frames, close-ups (see view_session.h; the jobs are in view_jobs.cpp).
#include "enhance/view/view_session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "enhance/enhance.h"
#include "gs/formats/scene_io.h"
#include "gs/image_io.h"
#include "gs/raster/render_job.h"

namespace macro::enhance::view {
namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {

// The 50th-percentile point per axis and the 90th-percentile distance from it: an orbit centre
// and a scale that ignore far outliers (sky Gaussians, floaters).
void cloud_bounds(const gs::GaussianCloud& cloud, double center[3], double* radius) {
  const size_t n = cloud.size();
  if (n == 0) return;
  const size_t step = std::max<size_t>(1, n / 20000);  // a sample is enough for a view centre
  std::vector<float> axis;
  for (int a = 0; a < 3; ++a) {
    axis.clear();
    for (size_t i = 0; i < n; i += step) axis.push_back(cloud.position[i * 3 + size_t(a)]);
    std::nth_element(axis.begin(), axis.begin() + long(axis.size() / 2), axis.end());
    center[a] = axis[axis.size() / 2];
  }
  std::vector<double> dist;
  for (size_t i = 0; i < n; i += step) {
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double d = cloud.position[i * 3 + size_t(a)] - center[a];
      d2 += d * d;
    }
    if (std::isfinite(d2)) dist.push_back(std::sqrt(d2));
  }
  if (dist.empty()) return;
  const size_t k = std::min(dist.size() - 1, dist.size() * 9 / 10);
  std::nth_element(dist.begin(), dist.begin() + long(k), dist.end());
  *radius = std::max(1e-3, dist[k]);
}

}  // namespace

ViewSession::~ViewSession() {
  join_job();
}

Result<std::unique_ptr<ViewSession>> ViewSession::open(const ViewOptions& o) {
  std::unique_ptr<ViewSession> s(new ViewSession());
  s->options_ = o;
  if (o.results_dir.empty()) return Status::error("view: no results folder given");
  if (o.scene_dir.empty() == o.scene.empty())
    return Status::error("give one of --scene-dir DIR (a DL3DV-Closeup folder) or --scene S");
  std::string save_to = o.save_to;
  if (!o.scene_dir.empty()) {
    if (!is_directory(o.scene_dir))
      return Status::error("--scene-dir " + o.scene_dir + ": folder not found");
    // The references for plan / enhance; the close-up camera is replaced per job.
    SceneInputOptions in;
    in.scene_dir = o.scene_dir;
    in.cameras = o.cameras;
    in.closeup = "viewer";
    in.closeup_camera = gs::Camera();
    // A placeholder close-up: only the candidates and the splat are kept.
    in.closeup_camera->width = in.closeup_camera->height = 16;
    in.closeup_camera->fx = in.closeup_camera->fy = 16;
    in.closeup_camera->cx = in.closeup_camera->cy = 8;
    auto inputs = load_scene_inputs(in);
    if (!inputs) return inputs.status().with_context("--scene-dir " + o.scene_dir);
    auto cams = gs::load_cameras(inputs->cameras_path);
    if (!cams) return cams.status();
    s->cameras_ = cams->cameras;
    s->camera_notes = inputs->notes;
    s->inputs_ = std::move(*inputs);
    if (save_to.empty()) {
      const std::string split = (fs::path(o.scene_dir) / "split.json").string();
      save_to = file_exists(split) ? split : (fs::path(o.scene_dir) / "closeups.json").string();
    }
  } else {
    std::string scene = o.scene, cameras = o.cameras;
    if (is_directory(scene) && file_exists(scene + "/scene.ply")) {
      if (cameras.empty() && file_exists(scene + "/cameras.json"))
        cameras = scene + "/cameras.json";
      scene += "/scene.ply";
    }
    auto cloud = gs::load_scene(scene);
    if (!cloud) return cloud.status().with_context("--scene");
    s->cloud_ = std::move(*cloud);
    if (!cameras.empty()) {
      auto cams = gs::load_cameras(cameras);
      if (!cams) return cams.status().with_context("--cameras");
      s->cameras_ = cams->cameras;
    }
    if (save_to.empty()) save_to = (fs::path(scene).parent_path() / "closeups.json").string();
  }
  for (gs::Camera& c : s->cameras_) {
    if (c.has_distortion()) {
      s->camera_notes.push_back("camera " + c.name + " has lens distortion (" + c.model_text() +
                                "): shown as a pinhole");
      c.distortion.clear();
      c.model = gs::CameraModel::kPinhole;
    }
  }
  MACRO_ASSIGN_OR_RETURN(s->store_, open_closeup_store(save_to));
  if (auto listed = list_closeups(s->store_); !listed)
    return listed.status().with_context("--save-to");
  const gs::GaussianCloud& cloud = s->inputs_ ? s->inputs_->cloud : s->cloud_;
  if (cloud.size() == 0) return Status::error("--scene: the scene has no Gaussians");
  cloud_bounds(cloud, s->center_, &s->radius_);
  // Up: the mean of the cameras' up directions (OpenCV: -y of the camera, in the world).
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (const gs::Camera& c : s->cameras_) up -= c.R.row(1).transpose();
  if (up.norm() > 1e-6) {
    up.normalize();
    for (int a = 0; a < 3; ++a) s->up_[a] = up[a];
  }
  std::error_code ec;
  fs::create_directories(o.results_dir, ec);
  if (!is_directory(o.results_dir))
    return Status::error(o.results_dir + ": cannot create the results folder: " + ec.message());
  s->render_pool_ = std::make_unique<ThreadPool>(o.render_threads);
  return s;
}

Json ViewSession::scene_json() const {
  Json j;
  j["scene"] = options_.scene_dir.empty() ? options_.scene : options_.scene_dir;
  j["gaussians"] = (inputs_ ? inputs_->cloud : cloud_).size();
  Json cams = Json::array();
  for (const gs::Camera& c : cameras_) cams.push_back(camera_to_json(c));
  j["cameras"] = cams;
  j["bounds"] = {{"center", {center_[0], center_[1], center_[2]}}, {"radius", radius_}};
  j["up"] = {up_[0], up_[1], up_[2]};
  j["closeup_file"] = {{"path", store_.path}, {"kind", closeup_store_kind_name(store_.kind)}};
  j["can_plan"] = can_plan();
  j["enhancer"] = options_.weights.empty() ? "transfer (weight-free)" : "difix (network)";
  j["limits"] = {{"max_side", options_.limits.max_side},
                 {"max_pixels", options_.limits.max_pixels}};
  j["notes"] = camera_notes;
  return j;
}

std::optional<gs::Camera> ViewSession::find_camera(const std::string& name) const {
  for (const gs::Camera& c : cameras_)
    if (c.name == name) return c;
  if (auto listed = closeups(); listed)
    for (const gs::Camera& c : listed->cameras)
      if (c.name == name) return c;
  return std::nullopt;
}

Result<Frame> ViewSession::render(const gs::Camera& camera) {
  std::lock_guard<std::mutex> lock(render_mutex_);
  const gs::GaussianCloud& cloud = inputs_ ? inputs_->cloud : cloud_;
  Frame f;
  const auto t0 = std::chrono::steady_clock::now();
  // The options of `macro render` by default: classic, black background, SH degree 3.
  MACRO_TRY(rasterizer_.render_into(cloud, camera, gs::RenderOptions{}, &frame_, *render_pool_));
  f.ms_render = ms_since(t0);
  const auto t1 = std::chrono::steady_clock::now();
  gs::Image img(frame_.width, frame_.height, 3);
  img.data = frame_.color;
  MACRO_ASSIGN_OR_RETURN(f.png, gs::encode_png(img));
  f.ms_encode = ms_since(t1);
  f.width = frame_.width;
  f.height = frame_.height;
  f.visible = frame_.stats.visible;
  return f;
}

Result<gs::CameraSet> ViewSession::closeups() const {
  return list_closeups(store_);
}

Status ViewSession::save_closeup(const std::string& name, const gs::Camera& camera, bool overwrite,
                                 bool* exists) {
  std::lock_guard<std::mutex> lock(store_mutex_);
  std::vector<std::string> reserved;
  for (const gs::Camera& c : cameras_) reserved.push_back(c.name);
  return view::save_closeup(store_, name, camera, overwrite, reserved, exists);
}

Result<std::string> ViewSession::result_file(const std::string& rel) const {
  const size_t slash = rel.find('/');
  if (slash == std::string::npos || rel.find('/', slash + 1) != std::string::npos)
    return Status::error("result '" + rel + "': expected FOLDER/FILE");
  for (const std::string& part : {rel.substr(0, slash), rel.substr(slash + 1)}) {
    if (Status s = check_closeup_name(part); !s)
      return Status::error("result '" + rel + "': not a result name");
  }
  const std::string path = (fs::path(options_.results_dir) / rel).string();
  if (!file_exists(path) || is_directory(path))
    return Status::error("result '" + rel + "': no such file");
  return path;
}

}  // namespace macro::enhance::view
