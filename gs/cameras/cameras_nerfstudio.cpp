// nerfstudio / instant-ngp / Blender transforms.json (docs/cameras.md, docs/spec/gs-rasterizer.md
// §2.5).
//
//   frames[i].transform_matrix  camera-to-world, OpenGL camera axes (x right, y up, z back), 4x4 or
//                               3x4, in the transforms.json world frame.
//   intrinsics                  fl_x fl_y cx cy w h camera_model k1..k6 p1 p2, per frame or
//                               at the top level (a frame's own value wins). Blender files give
//                               camera_angle_x (and maybe camera_angle_y) instead:
//                               fx = 0.5 w / tan(camera_angle_x / 2).
//   applied_transform           3x4 / 4x4 A that ns-process-data applied to COLMAP world points,
//                               x_ns = A x_colmap. Undone by default (CameraLoadOptions).
//
// Conversion per frame: P = transform_matrix; if applied_transform is present (and undone), write
// A = [s Q | a] (s = cbrt(det), Q a rotation, else an error) and map the camera into the COLMAP
// frame: centre' = A^-1 centre, R_c2w' = Q^T R_c2w (for a rigid A this is exactly A^-1 P). Then
// OpenGL -> OpenCV: negate columns 1 and 2 of R_c2w, and invert to world-to-camera.
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include "gs/cameras/camera.h"
#include "gs/cameras/cameras_json_fields.h"
#include "gs/cameras/cameras_lenient.h"

