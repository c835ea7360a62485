// A tiny COLMAP scene folder for the trainer's tests (test_train_strategy.cpp,
// test_train_report.cpp): images/, sparse/0 (cameras, images, points3D as text).
#pragma once

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include "gs/cameras/camera.h"
#include "gs/cameras/colmap_points.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/synth/synth_random.h"
#include "gs/train/diff_render.h"

namespace macro::test {

// A tiny COLMAP scene: 40 coloured Gaussians in a box, 9 cameras 48 x 36 on an arc looking at
// it, the photos their renders, points3D the Gaussians' centres (jittered) and colours.
inline void write_tiny_scene(const std::string& dir, gs::SplatParams* truth) {
  namespace fs = std::filesystem;
  fs::create_directories(dir + "/images");
  fs::create_directories(dir + "/sparse/0");
  gs::synth_random::Rng rng{11};
  gs::SplatParams& p = *truth;
  p.resize(40, 0);
  for (size_t i = 0; i < 40; ++i) {
    for (int a = 0; a < 3; ++a) p.means[3 * i + a] = float(rng.range(-0.6, 0.6));
    for (int a = 0; a < 3; ++a) p.scales[3 * i + a] = float(std::log(rng.range(0.08, 0.2)));
    p.quats[4 * i] = 1.f;
    p.opacities[i] = 1.5f;
    for (int c = 0; c < 3; ++c) p.sh0[3 * i + c] = float(rng.range(-1.5, 1.5));
  }
  gs::CameraSet set;
  for (int k = 0; k < 9; ++k) {
    gs::Camera cam;
    cam.name = "v";  // (not "v" + to_string: GCC 12 warns -Wrestrict on it)
    cam.name += std::to_string(k) + ".png";
    cam.file_path = cam.name;
    cam.width = 48;
    cam.height = 36;
    cam.fx = cam.fy = 45;
    cam.cx = 24;
    cam.cy = 18;
    const double ang = -0.6 + 0.15 * k;
    const Eigen::Vector3d c(3 * std::sin(ang), 0.2, -3 * std::cos(ang));
    const Eigen::Vector3d fwd = (-c).normalized();
    const Eigen::Vector3d right = Eigen::Vector3d(0, 1, 0).cross(fwd).normalized();
    const Eigen::Vector3d down = fwd.cross(right);
    cam.R.row(0) = right;
    cam.R.row(1) = down;
    cam.R.row(2) = fwd;
    cam.t = -cam.R * c;
    set.cameras.push_back(cam);
    gs::train::DiffRenderer r;
    gs::train::DiffImage img;
    REQUIRE(r.forward(p, cam, {}, &img).is_ok());
    gs::Image png(48, 36, 3);
    for (size_t j = 0; j < png.data.size(); ++j)
      png.data[j] = float(std::clamp(img.color[j], 0.0, 1.0));
    REQUIRE(write_png(dir + "/images/" + cam.name, png).is_ok());
  }
  REQUIRE(save_colmap_text(set, dir + "/sparse/0").is_ok());
  gs::ColmapPoints pts;
  for (size_t i = 0; i < 40; ++i) {
    pts.ids.push_back(int64_t(i + 1));
    pts.xyz.emplace_back(p.means[3 * i] + rng.range(-0.05, 0.05),
                         p.means[3 * i + 1] + rng.range(-0.05, 0.05),
                         p.means[3 * i + 2] + rng.range(-0.05, 0.05));
    for (int c = 0; c < 3; ++c)
      pts.rgb.push_back(uint8_t(
          std::clamp(std::lround(255 * (0.5 + 0.28209479177387814 * p.sh0[3 * i + c])), 0L, 255L)));
    pts.error.push_back(0.5);
    pts.track_offsets.push_back(0);
  }
  pts.track_offsets.push_back(0);
  REQUIRE(save_colmap_points_text(pts, dir + "/sparse/0/points3D.txt").is_ok());
}

}  // namespace macro::test
