// Shared by the MACRO planning tests: a small synthetic three-plane scene and cameras with
// analytic answers (gs/synth/synth.h cast_pixel).
#pragma once

#include <Eigen/Geometry>
#include <cmath>

#include <utility>
#include <vector>

#include "attention/runtime/status.h"
#include "enhance/macro/depth_planes.h"
#include "enhance/macro/reference_selection.h"
#include "gs/raster/rasterizer.h"
#include "gs/synth/synth.h"

namespace macro::test {

inline gs::SynthScene three_plane_scene(int w = 320, int h = 180) {
  gs::SynthParams p;
  p.seed = 7;
  p.kind = gs::SynthKind::kPlanes;
  p.background = false;
  p.gaussians = 80'000;
  p.width = w;
  p.height = h;
  p.training_views = 6;
  p.closeup_views = 1;
  auto s = gs::generate_synthetic_scene(p);
  MACRO_CHECK(s.is_ok());
  return std::move(s).value();
}

// A camera at `eye` looking along +z, rotated by yaw (degrees, about y), same intrinsics rule as
// the generator.
inline gs::Camera axis_camera(const std::string& name, const Eigen::Vector3d& eye, double yaw_deg,
                              int w, int h, double focal_factor = 0.82) {
  gs::Camera c;
  c.name = name;
  c.width = w;
  c.height = h;
  c.fx = c.fy = focal_factor * w;
  c.cx = 0.5 * w;
  c.cy = 0.5 * h;
  const Eigen::Matrix3d r_c2w =
      Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  c.R = r_c2w.transpose();
  c.t = -c.R * eye;
  return c;
}

// Planes of the scene sorted far to near (bin order): bin -> plane index.
inline std::vector<int> planes_far_to_near(const gs::SynthGeometry& g, const gs::Camera& cam) {
  std::vector<int> idx;
  for (size_t k = 0; k < g.planes.size(); ++k) idx.push_back(int(k));
  std::sort(idx.begin(), idx.end(), [&](int a, int b) {
    return cam.project(g.planes[size_t(a)].center).z() >
           cam.project(g.planes[size_t(b)].center).z();
  });
  return idx;
}

// The three-plane scene seen by a 320x180 close-up on the axis and two references (the second
// with another size and focal), with the close-up's MACRO depth and its three planes.
struct ThreePlaneCloseup {
  gs::SynthScene scene = three_plane_scene();
  gs::Camera cu = axis_camera("closeup", {0.0, 0.0, 0.0}, 0, 320, 180);
  std::vector<gs::Camera> refs = {axis_camera("ref_a", {0.3, 0.1, -1.5}, 4, 320, 180),
                                  axis_camera("ref_b", {-0.5, -0.1, -2.5}, -6, 400, 300, 0.7)};
  enhance::DepthView cud;
  enhance::PlaneResult planes;
  ThreePlaneCloseup() {
    auto r = gs::render(scene.cloud, cu);
    MACRO_CHECK(r.is_ok());
    cud = {cu, enhance::macro_depth(*r)};
    auto p = enhance::compute_depth_planes(cud.depth, cu.width, cu.height, {3, false});
    MACRO_CHECK(p.is_ok());
    planes = std::move(p).value();
  }
};

}  // namespace macro::test
