// DL3DV-Closeup / MobileClose split JSON (docs/spec/macro-method.md §7):
//   scene, data_factor, intrinsics {w, h, fl_x, fl_y, cx, cy, k1, k2, p1, p2, camera_model} (and
//   k3..k6 for the models that take them),
//   training_frames (MobileClose: train_frames), optional closeup_frames,
//   closeup_eval_pairs [{training_frame, closeup_frame, depth_ratio, iou, angle_deg, pair_score}],
//   closeup_poses {frame: 4x4 camera-to-world, OpenGL axes, COLMAP world frame}.
// Each close-up pose becomes a Camera named by its key with the shared intrinsics; the pose is
// converted OpenGL c2w -> OpenCV w2c (negate columns 1 and 2, invert). No world transform.
#include "gs/cameras/camera.h"
#include "gs/cameras/cameras_json_fields.h"
#include "gs/cameras/cameras_lenient.h"

namespace macro::gs {
namespace {

using detail::Json;

// The shared intrinsics as a camera without pose or name.
Result<Camera> parse_intrinsics(const Json& root, const std::string& path) {
  if (!root.contains("intrinsics")) return Status::error(path + ": missing field 'intrinsics'");
  const Json& in = root["intrinsics"];
  const std::string where = path + ": intrinsics";
  if (!in.is_object())
    return Status::error(where + ": expected an object, found " + detail::describe_json(in));
  Camera c;
  MACRO_ASSIGN_OR_RETURN(c.width, detail::int_field(in, "w", where));
  MACRO_ASSIGN_OR_RETURN(c.height, detail::int_field(in, "h", where));
  MACRO_ASSIGN_OR_RETURN(c.fx, detail::number_field(in, "fl_x", where));
  MACRO_ASSIGN_OR_RETURN(c.fy, detail::number_field(in, "fl_y", where));
  MACRO_ASSIGN_OR_RETURN(c.cx, detail::number_field(in, "cx", where));
  MACRO_ASSIGN_OR_RETURN(c.cy, detail::number_field(in, "cy", where));
  const bool any_k =
      in.contains("k1") || in.contains("k2") || in.contains("p1") || in.contains("p2");
  std::string model = any_k ? "OPENCV" : "PINHOLE";
  if (in.contains("camera_model")) {
    MACRO_ASSIGN_OR_RETURN(model, detail::string_field(in, "camera_model", where));
  }
  MACRO_ASSIGN_OR_RETURN(c.model, detail::intrinsics_model(model, where));
  for (const char* key : detail::distortion_keys(c.model)) {
    MACRO_ASSIGN_OR_RETURN(double v, detail::number_field_or(in, key, 0.0, where));
    c.distortion.push_back(v);
  }
  if (c.model == CameraModel::kOpenCV) {
    MACRO_ASSIGN_OR_RETURN(double k3, detail::number_field_or(in, "k3", 0.0, where));
    if (k3 != 0) c.distortion.push_back(k3);
  }
  return c;
}

Result<CloseupEvalPair> parse_pair(const Json& p, const std::string& where) {
  if (!p.is_object())
    return Status::error(where + ": expected an object, found " + detail::describe_json(p));
  CloseupEvalPair pair;
  MACRO_ASSIGN_OR_RETURN(pair.training_frame, detail::string_field(p, "training_frame", where));
  MACRO_ASSIGN_OR_RETURN(pair.closeup_frame, detail::string_field(p, "closeup_frame", where));
  const std::string w = where + " ('" + pair.closeup_frame + "')";
  MACRO_ASSIGN_OR_RETURN(pair.depth_ratio, detail::number_field(p, "depth_ratio", w));
  MACRO_ASSIGN_OR_RETURN(pair.iou, detail::number_field(p, "iou", w));
  MACRO_ASSIGN_OR_RETURN(pair.angle_deg, detail::number_field(p, "angle_deg", w));
  MACRO_ASSIGN_OR_RETURN(pair.pair_score, detail::number_field(p, "pair_score", w));
  return pair;
}

}  // namespace

Result<CloseupSplit> load_closeup_split(const std::string& path, const CameraLoadOptions& options) {
  MACRO_ASSIGN_OR_RETURN(Json root, detail::parse_json_file(path));
  if (!root.is_object()) {
    return Status::error(path + ": expected a split object, found " + detail::describe_json(root));
  }
  CloseupSplit split;
  if (root.contains("scene")) {
    MACRO_ASSIGN_OR_RETURN(split.scene, detail::string_field(root, "scene", path));
  }
  if (root.contains("data_factor")) {
    MACRO_ASSIGN_OR_RETURN(split.data_factor, detail::int_field(root, "data_factor", path));
  }
  if (root.contains("training_frames")) {
    MACRO_ASSIGN_OR_RETURN(split.training_frames,
                           detail::string_list_field(root, "training_frames", path));
  } else if (root.contains("train_frames")) {
    MACRO_ASSIGN_OR_RETURN(split.training_frames,
                           detail::string_list_field(root, "train_frames", path));
  }
  if (root.contains("closeup_frames")) {
    split.has_closeup_frames = true;
    MACRO_ASSIGN_OR_RETURN(split.closeup_frames,
                           detail::string_list_field(root, "closeup_frames", path));
  }
  if (root.contains("closeup_eval_pairs")) {
    const Json& pairs = root["closeup_eval_pairs"];
    if (!pairs.is_array()) {
      return Status::error(path + ": field 'closeup_eval_pairs': expected a list, found " +
                           detail::describe_json(pairs));
    }
    for (size_t i = 0; i < pairs.size(); ++i) {
      MACRO_ASSIGN_OR_RETURN(
          CloseupEvalPair p,
          parse_pair(pairs[i], path + ": closeup_eval_pairs[" + std::to_string(i) + "]"));
      split.closeup_eval_pairs.push_back(std::move(p));
    }
  }

  MACRO_ASSIGN_OR_RETURN(Camera intr, parse_intrinsics(root, path));
  intr.name = "intrinsics";
  MACRO_TRY(intr.validate().with_context(path));
  if (!root.contains("closeup_poses"))
    return Status::error(path + ": missing field 'closeup_poses'");
  const Json& poses = root["closeup_poses"];
  if (!poses.is_object()) {
    return Status::error(path + ": field 'closeup_poses': expected an object {frame: 4x4}, found " +
                         detail::describe_json(poses));
  }
  split.closeups.source = path;
  int index = 0;
  for (auto it = poses.begin(); it != poses.end(); ++it, ++index) {
    const std::string where = path + ": closeup_poses['" + it.key() + "']";
    Result<Eigen::Matrix4d> c2w_gl = detail::matrix_value(it.value(), where, false);
    Camera c = intr;
    c.name = it.key();
    c.file_path = it.key();
    Status s = c2w_gl.status();
    if (s) {
      c.set_world_to_camera(opencv_w2c_from_opengl_c2w(*c2w_gl));
      s = c.validate().with_context(path);
    }
    if (!s) {
      if (options.strict) return s;
      split.closeups.rejected.push_back({index, it.key(), s.message()});
      continue;
    }
    split.closeups.cameras.push_back(std::move(c));
  }
  MACRO_ASSIGN_OR_RETURN(split.closeups,
                         detail::finish_lenient_load(std::move(split.closeups), path));
  return split;
}

}  // namespace macro::gs