namespace macro::gs {
namespace {

using detail::Json;

std::string parent_dir(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string(".") : path.substr(0, slash);
}

std::string file_name_of(const std::string& path) {
  const size_t slash = path.find_last_of("/\\");
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

// Width and height from a PNG header (Blender-style files have no w/h). False if not a PNG.
bool png_size(const std::string& path, int* w, int* h) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  unsigned char b[24];
  const size_t got = std::fread(b, 1, sizeof b, f);
  std::fclose(f);
  static const unsigned char kSig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (got != sizeof b || std::memcmp(b, kSig, 8) != 0 || std::memcmp(b + 12, "IHDR", 4) != 0) {
    return false;
  }
  auto be32 = [](const unsigned char* p) {
    return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | uint32_t(p[3]);
  };
  const uint32_t pw = be32(b + 16), ph = be32(b + 20);
  if (pw == 0 || ph == 0 || pw > 1u << 30 || ph > 1u << 30) return false;
  *w = int(pw);
  *h = int(ph);
  return true;
}

// A field of the frame, else of the top level.
const Json* lookup(const Json& frame, const Json& root, const char* key) {
  if (frame.is_object() && frame.contains(key)) return &frame[key];
  if (root.contains(key)) return &root[key];
  return nullptr;
}

Result<double> number(const Json& frame, const Json& root, const char* key,
                      const std::string& where) {
  if (frame.is_object() && frame.contains(key)) return detail::number_field(frame, key, where);
  return detail::number_field(root, key, where + " (top level)");
}

// The inverse world map of applied_transform as (M^-1, a, Q^T): x_colmap = M^-1 (x_ns - a).
struct WorldUndo {
  Eigen::Matrix3d m_inv = Eigen::Matrix3d::Identity();
  Eigen::Vector3d a = Eigen::Vector3d::Zero();
  Eigen::Matrix3d q_t = Eigen::Matrix3d::Identity();
};

Result<WorldUndo> parse_applied_transform(const Json& value, const std::string& where) {
  MACRO_ASSIGN_OR_RETURN(Eigen::Matrix4d A, detail::matrix_value(value, where, true));
  const Eigen::Matrix3d M = A.topLeftCorner<3, 3>();
  const double det = M.determinant();
  const double s = std::cbrt(det);
  if (!std::isfinite(s) || !(s > 0)) {
    return Status::error(where + ": determinant " + std::to_string(det) +
                         ", expected a positive similarity (rotation x scale + translation)");
  }
  const Eigen::Matrix3d Q = M / s;
  const double err = (Q.transpose() * Q - Eigen::Matrix3d::Identity()).norm();
  if (!(err < 1e-6)) {
    return Status::error(where + ": not a similarity: ||Q^T Q - I|| = " + std::to_string(err) +
                         " for Q = M / cbrt(det M)");
  }
  WorldUndo u;
  u.m_inv = M.inverse();
  u.a = A.topRightCorner<3, 1>();
  u.q_t = Q.transpose();
  return u;
}

// `name` receives the frame's name as soon as it is read (for the rejection list).
Result<Camera> frame_camera(const Json& frame, const Json& root, const std::string& where0,
                            const std::string& base_dir, const WorldUndo* undo, std::string* name) {
  if (!frame.is_object()) {
    return Status::error(where0 + ": expected an object, found " + detail::describe_json(frame));
  }
  Camera c;
  MACRO_ASSIGN_OR_RETURN(c.file_path, detail::string_field(frame, "file_path", where0));
  c.name = file_name_of(c.file_path);
  *name = c.name;
  const std::string where = where0 + " '" + c.file_path + "'";

  // Size: w/h, else the PNG header (Blender files).
  if (lookup(frame, root, "w") || lookup(frame, root, "h")) {
    MACRO_ASSIGN_OR_RETURN(double w, number(frame, root, "w", where));
    MACRO_ASSIGN_OR_RETURN(double h, number(frame, root, "h", where));
    if (!(w == std::floor(w) && h == std::floor(h) && std::abs(w) < 1e9 && std::abs(h) < 1e9)) {
      return Status::error(where + ": fields 'w'/'h': expected integers, found " +
                           std::to_string(w) + " x " + std::to_string(h));
    }
    c.width = int(w);
    c.height = int(h);
  } else {
    const std::string img = base_dir + "/" + c.file_path;
    if (!png_size(img, &c.width, &c.height) && !png_size(img + ".png", &c.width, &c.height)) {
      return Status::error(where + ": missing fields 'w' and 'h', and no PNG image at " + img +
                           " to take the size from");
    }
  }

  // Focal lengths.
  if (lookup(frame, root, "fl_x")) {
    MACRO_ASSIGN_OR_RETURN(c.fx, number(frame, root, "fl_x", where));
  } else if (lookup(frame, root, "camera_angle_x")) {
    MACRO_ASSIGN_OR_RETURN(double ax, number(frame, root, "camera_angle_x", where));
    c.fx = 0.5 * c.width / std::tan(0.5 * ax);
  } else {
    return Status::error(where + ": missing field 'fl_x' (or 'camera_angle_x')");
  }
  if (lookup(frame, root, "fl_y")) {
    MACRO_ASSIGN_OR_RETURN(c.fy, number(frame, root, "fl_y", where));
  } else if (lookup(frame, root, "camera_angle_y")) {
    MACRO_ASSIGN_OR_RETURN(double ay, number(frame, root, "camera_angle_y", where));
    c.fy = 0.5 * c.height / std::tan(0.5 * ay);
  } else {
    c.fy = c.fx;
  }
  // Principal point, default the image centre (w/2, h/2 with +0.5 pixel centres).
  c.cx = 0.5 * c.width;
  c.cy = 0.5 * c.height;
  if (lookup(frame, root, "cx")) {
    MACRO_ASSIGN_OR_RETURN(c.cx, number(frame, root, "cx", where));
  }
  if (lookup(frame, root, "cy")) {
    MACRO_ASSIGN_OR_RETURN(c.cy, number(frame, root, "cy", where));
  }

  // Model and distortion.
  const bool any_k = lookup(frame, root, "k1") || lookup(frame, root, "k2") ||
                     lookup(frame, root, "p1") || lookup(frame, root, "p2");
  c.model = any_k ? CameraModel::kOpenCV : CameraModel::kPinhole;
  if (const Json* m = lookup(frame, root, "camera_model")) {
    if (!m->is_string()) {
      return Status::error(where + ": field 'camera_model': expected a string, found " +
                           detail::describe_json(*m));
    }
    MACRO_ASSIGN_OR_RETURN(c.model, detail::intrinsics_model(m->get<std::string>(), where));
  }
  auto coef = [&](const char* key) -> Result<double> {
    if (!lookup(frame, root, key)) return 0.0;
    return number(frame, root, key, where);
  };
  for (const char* key : detail::distortion_keys(c.model)) {
    MACRO_ASSIGN_OR_RETURN(double v, coef(key));
    c.distortion.push_back(v);
  }
  if (c.model == CameraModel::kOpenCV) {
    MACRO_ASSIGN_OR_RETURN(double k3, coef("k3"));
    if (k3 != 0) c.distortion.push_back(k3);
  }

  // Pose.
  if (!frame.contains("transform_matrix"))
    return Status::error(where + ": missing field 'transform_matrix'");
  MACRO_ASSIGN_OR_RETURN(
      Eigen::Matrix4d c2w,
      detail::matrix_value(frame["transform_matrix"], where + ": transform_matrix", true));
  if (undo) {
    Eigen::Matrix4d p = Eigen::Matrix4d::Identity();
    p.topLeftCorner<3, 3>() = undo->q_t * c2w.topLeftCorner<3, 3>();
    p.topRightCorner<3, 1>() = undo->m_inv * (c2w.topRightCorner<3, 1>() - undo->a);
    c2w = p;
  }
  c.set_world_to_camera(opencv_w2c_from_opengl_c2w(c2w));
  MACRO_TRY(c.validate().with_context(where));
  return c;
}

}  // namespace

Result<CameraSet> load_nerfstudio(const std::string& path, const CameraLoadOptions& options) {
  MACRO_ASSIGN_OR_RETURN(Json root, detail::parse_json_file(path));
  if (!root.is_object()) {
    return Status::error(path + ": expected a transforms.json object, found " +
                         detail::describe_json(root));
  }
  if (!root.contains("frames")) return Status::error(path + ": missing field 'frames'");
  const Json& frames = root["frames"];
  if (!frames.is_array()) {
    return Status::error(path + ": field 'frames': expected a list, found " +
                         detail::describe_json(frames));
  }
  WorldUndo undo;
  const bool has_undo = options.undo_applied_transform && root.contains("applied_transform");
  if (has_undo) {
    MACRO_ASSIGN_OR_RETURN(
        undo, parse_applied_transform(root["applied_transform"], path + ": applied_transform"));
  }
  CameraSet set;
  set.source = path;
  set.cameras.reserve(frames.size());
  const std::string base = parent_dir(path);
  for (size_t i = 0; i < frames.size(); ++i) {
    std::string name;
    Result<Camera> c = frame_camera(frames[i], root, path + ": frames[" + std::to_string(i) + "]",
                                    base, has_undo ? &undo : nullptr, &name);
    if (!c) {
      if (options.strict) return c.status();
      set.rejected.push_back({int(i), name, c.status().message()});
      continue;
    }
    set.cameras.push_back(std::move(*c));
  }
  return detail::finish_lenient_load(std::move(set), path);
}

}  // namespace macro::gs
