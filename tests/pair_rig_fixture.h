// The analytic camera rigs of the pair-construction tests (tests/test_pair_construction*.cpp):
// cameras looking at cubes of points at known distances, and the rig written as a COLMAP scene.
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "enhance/datasets/pair_construction.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/colmap_points.h"
#include "gs/image_io.h"
#include "gs/synth/random_scene.h"
#include "gs/formats/scene_io.h"
#include "tests/test_support.h"

namespace macro::pair_test {

using enhance::PairConstruction;
using enhance::PairMeasure;
using enhance::PairParams;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// 100x100 pinhole, f = 50: tan(diagonal half FOV) = sqrt(1 + 1), half FOV = 54.7356 deg.
inline gs::Camera rig_camera(const std::string& name, const Eigen::Vector3d& centre,
                             const Eigen::Vector3d& axis) {
  gs::Camera c;
  c.name = c.file_path = name;
  c.width = c.height = 100;
  c.fx = c.fy = 50;
  c.cx = c.cy = 50;
  const Eigen::Vector3d z = axis.normalized();
  const Eigen::Vector3d y(0, 1, 0);  // every rig axis lies in the x-z plane
  const Eigen::Vector3d x = y.cross(z);
  c.R.row(0) = x.transpose();
  c.R.row(1) = y.transpose();
  c.R.row(2) = z.transpose();
  c.t = -c.R * centre;
  return c;
}

// A camera at distance D from `target`, turned by phi degrees about the y axis from looking
// along +z, looking at the target.
inline gs::Camera look_at(const std::string& name, const Eigen::Vector3d& target, double distance,
                          double phi_deg) {
  const double p = phi_deg * kDeg;
  const Eigen::Vector3d axis(-std::sin(p), 0, std::cos(p));
  return rig_camera(name, target - distance * axis, axis);
}

// 11^3 grid over [-0.5, 0.5]^3 around `centre`: symmetric under x -> -x about the centre, so
// every camera looking at the centre from distance D has median depth exactly D.
inline void add_cube(std::vector<Eigen::Vector3d>* pts, const Eigen::Vector3d& centre) {
  for (int i = 0; i <= 10; ++i)
    for (int j = 0; j <= 10; ++j)
      for (int k = 0; k <= 10; ++k)
        pts->push_back(centre + Eigen::Vector3d(i - 5, j - 5, k - 5) * 0.1);
}

const Eigen::Vector3d kA(0, 0, 0), kB(0, 100, 0);  // two objects, out of each other's cones

// The ten-camera rig. Depth order = list order; close set cA cB cC cD, far set fA fB fC fD, test
// pool cA cB cC, discarded cD m1 m2 fA, training pool fB fC fD. fC looks at object B, all others
// at object A (IoU 1 among A cameras, 0 with fC; angles are differences of phi).
//   pair     ratio  angle  IoU  verdict
//   cA-fA    2.05    0     1    angle
//   cA-fB    2.50   30     1    ACCEPT
//   cA-fC    3.00    0     0    angle, IoU
//   cA-fD    3.50   20     1    ACCEPT
//   cB-fA    1.95   12     1    ratio
//   cB-fB    2.38   42     1    ACCEPT
//   cB-fC    2.86   12     0    IoU
//   cB-fD    3.33    8     1    angle
//   cC-fA    1.86   45     1    ratio
//   cC-fB    2.27   15     1    ACCEPT
//   cC-fC    2.73   45     0    IoU
//   cC-fD    3.18   65     1    angle
//   cD-fA    1.32    0     1    ratio, angle
//   cD-fB    1.61   30     1    ratio
//   cD-fC    1.94    0     0    all three
//   cD-fD    2.26   20     1    ACCEPT
struct Rig {
  gs::CameraSet cameras;
  std::vector<Eigen::Vector3d> points;
  std::vector<double> distance;  // by camera index (= name order, see below)
};

inline Rig ten_camera_rig() {
  struct Spec {
    const char* name;
    double d, phi;
    bool object_b;
  };
  // Names sort in depth order, so camera index == depth rank.
  const Spec specs[] = {{"c0_cA", 2.0, 0, false},  {"c1_cB", 2.1, -12, false},
                        {"c2_cC", 2.2, 45, false}, {"c3_cD", 3.1, 0, false},
                        {"c4_m1", 3.5, 0, false},  {"c5_m2", 3.6, 15, false},
                        {"c6_fA", 4.1, 0, false},  {"c7_fB", 5.0, 30, false},
                        {"c8_fC", 6.0, 0, true},   {"c9_fD", 7.0, -20, false}};
  Rig rig;
  for (const Spec& s : specs) {
    rig.cameras.cameras.push_back(look_at(s.name, s.object_b ? kB : kA, s.d, s.phi));
    rig.distance.push_back(s.d);
  }
  add_cube(&rig.points, kA);
  add_cube(&rig.points, kB);
  return rig;
}

inline PairParams quiet_params() {
  PairParams p;
  p.progress = false;
  return p;
}

inline std::string pair_name(const gs::CameraSet& cams, const PairMeasure& m) {
  return cams.cameras[size_t(m.close)].name.substr(3) + "-" +
         cams.cameras[size_t(m.far)].name.substr(3);
}

inline std::vector<std::string> names(const gs::CameraSet& cams, const std::vector<int>& idx) {
  std::vector<std::string> out;
  for (int i : idx) out.push_back(cams.cameras[size_t(i)].name.substr(3));
  return out;
}

// Sorted copy, then numpy's linear percentile: an independent reference for the library's
// nth_element version.
inline double sorted_percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  const double pos = p / 100.0 * double(v.size() - 1);
  const size_t lo = size_t(pos);
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - double(lo)) * (v[hi] - v[lo]);
}

// Writes the ten-camera rig as a COLMAP text scene: sparse/0 (cameras, images, points3D), and
// optionally images/ (grey PNGs) and a small splat for `bench run`.
inline void write_rig_scene(const Rig& rig, const std::string& dir, bool with_images) {
  REQUIRE(gs::save_colmap_text(rig.cameras, dir + "/sparse/0").is_ok());
  gs::ColmapPoints pts;
  for (size_t i = 0; i < rig.points.size(); ++i) {
    pts.ids.push_back(int64_t(i) + 1);
    pts.xyz.push_back(rig.points[i]);
    pts.rgb.insert(pts.rgb.end(), {128, 128, 128});
    pts.error.push_back(0.5);
    pts.track_offsets.push_back(i);
    pts.track_image_ids.push_back(1);
    pts.track_point2d.push_back(uint32_t(i));
  }
  pts.track_offsets.push_back(rig.points.size());
  REQUIRE(gs::save_colmap_points_text(pts, dir + "/sparse/0/points3D.txt").is_ok());
  if (!with_images) return;
  std::filesystem::create_directories(dir + "/images");
  for (size_t i = 0; i < rig.cameras.cameras.size(); ++i) {
    gs::Image img(100, 100, 3);
    std::fill(img.data.begin(), img.data.end(), 0.1f + 0.05f * float(i));
    REQUIRE(gs::write_png(dir + "/images/" + rig.cameras.cameras[i].name, img).is_ok());
  }
  gs::RandomSceneParams rp;
  rp.count = 2000;
  rp.sh_degree = 0;
  REQUIRE(gs::save_scene(gs::random_scene(rp, gs::bench_camera(100, 100, 50.0)), dir + "/scene.ply")
              .is_ok());
}

}  // namespace macro::pair_test
