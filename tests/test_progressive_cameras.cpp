// Difix3D's progressive novel cameras (enhance/baselines/progressive_cameras.h) against poses
// computed by hand: a 2 m, 90-degree gap walked in 0.5 m steps, the snap rules, nearest-camera
// matching, rotation-only gaps.
#include <catch2/catch.hpp>

#include <Eigen/Geometry>
#include <cmath>

#include "enhance/baselines/progressive_cameras.h"

using namespace macro;
using namespace macro::enhance;

namespace {

// A camera at centre c whose camera-to-world rotation turns by `deg` about the world y axis.
gs::Camera posed(const std::string& name, Eigen::Vector3d c, double deg) {
  gs::Camera cam;
  cam.name = name;
  cam.width = 64;
  cam.height = 48;
  cam.fx = cam.fy = 50;
  cam.cx = 32;
  cam.cy = 24;
  const Eigen::Matrix3d Rc =
      Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  cam.R = Rc.transpose();
  cam.t = -cam.R * c;
  return cam;
}

// The camera-to-world turn about y, in degrees (the test poses turn about y only).
double yaw_deg(const gs::Camera& c) {
  const Eigen::Matrix3d Rc = c.R.transpose();
  return std::atan2(Rc(0, 2), Rc(2, 2)) * 180 / M_PI;
}

}  // namespace

TEST_CASE("progressive cameras: a 2 m, 90-degree gap in 0.5 m steps", "[baselines]") {
  const gs::Camera train = posed("train", {0, 0, 0}, 0);
  gs::Camera target = posed("close", {2, 0, 0}, 90);
  target.fx = 200;  // the novel cameras take the training camera's intrinsics, not the target's
  CHECK(pose_distance(train, target) == Approx(2 + M_PI / 2));
  const auto rounds = progressive_schedule({train}, {target}, 5);
  REQUIRE(rounds.size() == 5);
  // By hand: round 1 moves 0.5 m of 2 and turns a quarter of 90 (0.5 / 2): 22.5; round 2 0.5 of
  // 1.5 and a third of the remaining 67.5: 45; round 3 moves to 1.5 m, within 0.5 of the target,
  // so it snaps to 2 m, and turns half of 45 (0.5 / 1): 67.5; round 4 is 0 m + 22.5 deg = 0.39
  // <= 0.5 away: the target itself; round 5 stays.
  const double x[5] = {0.5, 1.0, 2.0, 2.0, 2.0};
  const double yaw[5] = {22.5, 45, 67.5, 90, 90};
  for (int r = 0; r < 5; ++r) {
    INFO("round " << r + 1);
    const gs::Camera& c = rounds[size_t(r)][0];
    CHECK(c.name == "close@" + std::to_string(r + 1));
    CHECK(c.center().x() == Approx(x[r]).margin(1e-12));
    CHECK(c.center().y() == Approx(0).margin(1e-12));
    CHECK(c.center().z() == Approx(0).margin(1e-12));
    CHECK(yaw_deg(c) == Approx(yaw[r]).margin(1e-9));
    CHECK(c.fx == 50);
    CHECK(c.width == 64);
  }
  CHECK((rounds[3][0].R - target.R).norm() <= 1e-12);
}

TEST_CASE("progressive cameras: nearest matching, snaps and rotation-only gaps", "[baselines]") {
  const gs::Camera a = posed("a", {0, 0, 0}, 0), b = posed("b", {4, 0, 0}, 0);
  // A target 1 m from b (and 3 m from a) starts from b: round 1 is at 3.5 m.
  const gs::Camera t = posed("t", {3, 0, 0}, 0);
  CHECK(nearest_pose(t, {a, b}) == 1);
  CHECK(nearest_pose(t, {}) == -1);
  const auto r = progressive_schedule({a, b}, {t}, 1);
  REQUIRE(r.size() == 1);
  CHECK(r[0][0].center().x() == Approx(3.0));  // 4 - 0.5 = 3.5 is within 0.5 of 3: snapped
  // 0.6 m away: one step to 0.1 m left, inside the snap radius, so the target itself.
  const gs::Camera u = posed("u", {4.6, 0, 0}, 0);
  CHECK(progressive_schedule({b}, {u}, 1)[0][0].center().x() == Approx(4.6));
  // 1.2 m away: 0.5 m, then 0.7 m left: not snapped.
  const gs::Camera v = posed("v", {5.2, 0, 0}, 0);
  const auto rv = progressive_schedule({b}, {v}, 2);
  CHECK(rv[0][0].center().x() == Approx(4.5));
  CHECK(rv[1][0].center().x() == Approx(5.2));
  // The same centre, 60 degrees apart (1.05 > 0.5): the rotation snaps in one round.
  const gs::Camera w = posed("w", {4, 0, 0}, 60);
  const gs::Camera s = progressive_schedule({b}, {w}, 1)[0][0];
  CHECK(yaw_deg(s) == Approx(60).margin(1e-9));
  CHECK(s.center().x() == Approx(4.0).margin(1e-12));
  // Two targets move independently; each is named after itself.
  const auto two =
      progressive_schedule({a}, {posed("p", {0, 0, 2}, 0), posed("q", {0, 0, -2}, 0)}, 1);
  REQUIRE(two[0].size() == 2);
  CHECK(two[0][0].name == "p@1");
  CHECK(two[0][0].center().z() == Approx(0.5));
  CHECK(two[0][1].center().z() == Approx(-0.5));
  CHECK(progressive_schedule({}, {t}, 3).empty());
}
