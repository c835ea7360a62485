// Saving and listing the viewer's close-ups (see closeup_store.h).
#include "enhance/view/closeup_store.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"

namespace macro::enhance::view {

using Json = nlohmann::ordered_json;  // keeps the split's keys in file order

const char* closeup_store_kind_name(CloseupStore::Kind kind) {
  return kind == CloseupStore::kSplit ? "split" : "cameras";
}

Result<CloseupStore> open_closeup_store(const std::string& path) {
  CloseupStore store;
  store.path = path;
  if (path.empty()) return Status::error("close-up file: no path given");
  if (is_directory(path)) return Status::error(path + ": is a folder, expected a JSON file");
  if (file_exists(path)) {
    MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 1ull << 28));
    if (text.find("\"closeup_poses\"") != std::string::npos) store.kind = CloseupStore::kSplit;
  }
  return store;
}

Result<gs::CameraSet> list_closeups(const CloseupStore& store) {
  if (store.kind == CloseupStore::kSplit) {
    MACRO_ASSIGN_OR_RETURN(gs::CloseupSplit split, gs::load_closeup_split(store.path));
    return split.closeups;
  }
  if (!file_exists(store.path)) return gs::CameraSet{};
  return gs::load_cameras_json(store.path);
}

Status check_closeup_name(const std::string& name) {
  if (name.empty() || name.size() > 128)
    return Status::error("close-up name: expected 1..128 characters, found " +
                         std::to_string(name.size()));
  if (name[0] == '.') return Status::error("close-up name '" + name + "': must not start with '.'");
  for (char ch : name) {
    const bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') ||
                    (ch >= '0' && ch <= '9') || ch == '.' || ch == '_' || ch == '-';
    if (!ok)
      return Status::error("close-up name '" + name +
                           "': only letters, digits, '.', '_' and '-' are allowed");
  }
  return Status::ok();
}

namespace {

bool near(double a, double b) {
  return std::abs(a - b) <= 1e-9 * std::max(1.0, std::abs(b));
}

Status save_to_split(const CloseupStore& store, const std::string& name, const gs::Camera& cam,
                     bool overwrite, bool* exists) {
  // The loader checks the whole file first: a split it cannot read is not rewritten.
  MACRO_TRY(gs::load_closeup_split(store.path).status());
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(store.path, 1ull << 28));
  Json root = Json::parse(text, nullptr, false);
  if (root.is_discarded() || !root.is_object() || !root.contains("closeup_poses") ||
      !root["closeup_poses"].is_object())
    return Status::error(store.path + ": expected a split JSON object with 'closeup_poses'");
  if (root.contains("intrinsics") && root["intrinsics"].is_object()) {
    const Json& in = root["intrinsics"];
    auto num = [&](const char* k) {
      return in.contains(k) && in[k].is_number() ? in[k].get<double>() : NAN;
    };
    const double w = num("w"), h = num("h");
    const bool sized = std::isfinite(w) && std::isfinite(h);
    const bool same = near(cam.fx, num("fl_x")) && near(cam.fy, num("fl_y")) &&
                      near(cam.cx, num("cx")) && near(cam.cy, num("cy")) &&
                      (!sized || (near(cam.width, w) && near(cam.height, h)));
    if (!same) {
      char buf[512];
      std::snprintf(
          buf, sizeof buf,
          ": the split's close-ups share its intrinsics (%gx%g, fx %g fy %g cx %g cy %g); "
          "this camera has %dx%d, fx %g fy %g cx %g cy %g. Reset the field of view, or "
          "save to a cameras JSON (macro view --save-to FILE.json)",
          w, h, num("fl_x"), num("fl_y"), num("cx"), num("cy"), cam.width, cam.height, cam.fx,
          cam.fy, cam.cx, cam.cy);
      return Status::error(store.path + buf);
    }
  }
  Json& poses = root["closeup_poses"];
  if (poses.contains(name) && !overwrite) {
    if (exists) *exists = true;
    return Status::error(store.path + ": close-up '" + name +
                         "' exists already (save with overwrite to replace it)");
  }
  const Eigen::Matrix4d c2w = gs::opengl_c2w_from_opencv_w2c(cam.world_to_camera());
  Json rows = Json::array();
  for (int r = 0; r < 4; ++r) rows.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
  poses[name] = rows;
  return write_file_atomic(store.path, root.dump(2) + "\n");
}

Status save_to_cameras(const CloseupStore& store, const std::string& name, const gs::Camera& cam,
                       bool overwrite, bool* exists) {
  gs::CameraSet set;
  if (file_exists(store.path)) {
    // Strict: rewriting the file must not drop an entry the lenient loader would leave out.
    gs::CameraLoadOptions strict;
    strict.strict = true;
    MACRO_ASSIGN_OR_RETURN(set, gs::load_cameras_json(store.path, strict));
  }
  gs::Camera saved = cam;
  saved.name = name;
  saved.file_path.clear();
  auto it = std::find_if(set.cameras.begin(), set.cameras.end(),
                         [&](const gs::Camera& c) { return c.name == name; });
  if (it != set.cameras.end()) {
    if (!overwrite) {
      if (exists) *exists = true;
      return Status::error(store.path + ": close-up '" + name +
                           "' exists already (save with overwrite to replace it)");
    }
    *it = saved;
  } else {
    set.cameras.push_back(saved);
  }
  return gs::save_cameras_json(set, store.path);
}

}  // namespace

Status save_closeup(const CloseupStore& store, const std::string& name, const gs::Camera& camera,
                    bool overwrite, const std::vector<std::string>& reserved, bool* exists) {
  if (exists) *exists = false;
  MACRO_TRY(check_closeup_name(name));
  if (std::find(reserved.begin(), reserved.end(), name) != reserved.end())
    return Status::error("close-up name '" + name +
                         "': a training camera has this name; choose another");
  MACRO_TRY(camera.validate().with_context("close-up '" + name + "'"));
  if (store.kind == CloseupStore::kSplit)
    return save_to_split(store, name, camera, overwrite, exists);
  return save_to_cameras(store, name, camera, overwrite, exists);
}

}  // namespace macro::enhance::view
