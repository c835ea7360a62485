// Difix3D's progressive novel cameras (progressive_cameras.h).
#include "enhance/baselines/progressive_cameras.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

namespace macro::enhance {
namespace {

// The camera-to-world rotation as a unit quaternion (w, x, y, z).
Eigen::Vector4d c2w_quaternion(const gs::Camera& c) {
  const Eigen::Quaterniond q(Eigen::Matrix3d(c.R.transpose()));
  return Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()).normalized();
}

// Spherical interpolation from a to b (unit quaternions) at fraction s, the shorter way round;
// linear (then normalised) when they are within 1e-6 rad.
Eigen::Vector4d slerp(Eigen::Vector4d a, Eigen::Vector4d b, double s) {
  double dot = a.dot(b);
  if (dot < 0) b = -b, dot = -dot;
  dot = std::clamp(dot, -1.0, 1.0);
  const double theta = std::acos(dot);
  Eigen::Vector4d q;
  if (theta < 1e-6) {
    q = (1 - s) * a + s * b;
  } else {
    const double st = std::sin(theta);
    q = std::sin((1 - s) * theta) / st * a + std::sin(s * theta) / st * b;
  }
  return q.normalized();
}

}  // namespace

double pose_distance(const gs::Camera& a, const gs::Camera& b) {
  const double d = (a.center() - b.center()).norm();
  const double dot = c2w_quaternion(a).dot(c2w_quaternion(b));
  const double angle = std::acos(std::clamp(2 * dot * dot - 1, -1.0, 1.0));
  return d + angle;
}

int nearest_pose(const gs::Camera& target, const std::vector<gs::Camera>& poses) {
  int best = -1;
  double best_d = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < poses.size(); ++i) {
    const double d = pose_distance(target, poses[i]);
    if (d < best_d) best_d = d, best = int(i);
  }
  return best;
}

gs::Camera shift_pose(const gs::Camera& from, const gs::Camera& target, double step,
                      const gs::Camera& intrinsics, const std::string& name) {
  gs::Camera out = intrinsics;
  out.name = out.file_path = name;
  out.colmap_image_id = 0;
  if (pose_distance(from, target) <= step) {
    out.R = target.R;
    out.t = target.t;
    return out;
  }
  const Eigen::Vector3d cs = from.center(), ct = target.center(), dt = ct - cs;
  const double gap = dt.norm();
  Eigen::Vector3d c;
  Eigen::Matrix3d Rc;  // camera-to-world rotation
  if (gap <= 1e-6) {
    c = ct;
    Rc = target.R.transpose();
  } else {
    c = cs + step * dt / gap;
    if ((c - ct).norm() <= step) c = ct;
    const Eigen::Vector4d q =
        slerp(c2w_quaternion(from), c2w_quaternion(target), std::min(step / gap, 1.0));
    Rc = Eigen::Quaterniond(q(0), q(1), q(2), q(3)).toRotationMatrix();
  }
  out.R = Rc.transpose();
  out.t = -out.R * c;
  return out;
}

std::vector<std::vector<gs::Camera>> progressive_schedule(const std::vector<gs::Camera>& training,
                                                          const std::vector<gs::Camera>& targets,
                                                          int rounds, double step) {
  std::vector<std::vector<gs::Camera>> out;
  if (training.empty() || targets.empty()) return out;
  std::vector<gs::Camera> current = training;
  for (int r = 1; r <= rounds; ++r) {
    std::vector<gs::Camera> next;
    for (const gs::Camera& t : targets) {
      const gs::Camera& from = current[size_t(nearest_pose(t, current))];
      next.push_back(shift_pose(from, t, step, training.front(), t.name + "@" + std::to_string(r)));
    }
    out.push_back(next);
    current = std::move(next);
  }
  return out;
}

}  // namespace macro::enhance
