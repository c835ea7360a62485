// Camera and CameraSet methods, and the pose conventions every loader converts through
// (docs/cameras.md). Nothing here reads files.
#include "gs/cameras/camera.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>

#include "attention/runtime/limits.h"
#include "attention/runtime/text.h"

namespace macro::gs {
namespace {

std::string file_name_of(const std::string& path) {
  size_t slash = path.find_last_of("/\\");
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string strip_dot_slash(std::string p) {
  while (p.size() >= 2 && p[0] == '.' && (p[1] == '/' || p[1] == '\\')) p.erase(0, 2);
  return p;
}

// Where a lookup ended: one index, none, or several equally good candidates.
struct Lookup {
  int index = -1;
  std::vector<int> ambiguous;
};

// The file name without its last extension: "images/frame_00001.png" -> "frame_00001".
std::string stem_of(const std::string& path) {
  const std::string f = file_name_of(path);
  const size_t dot = f.find_last_of('.');
  return dot == std::string::npos || dot == 0 ? f : f.substr(0, dot);
}

Lookup lookup(const std::vector<Camera>& cams, const std::string& query) {
  const std::string q_path = strip_dot_slash(query);
  const std::string q_file = file_name_of(query);
  // Four passes, strictest first; a pass with exactly one hit wins, several hits are ambiguous.
  // The last matches a query without extension against the names' stems.
  for (int pass = 0; pass < 4; ++pass) {
    std::vector<int> hits;
    for (size_t i = 0; i < cams.size(); ++i) {
      const Camera& c = cams[i];
      bool hit = pass == 0   ? c.name == query
                 : pass == 1 ? !c.file_path.empty() && strip_dot_slash(c.file_path) == q_path
                 : pass == 2 ? file_name_of(c.name) == q_file
                             : stem_of(c.name) == q_file && stem_of(c.name) != file_name_of(c.name);
      if (hit) hits.push_back(static_cast<int>(i));
    }
    if (hits.size() == 1) return {hits[0], {}};
    if (hits.size() > 1) return {-1, hits};
  }
  return {};
}

}  // namespace

const char* camera_model_name(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return "PINHOLE";
    case CameraModel::kOpenCV:
      return "OPENCV";
    case CameraModel::kOpenCVFisheye:
      return "OPENCV_FISHEYE";
    case CameraModel::kSimpleRadial:
      return "SIMPLE_RADIAL";
    case CameraModel::kRadial:
      return "RADIAL";
    case CameraModel::kFullOpenCV:
      return "FULL_OPENCV";
  }
  return "?";
}

bool camera_model_from_name(const std::string& name, CameraModel* model) {
  for (CameraModel m :
       {CameraModel::kPinhole, CameraModel::kOpenCV, CameraModel::kOpenCVFisheye,
        CameraModel::kSimpleRadial, CameraModel::kRadial, CameraModel::kFullOpenCV}) {
    if (name == camera_model_name(m)) {
      *model = m;
      return true;
    }
  }
  return false;
}

int camera_model_distortion_count(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return 0;
    case CameraModel::kSimpleRadial:
      return 1;
    case CameraModel::kRadial:
      return 2;
    case CameraModel::kOpenCV:
    case CameraModel::kOpenCVFisheye:
      return 4;
    case CameraModel::kFullOpenCV:
      return 8;
  }
  return 0;
}

const char* camera_format_name(CameraFormat format) {
  switch (format) {
    case CameraFormat::kJson:
      return "cameras JSON";
    case CameraFormat::kColmapText:
      return "COLMAP text";
    case CameraFormat::kColmapBinary:
      return "COLMAP binary";
    case CameraFormat::kNerfstudio:
      return "nerfstudio transforms.json";
    case CameraFormat::kCloseupSplit:
      return "DL3DV-Closeup split JSON";
  }
  return "?";
}

// With pixel centres at +0.5 the continuous image plane spans [0, W] x [0, H] and maps linearly
// onto [0, W'] x [0, H'], so u' = sx * u for every point: fx' = sx fx and cx' = sx cx. (With
// integer centres it would be cx' = sx (cx + 0.5) - 0.5 instead.)
Camera Camera::resized(int new_width, int new_height) const {
  MACRO_CHECK(width > 0 && height > 0 && new_width > 0 && new_height > 0);
  const double sx = double(new_width) / double(width);
  const double sy = double(new_height) / double(height);
  Camera c = *this;
  c.width = new_width;
  c.height = new_height;
  c.fx = fx * sx;
  c.cx = cx * sx;
  c.fy = fy * sy;
  c.cy = cy * sy;
  return c;
}

