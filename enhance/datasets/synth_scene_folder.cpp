// Synthetic scene -> DL3DV-Closeup folder (see synth_scene_folder.h).
#include "enhance/datasets/synth_scene_folder.h"

#include <algorithm>
#include <cmath>
#include <vector>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/formats/scene_io.h"

namespace macro::enhance {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// Photo pixel (i, j) from the s x supersampled render: the mean of its s x s samples (box), or
// with `tent` a separable tent of radius one output pixel over the 2s x 2s samples around its
// centre (weights renormalised at the border), a sensor's blur that keeps detail finer than a
// pixel from aliasing into the photo.
Status render_png(const gs::GaussianCloud& cloud, const gs::Camera& cam, int supersample,
                  bool tent, const std::string& path, gs::Rasterizer& raster) {
  const int s = std::max(1, supersample);
  gs::RenderResult r;
  MACRO_TRY(raster.render_into(cloud, s == 1 ? cam : cam.resized(cam.width * s, cam.height * s),
                               {}, &r));
  gs::Image img(cam.width, cam.height, 3);
  if (s == 1) {
    img.data = r.color;
    return gs::write_png(path, img);
  }
  // Taps along one axis: high-res offsets k - s/2 ... relative to the pixel's first sample.
  std::vector<int> offset;
  std::vector<float> weight;
  if (!tent) {
    for (int k = 0; k < s; ++k) {
      offset.push_back(k);
      weight.push_back(1.f / float(s));
    }
  } else {
    for (int k = -s / 2; k < s + (s + 1) / 2; ++k) {
      const double d = std::abs(k + 0.5 - 0.5 * s) / double(s);  // output pixels from the centre
      if (d >= 1) continue;
      offset.push_back(k);
      weight.push_back(float(1 - d));
    }
  }
  for (int i = 0; i < cam.height; ++i)
    for (int j = 0; j < cam.width; ++j) {
      float sum[3] = {0.f, 0.f, 0.f}, wsum = 0.f;
      for (size_t a = 0; a < offset.size(); ++a) {
        const int y = i * s + offset[a];
        if (y < 0 || y >= r.height) continue;
        for (size_t b = 0; b < offset.size(); ++b) {
          const int x = j * s + offset[b];
          if (x < 0 || x >= r.width) continue;
          const float w = weight[a] * weight[b];
          const float* px = &r.color[(size_t(y) * size_t(r.width) + size_t(x)) * 3];
          for (int c = 0; c < 3; ++c) sum[c] += w * px[c];
          wsum += w;
        }
      }
      for (int c = 0; c < 3; ++c) img.at(i, j, c) = sum[c] / wsum;
    }
  return gs::write_png(path, img);
}

}  // namespace

Status write_closeup_scene_folder(const gs::SynthScene& scene, const std::string& dir,
                                  const SynthFolderOptions& o) {
  std::error_code ec;
  const fs::path root(dir);
  for (const char* sub : {"images", "sparse/0", "closeup_gt"}) {
    fs::create_directories(root / sub, ec);
    if (ec) return Status::error((root / sub).string() + ": cannot create folder: " + ec.message());
  }
  std::vector<const gs::Camera*> train, close;
  for (const gs::Camera& c : scene.cameras.cameras) {
    bool is_closeup = false;
    for (const gs::SynthCloseup& s : scene.geometry.closeups) is_closeup |= s.camera == c.name;
    (is_closeup ? close : train).push_back(&c);
  }
  if (train.empty())
    return Status::error("synthetic scene folder: the scene has no training camera");
  auto frame = [](const std::string& name) { return name + ".png"; };
  gs::Rasterizer raster;
  const gs::GaussianCloud& photos = o.photo_cloud ? *o.photo_cloud : scene.cloud;
  const auto photo = [&](const gs::Camera& c, const char* sub) -> Status {
    MACRO_TRY(render_png(photos, c, o.supersample, o.tent_filter, (root / sub / frame(c.name)).string(), raster));
    if (o.on_photo) o.on_photo();
    return Status::ok();
  };
  gs::CameraSet colmap;
  json training = json::array();
  for (const gs::Camera* c : train) {
    MACRO_TRY(photo(*c, "images"));
    gs::Camera named = *c;
    named.name = named.file_path = frame(c->name);
    colmap.cameras.push_back(named);
    training.push_back(frame(c->name));
  }
  json poses = json::object(), pairs = json::array();
  for (const gs::Camera* c : close) {
    if (o.closeup_gt) MACRO_TRY(photo(*c, "closeup_gt"));
    const Eigen::Matrix4d gl = gs::opengl_c2w_from_opencv_w2c(c->world_to_camera());
    json m = json::array();
    for (int r = 0; r < 4; ++r) m.push_back({gl(r, 0), gl(r, 1), gl(r, 2), gl(r, 3)});
    poses[frame(c->name)] = m;
    if (o.register_closeups) {
      gs::Camera named = *c;
      named.name = named.file_path = frame(c->name);
      colmap.cameras.push_back(named);
    }
  }
  for (const gs::SynthCloseup& s : scene.geometry.closeups)
    pairs.push_back({{"training_frame", frame(s.reference)},
                     {"closeup_frame", frame(s.camera)},
                     {"depth_ratio", s.zoom},
                     {"iou", 0.0},
                     {"angle_deg", 0.0},
                     {"pair_score", 0.0}});
  MACRO_TRY(gs::save_colmap_text(colmap, (root / "sparse" / "0").string()));
  const gs::Camera& k = *train.front();
  const std::string scene_name =
      o.scene_name.empty() ? "synthetic-seed-" + std::to_string(scene.params.seed) : o.scene_name;
  json split = {{"scene", scene_name},
                {"data_factor", 1},
                {"intrinsics",
                 {{"w", k.width},
                  {"h", k.height},
                  {"fl_x", k.fx},
                  {"fl_y", k.fy},
                  {"cx", k.cx},
                  {"cy", k.cy},
                  {"camera_model", "PINHOLE"}}},
                {"training_frames", training},
                {"closeup_eval_pairs", pairs},
                {"closeup_poses", poses},
                {"num_training_frames", training.size()},
                {"num_closeup_pairs", pairs.size()}};
  MACRO_TRY(write_file_atomic((root / "split.json").string(), split.dump(2) + "\n"));
  MACRO_TRY(gs::save_scene(scene.cloud, (root / o.ply_name).string()));
  if (o.photo_cloud && !o.photo_ply_name.empty())
    MACRO_TRY(gs::save_scene(*o.photo_cloud, (root / o.photo_ply_name).string()));
  return write_file_atomic((root / "geometry.json").string(), gs::geometry_to_json(scene));
}

}  // namespace macro::enhance
