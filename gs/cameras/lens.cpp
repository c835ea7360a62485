// Forward lens distortion (gs/cameras/lens.h has the formulas).
#include "gs/cameras/lens.h"

#include <cmath>

namespace macro::gs {

Eigen::Vector2d distort_normalized(const Camera& c, const Eigen::Vector2d& xy) {
  MACRO_CHECK(static_cast<int>(c.distortion.size()) >= camera_model_distortion_count(c.model));
  const double x = xy.x(), y = xy.y();
  const double r2 = x * x + y * y;
  const std::vector<double>& d = c.distortion;
  auto tangential = [&](double p1, double p2) {
    return Eigen::Vector2d(2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                           2 * p2 * x * y + p1 * (r2 + 2 * y * y));
  };
  switch (c.model) {
    case CameraModel::kPinhole:
      return xy;
    case CameraModel::kSimpleRadial:
      return xy * (1 + d[0] * r2);
    case CameraModel::kRadial:
      return xy * (1 + d[0] * r2 + d[1] * r2 * r2);
    case CameraModel::kOpenCV: {
      const double k3 = d.size() > 4 ? d[4] : 0.0;
      const double radial = 1 + d[0] * r2 + d[1] * r2 * r2 + k3 * r2 * r2 * r2;
      return xy * radial + tangential(d[2], d[3]);
    }
    case CameraModel::kFullOpenCV: {
      const double r4 = r2 * r2, r6 = r4 * r2;
      const double radial =
          (1 + d[0] * r2 + d[1] * r4 + d[4] * r6) / (1 + d[5] * r2 + d[6] * r4 + d[7] * r6);
      return xy * radial + tangential(d[2], d[3]);
    }
    case CameraModel::kOpenCVFisheye: {
      const double r = std::sqrt(r2);
      if (r < 1e-12) return xy;
      const double th = std::atan(r), t2 = th * th;
      const double th_d = th * (1 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))));
      return xy * (th_d / r);
    }
  }
  return xy;
}

Eigen::Vector3d project_distorted(const Camera& c, const Eigen::Vector3d& x_world) {
  const Eigen::Vector3d xc = c.R * x_world + c.t;
  const Eigen::Vector2d d = distort_normalized(c, {xc.x() / xc.z(), xc.y() / xc.z()});
  return {c.fx * d.x() + c.cx, c.fy * d.y() + c.cy, xc.z()};
}

std::vector<double> opencv_coefficients(const Camera& c) {
  const std::vector<double>& d = c.distortion;
  switch (c.model) {
    case CameraModel::kPinhole:
      return {};
    case CameraModel::kSimpleRadial:
      return {d.at(0), 0, 0, 0};
    case CameraModel::kRadial:
      return {d.at(0), d.at(1), 0, 0};
    case CameraModel::kOpenCV:
    case CameraModel::kFullOpenCV:
    case CameraModel::kOpenCVFisheye:
      return d;
  }
  return d;
}

}  // namespace macro::gs