Status Camera::validate() const {
  auto fail = [&](const std::string& what) {
    return Status::error("camera '" + name + "': " + what);
  };
  if (width <= 0 || height <= 0) {
    return fail("size " + std::to_string(width) + "x" + std::to_string(height) +
                ": expected width and height > 0");
  }
  // Checked here, where the camera is read, so the message can name the file; the renderer
  // allocates its image buffers from this size.
  if (uint64_t(width) * uint64_t(height) > resource_limits().max_image_pixels) {
    return fail("image " + std::to_string(width) + "x" + std::to_string(height) +
                " has more than the limit of " +
                std::to_string(resource_limits().max_image_pixels) + " pixels (--max-image-pixels)");
  }
  if (!std::isfinite(fx) || !(fx > 0))
    return fail("fx = " + format_number(fx) + ": expected finite and > 0");
  if (!std::isfinite(fy) || !(fy > 0))
    return fail("fy = " + format_number(fy) + ": expected finite and > 0");
  if (!std::isfinite(cx)) return fail("cx = " + format_number(cx) + ": expected a finite value");
  if (!std::isfinite(cy)) return fail("cy = " + format_number(cy) + ": expected a finite value");
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(R(r, c))) {
        return fail("R(" + std::to_string(r) + "," + std::to_string(c) +
                    ") = " + format_number(R(r, c)) + ": expected a finite value");
      }
    }
    if (!std::isfinite(t[r])) {
      return fail("t[" + std::to_string(r) + "] = " + format_number(t[r]) +
                  ": expected a finite value");
    }
  }
  const double ortho = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (!(ortho < 1e-4)) {
    return fail("rotation is not orthonormal: ||R^T R - I|| = " + format_number(ortho) +
                ", expected < 1e-4 (a rigid world-to-camera pose)");
  }
  const double det = R.determinant();
  if (!(std::abs(det - 1.0) < 1e-4)) {
    return fail("rotation has determinant " + format_number(det) +
                ", expected +1 (not a reflection)");
  }
  const int expected = camera_model_distortion_count(model);
  const int found = static_cast<int>(distortion.size());
  if (model != CameraModel::kPinhole && found < expected) {
    return fail(std::string(camera_model_name(model)) + " needs " + std::to_string(expected) +
                " distortion parameters, found " + std::to_string(found));
  }
  const int most = model == CameraModel::kOpenCV ? 5 : expected;
  if (model != CameraModel::kPinhole && found > most) {
    return fail(std::string(camera_model_name(model)) + " takes at most " + std::to_string(most) +
                " distortion parameters, found " + std::to_string(found));
  }
  for (size_t i = 0; i < distortion.size(); ++i) {
    if (!std::isfinite(distortion[i])) {
      return fail("distortion[" + std::to_string(i) + "] = " + format_number(distortion[i]) +
                  ": expected a finite value");
    }
  }
  return Status::ok();
}

bool Camera::has_distortion() const {
  if (model == CameraModel::kPinhole) return false;
  for (double d : distortion)
    if (d != 0) return true;
  return false;
}

std::string Camera::model_text() const {
  static const char* const kNames[][8] = {
      {},
      {"k1", "k2", "p1", "p2", "k3"},
      {"k1", "k2", "k3", "k4"},
      {"k"},
      {"k1", "k2"},
      {"k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"},
  };
  std::string text = camera_model_name(model);
  const auto& names = kNames[static_cast<int>(model)];
  for (size_t i = 0; i < distortion.size() && i < 8; ++i) {
    char buf[48];
    std::snprintf(buf, sizeof buf, " %s=%.9g", names[i] ? names[i] : "?", distortion[i]);
    text += buf;
  }
  return text;
}

Status refuse_distorted(const Camera& camera, const std::string& what, const std::string& remedy) {
  if (!camera.has_distortion()) return Status::ok();
  return Status::error("camera '" + camera.name + "' is " + camera.model_text() + ": " + what +
                       " draws pinhole images and would ignore this lens distortion; " + remedy);
}

