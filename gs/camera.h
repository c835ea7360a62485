// Cameras. One internal convention everywhere (docs/formats.md):
//   OpenCV axes (x right, y down, z forward), world-to-camera x_c = R x_w + t,
//   pixel (row i, column j) has its centre at (j + 0.5, i + 0.5); u = fx * x/z + cx.
// Loaders for other conventions (COLMAP, nerfstudio, DL3DV-Closeup split JSON) convert on load.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::gs {

enum class CameraModel { kPinhole, kOpenCV, kOpenCVFisheye };

struct Camera {
  std::string name;
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world -> camera rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // world -> camera translation
  CameraModel model = CameraModel::kPinhole;
  std::vector<double> distortion;  // OPENCV: k1 k2 p1 p2 [k3...]; fisheye: k1..k4. Kept, not applied.

  Eigen::Vector3d center() const { return -R.transpose() * t; }
  // The same camera with intrinsics scaled to another image size (sx = new_w / width, ...).
  Camera resized(int new_width, int new_height) const;
  // Checks: positive size, finite positive focal lengths, finite principal point, R orthonormal
  // with det +1 (tolerance 1e-4), finite t. The message names the camera and the field.
  Status validate() const;
};

struct CameraSet {
  std::vector<Camera> cameras;
  // Camera by name; the error lists a few available names.
  Result<Camera> find(const std::string& name) const;
};

// Any supported camera file, detected by content: our JSON list (golden cameras.json), a COLMAP
// sparse folder (cameras/images .txt or .bin), nerfstudio transforms.json, or a DL3DV-Closeup split
// JSON (close-up poses + intrinsics). Implemented in gs/cameras_*.cpp.
Result<CameraSet> load_cameras(const std::string& path);

}  // namespace macro::gs
