// Lens distortion models, forward direction only: an ideal (pinhole) normalised image point
// (x, y) = (X/Z, Y/Z) -> the distorted normalised point the lens images it at. COLMAP's
// definitions (src/colmap/sensor/models.h), with r2 = x^2 + y^2:
//   SIMPLE_RADIAL  s = k r2;                      x_d = x (1 + s)
//   RADIAL         s = k1 r2 + k2 r2^2;           x_d = x (1 + s)
//   OPENCV         s = k1 r2 + k2 r2^2 (+ k3 r2^3); x_d = x (1 + s) + 2 p1 x y + p2 (r2 + 2 x^2)
//                                                   y_d = y (1 + s) + 2 p2 x y + p1 (r2 + 2 y^2)
//   FULL_OPENCV    1 + s = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3),
//                  tangential terms as OPENCV
//   OPENCV_FISHEYE r = sqrt(r2), th = atan(r), th_d = th (1 + k1 th^2 + k2 th^4 + k3 th^6 + k4
//   th^8),
//                  x_d = x th_d / r (x_d = x at r = 0)
// Pixels follow the one convention (camera.h): u = fx x_d + cx with pixel centres at +0.5.
// Undistortion itself is OpenCV's (gs/cameras/undistort.h); these formulas are written out here so
// the tests can check it against something that is not OpenCV.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "gs/cameras/camera.h"

namespace macro::gs {

// The distorted normalised point of the ideal normalised point `xy` under the camera's model.
// The camera must have its model's coefficient count (Camera::validate).
Eigen::Vector2d distort_normalized(const Camera& camera, const Eigen::Vector2d& xy);

// Pixel (u, v) where the real (distorted) camera images a world point, and its camera depth z.
Eigen::Vector3d project_distorted(const Camera& camera, const Eigen::Vector3d& x_world);

// The camera's coefficients in OpenCV's order: distCoeffs (k1 k2 p1 p2 [k3 [k4 k5 k6]]) for the
// perspective models (SIMPLE_RADIAL -> k 0 0 0, RADIAL -> k1 k2 0 0), k1..k4 for the fisheye.
std::vector<double> opencv_coefficients(const Camera& camera);

}  // namespace macro::gs