Eigen::Matrix3d Camera::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

Eigen::Matrix4d Camera::world_to_camera() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = R;
  m.topRightCorner<3, 1>() = t;
  return m;
}

Eigen::Matrix4d Camera::camera_to_world() const {
  return invert_rigid(world_to_camera());
}

void Camera::set_world_to_camera(const Eigen::Matrix4d& w2c) {
  R = w2c.topLeftCorner<3, 3>();
  t = w2c.topRightCorner<3, 1>();
}

Eigen::Vector3d Camera::project(const Eigen::Vector3d& x_world) const {
  const Eigen::Vector3d xc = R * x_world + t;
  return {fx * xc.x() / xc.z() + cx, fy * xc.y() / xc.z() + cy, xc.z()};
}

int CameraSet::index_of(const std::string& name) const {
  return lookup(cameras, name).index;
}

Result<Camera> CameraSet::find(const std::string& name) const {
  const Lookup l = lookup(cameras, name);
  if (l.index >= 0) return cameras[l.index];
  const std::string where = source.empty() ? "camera set" : source;
  if (!l.ambiguous.empty()) {
    std::string msg = where + ": camera name '" + name + "' is ambiguous, it matches";
    for (size_t i = 0; i < l.ambiguous.size() && i < 8; ++i) {
      const Camera& c = cameras[l.ambiguous[i]];
      msg += std::string(i ? ", '" : " '") + (c.file_path.empty() ? c.name : c.file_path) + "'";
    }
    if (l.ambiguous.size() > 8) msg += ", ...";
    return Status::error(msg + "; give the full name");
  }
  for (const RejectedCamera& r : rejected) {
    if (!r.name.empty() && (r.name == name || file_name_of(r.name) == file_name_of(name) ||
                            stem_of(r.name) == file_name_of(name))) {
      return Status::error(where + ": camera '" + name + "' (entry " + std::to_string(r.index) +
                           ") was left out as invalid: " + r.message);
    }
  }
  std::string msg =
      where + ": no camera named '" + name + "' among " + count_noun(cameras.size(), "camera");
  if (!cameras.empty()) {
    msg += " (available: ";
    const size_t shown = std::min<size_t>(cameras.size(), 5);
    for (size_t i = 0; i < shown; ++i) msg += (i ? ", '" : "'") + cameras[i].name + "'";
    msg += cameras.size() > shown ? ", ...)" : ")";
  }
  return Status::error(msg);
}

Eigen::Matrix3d rotation_from_quaternion_wxyz(double qw, double qx, double qy, double qz) {
  const double n = std::sqrt(qw * qw + qx * qx + qy * qy + qz * qz);
  const double w = qw / n, x = qx / n, y = qy / n, z = qz / n;
  Eigen::Matrix3d r;
  r << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),  //
      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),   //
      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return r;
}

Eigen::Vector4d quaternion_wxyz_from_rotation(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
  return q.w() < 0 ? Eigen::Vector4d(-v) : v;
}

Eigen::Matrix4d invert_rigid(const Eigen::Matrix4d& m) {
  const Eigen::Matrix3d rt = m.topLeftCorner<3, 3>().transpose();
  Eigen::Matrix4d inv = Eigen::Matrix4d::Identity();
  inv.topLeftCorner<3, 3>() = rt;
  inv.topRightCorner<3, 1>() = -rt * m.topRightCorner<3, 1>();
  return inv;
}

Eigen::Matrix4d opencv_w2c_from_opengl_c2w(const Eigen::Matrix4d& c2w_gl) {
  Eigen::Matrix4d c2w_cv = c2w_gl;
  c2w_cv.row(3) << 0, 0, 0, 1;
  c2w_cv.block<3, 2>(0, 1) *= -1.0;  // camera y up -> down, z back -> forward
  return invert_rigid(c2w_cv);
}

Eigen::Matrix4d opengl_c2w_from_opencv_w2c(const Eigen::Matrix4d& w2c_cv) {
  Eigen::Matrix4d c2w = invert_rigid(w2c_cv);
  c2w.block<3, 2>(0, 1) *= -1.0;
  return c2w;
}

}  // namespace macro::gs
