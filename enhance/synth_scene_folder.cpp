// Synthetic scene -> DL3DV-Closeup folder (see synth_scene_folder.h).
#include "enhance/synth_scene_folder.h"

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "gs/image_io.h"
#include "gs/rasterizer.h"
#include "gs/scene_io.h"

namespace macro::enhance {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

Status render_png(const gs::GaussianCloud& cloud, const gs::Camera& cam, int supersample,
                  const std::string& path, gs::Rasterizer& raster) {
  const int s = std::max(1, supersample);
  gs::RenderResult r;
  MACRO_TRY(raster.render_into(cloud, s == 1 ? cam : cam.resized(cam.width * s, cam.height * s),
                               {}, &r));
  gs::Image img(cam.width, cam.height, 3);
  if (s == 1) {
    img.data = r.color;
  } else {
    const float norm = 1.f / float(s * s);
    for (int i = 0; i < cam.height; ++i)
      for (int j = 0; j < cam.width; ++j)
        for (int c = 0; c < 3; ++c) {
          float sum = 0.f;
          for (int a = 0; a < s; ++a)
            for (int b = 0; b < s; ++b)
              sum += r.color[(size_t(i * s + a) * size_t(r.width) + size_t(j * s + b)) * 3 + c];
          img.at(i, j, c) = sum * norm;
        }
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
    MACRO_TRY(render_png(photos, c, o.supersample, (root / sub / frame(c.name)).string(), raster));
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
