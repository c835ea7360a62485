// Our camera JSON (the golden cameras.json layout): a list of
//   {name, width, height, fx, fy, cx, cy, world_to_camera: 4x4 row-major OpenCV w2c}
// plus optional "model" (PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV, OPENCV_FISHEYE),
// "distortion" (list, the model's coefficients in COLMAP's order) and "file_path". Already in the
// internal convention, so loading is a copy. Non-strict loading leaves invalid entries out.
#include <cmath>

#include "attention/runtime/file_io.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/cameras_json_fields.h"
#include "gs/cameras/cameras_lenient.h"

namespace macro::gs {
namespace {

using detail::Json;

Result<CameraModel> model_from_name(const std::string& name, const std::string& where) {
  CameraModel m;
  if (camera_model_from_name(name, &m)) return m;
  return Status::error(where + ": field 'model': unknown camera model '" + name +
                       "' (expected PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV or "
                       "OPENCV_FISHEYE)");
}

// `name` receives the entry's name as soon as it is read (for the rejection list).
Result<Camera> camera_from_json(const Json& e, const std::string& where0, std::string* name) {
  if (!e.is_object())
    return Status::error(where0 + ": expected an object, found " + detail::describe_json(e));
  Camera c;
  MACRO_ASSIGN_OR_RETURN(c.name, detail::string_field(e, "name", where0));
  *name = c.name;
  const std::string where = where0 + " '" + c.name + "'";
  MACRO_ASSIGN_OR_RETURN(c.width, detail::int_field(e, "width", where));
  MACRO_ASSIGN_OR_RETURN(c.height, detail::int_field(e, "height", where));
  MACRO_ASSIGN_OR_RETURN(c.fx, detail::number_field(e, "fx", where));
  MACRO_ASSIGN_OR_RETURN(c.fy, detail::number_field(e, "fy", where));
  MACRO_ASSIGN_OR_RETURN(c.cx, detail::number_field(e, "cx", where));
  MACRO_ASSIGN_OR_RETURN(c.cy, detail::number_field(e, "cy", where));
  if (!detail::has_field(e, "world_to_camera")) {
    return Status::error(where + ": missing field 'world_to_camera'");
  }
  MACRO_ASSIGN_OR_RETURN(
      Eigen::Matrix4d w2c,
      detail::matrix_value(e["world_to_camera"], where + ": world_to_camera", false));
  c.set_world_to_camera(w2c);
  if (detail::has_field(e, "model")) {
    MACRO_ASSIGN_OR_RETURN(std::string model, detail::string_field(e, "model", where));
    MACRO_ASSIGN_OR_RETURN(c.model, model_from_name(model, where));
  }
  if (detail::has_field(e, "distortion")) {
    const Json& d = e["distortion"];
    if (!d.is_array()) {
      return Status::error(where + ": field 'distortion': expected a list of numbers, found " +
                           detail::describe_json(d));
    }
    for (size_t i = 0; i < d.size(); ++i) {
      if (!d[i].is_number()) {
        return Status::error(where + ": field 'distortion'[" + std::to_string(i) +
                             "]: expected a number, found " + detail::describe_json(d[i]));
      }
      c.distortion.push_back(d[i].get<double>());
    }
  }
  if (detail::has_field(e, "file_path")) {
    MACRO_ASSIGN_OR_RETURN(c.file_path, detail::string_field(e, "file_path", where));
  }
  return c;
}

}  // namespace

Result<CameraSet> load_cameras_json(const std::string& path, const CameraLoadOptions& options) {
  MACRO_ASSIGN_OR_RETURN(Json root, detail::parse_json_file(path));
  if (!root.is_array()) {
    return Status::error(path + ": expected a list of cameras, found " +
                         detail::describe_json(root));
  }
  CameraSet set;
  set.source = path;
  set.cameras.reserve(root.size());
  for (size_t i = 0; i < root.size(); ++i) {
    std::string name;
    Result<Camera> c = camera_from_json(root[i], path + ": [" + std::to_string(i) + "]", &name);
    Status s = c ? c->validate().with_context(path + ": [" + std::to_string(i) + "]") : c.status();
    if (!s) {
      if (options.strict) return s;
      set.rejected.push_back({int(i), name, s.message()});
      continue;
    }
    set.cameras.push_back(std::move(*c));
  }
  return detail::finish_lenient_load(std::move(set), path);
}

Status save_cameras_json(const CameraSet& set, const std::string& path) {
  Json root = Json::array();
  for (const Camera& c : set.cameras) {
    MACRO_TRY(c.validate().with_context(path));
    Json e = Json::object();
    e["name"] = c.name;
    e["width"] = c.width;
    e["height"] = c.height;
    e["fx"] = c.fx;
    e["fy"] = c.fy;
    e["cx"] = c.cx;
    e["cy"] = c.cy;
    const Eigen::Matrix4d m = c.world_to_camera();
    Json rows = Json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
    e["world_to_camera"] = rows;
    if (c.model != CameraModel::kPinhole || !c.distortion.empty()) {
      e["model"] = camera_model_name(c.model);
      e["distortion"] = c.distortion;
    }
    if (!c.file_path.empty() && c.file_path != c.name) e["file_path"] = c.file_path;
    root.push_back(std::move(e));
  }
  // nlohmann writes doubles in the shortest form that reads back to the same value.
  return write_file_atomic(path, root.dump(1) + "\n");
}

}  // namespace macro::gs
