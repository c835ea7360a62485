// The trainer's antialiased and mip modes (docs/training.md §2.2, §2.3): the forward against
// gs::render in the same mode (mip: the 3D filter folded into scale and opacity as the scene
// loader folds a filter_3D property), central differences of the loss for every parameter kind,
// the 2D-mean gradient through the principal point, and Mip-Splatting's 3D filter on hand-placed
// means.
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include "gs/cameras/camera.h"
#include "gs/formats/scene_io.h"
#include "gs/formats/splat_params.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/diff_project.h"
#include "gs/train/diff_render.h"
#include "gs/train/loss.h"
#include "gs/train/step_gradient.h"
#include "gs/train/train_kernels.h"
#include "gs/train/trainer.h"
#include "test_support.h"
#include "tests/cli_run.h"
#include "train_fd.h"

using namespace macro;
using namespace macro::gs;
using namespace macro::gs::train;

namespace {

struct ModeCase {
  SplatParams params;
  TrainView view;
  std::vector<float> filter;  // mip: the 3D filter of the view's camera
};

// Random Gaussians in front of a rotated camera (off-centre principal point), all inside the
// Jacobian clamp limits, some peaking above the 0.99 clamp; raw quaternions of norm != 1.
ModeCase mode_case(uint32_t seed, size_t n, int degree, int width, int height) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> nd(0, 1);
  ModeCase mc;
  Camera& cam = mc.view.camera;
  cam.name = "modes";
  cam.width = width;
  cam.height = height;
  cam.fx = 0.9 * width;
  cam.fy = 0.95 * width;
  cam.cx = 0.47 * width;
  cam.cy = 0.53 * height;
  const double qn = std::sqrt(1 + 0.05 * 0.05 + 0.08 * 0.08 + 0.03 * 0.03);
  cam.R = rotation_from_quaternion_wxyz(1 / qn, 0.05 / qn, -0.08 / qn, 0.03 / qn);
  cam.t = Eigen::Vector3d(0.1, -0.05, 0.2);
  SplatParams& p = mc.params;
  p.resize(n, degree);
  const size_t R = size_t(p.sh_rest());
  for (size_t i = 0; i < n; ++i) {
    const double z = 2 + 3 * u(rng);
    const Eigen::Vector3d xc((u(rng) - 0.5) * 0.9 * z, (u(rng) - 0.5) * 0.8 * z, z);
    const Eigen::Vector3d xw = cam.R.transpose() * (xc - cam.t);
    const double log_s = -3.4 + 1.3 * u(rng);
    for (int a = 0; a < 3; ++a) p.means[i * 3 + a] = float(xw(a));
    for (int a = 0; a < 3; ++a) p.scales[i * 3 + a] = float(log_s + 0.4 * nd(rng));
    for (int a = 0; a < 4; ++a) p.quats[i * 4 + a] = float(nd(rng) + (a == 0 ? 1.0 : 0.0));
    p.opacities[i] = float(i % 5 == 0 ? 7.0 : -1 + 4 * u(rng));
    for (int c = 0; c < 3; ++c) p.sh0[i * 3 + c] = float(0.8 * nd(rng));
    for (size_t j = 0; j < R * 3; ++j) p.shN[i * R * 3 + j] = float(0.3 * nd(rng));
  }
  mc.view.target.resize(size_t(width) * size_t(height) * 3);
  for (float& v : mc.view.target) v = float(0.05 + 0.9 * u(rng));
  mc.filter = compute_filter_3d(p, {cam});
  return mc;
}

DiffRenderOptions options_for(RasterMode mode, const ModeCase& mc) {
  DiffRenderOptions o;
  o.mode = mode;
  if (mode == RasterMode::kMip) o.filter_3d = &mc.filter;
  return o;
}

double loss_at(const SplatParams& p, const Camera& cam, const ModeCase& mc, RasterMode mode,
               ThreadPool& pool) {
  DiffRenderer r;
  DiffImage img;
  REQUIRE(r.forward(p, cam, options_for(mode, mc), &img, pool).is_ok());
  auto l = photometric_loss(img.color.data(), mc.view.target.data(), img.width, img.height, nullptr,
                            pool);
  REQUIRE(l.is_ok());
  return l->loss;
}

const char* mode_name(RasterMode m) {
  return m == RasterMode::kAntialiased ? "antialiased" : m == RasterMode::kMip ? "mip" : "classic";
}

// The rasterizer's input for the same scene: the 3D filter folded into scale and opacity as
// gs/formats/format_ply.cpp folds a filter_3D property.
GaussianCloud cloud_for(const ModeCase& mc, RasterMode mode) {
  GaussianCloud c = to_cloud(mc.params);
  if (mode != RasterMode::kMip) return c;
  for (size_t g = 0; g < c.size(); ++g) {
    const double f2 = double(mc.filter[g]) * mc.filter[g];
    double ratio = 1;
    for (int a = 0; a < 3; ++a) {
      const double s2 = double(c.scale[g * 3 + a]) * c.scale[g * 3 + a];
      ratio *= s2 / (s2 + f2);
      c.scale[g * 3 + a] = float(std::sqrt(s2 + f2));
    }
    c.opacity[g] = float(c.opacity[g] * std::sqrt(ratio));
  }
  return c;
}

}  // namespace

TEST_CASE("train modes: the forward is gs::render's in the same mode", "[train]") {
  ThreadPool pool(2);
  for (RasterMode mode : {RasterMode::kAntialiased, RasterMode::kMip}) {
    INFO(mode_name(mode));
    ModeCase mc = mode_case(21, 3000, 2, 96, 72);
    RenderOptions ro;
    ro.mode = mode;
    auto ref = render(cloud_for(mc, mode), mc.view.camera, ro);
    REQUIRE(ref.is_ok());
    DiffRenderer r;
    DiffImage img;
    REQUIRE(r.forward(mc.params, mc.view.camera, options_for(mode, mc), &img, pool).is_ok());
    CHECK(r.stats().visible > 1500);
    const std::vector<float> color(img.color.begin(), img.color.end());
    const std::vector<float> alpha(img.alpha.begin(), img.alpha.end());
    const auto dc = test::compare(color, ref->color), da = test::compare(alpha, ref->alpha);
    INFO("color max abs " << dc.max_abs << ", alpha max abs " << da.max_abs);
    CHECK(dc.max_abs <= 1e-4);
    CHECK(da.max_abs <= 1e-4);
    // The mode matters: classic differs by far more.
    DiffImage classic;
    REQUIRE(r.forward(mc.params, mc.view.camera, {}, &classic, pool).is_ok());
    const std::vector<float> cc(classic.color.begin(), classic.color.end());
    CHECK(test::compare(cc, ref->color).max_abs > 1e-2);
  }
}

TEST_CASE("train modes: gradients agree with central differences for every parameter kind",
          "[train]") {
  ThreadPool pool(1);
  // The double reference and every float table, against central differences of the double loss.
  const auto paths = test::train_gradient_paths();
  int means2d_skipped = 0;
  for (RasterMode mode : {RasterMode::kAntialiased, RasterMode::kMip}) {
    for (int degree : {3, 0}) {
      INFO(mode_name(mode) << ", SH degree " << degree);
      ModeCase mc = mode_case(31 + uint32_t(degree), 14, degree, 32, 24);
      const std::vector<test::ParamKind> kinds = test::param_kinds(degree);
      std::vector<std::vector<std::array<double, 2>>> est;
      const auto loss = [&](const SplatParams& p) {
        return loss_at(p, mc.view.camera, mc, mode, pool);
      };
      for (const test::ParamKind& k : kinds)
        est.push_back(test::fd_estimates(mc.params, k.field, loss));

      // means2d: moving the principal point by h moves every projected mean by h (no Gaussian
      // here is beyond the clamp limits, which also move with cx, cy), so dL/dcx = sum of the u
      // components and dL/dcy of the v components.
      double est2d[2][2];
      for (int axis = 0; axis < 2; ++axis)
        for (int k = 0; k < 2; ++k) {
          const double h = k == 0 ? 1e-4 : 2.5e-5;
          Camera cp = mc.view.camera, cm = mc.view.camera;
          (axis == 0 ? cp.cx : cp.cy) += h;
          (axis == 0 ? cm.cx : cm.cy) -= h;
          est2d[axis][k] =
              (loss_at(mc.params, cp, mc, mode, pool) - loss_at(mc.params, cm, mc, mode, pool)) /
              (2 * h);
        }

      for (const auto& [path, isa] : paths) {
        INFO("path " << path);
        test::IsaGuard restore;
        REQUIRE(set_isa(isa).is_ok());
        const Precision precision = isa == Isa::kScalar ? Precision::kDouble : Precision::kFloat;
        StepGradient sg(precision);
        SplatGrads g;
        REQUIRE(sg.compute(mc.params, mc.view.camera, mc.view.target.data(), options_for(mode, mc),
                           &g, pool)
                    .is_ok());
        if (isa != Isa::kScalar) REQUIRE(std::string(sg.path_name()) == path);
        double worst = 0;
        for (size_t k = 0; k < kinds.size(); ++k)
          worst = std::max(worst, test::check_fd(g.*(kinds[k].grad), est[k], kinds[k].name));
        double su = 0, sv = 0;
        for (size_t i = 0; i < g.size(); ++i) su += g.means2d[2 * i], sv += g.means2d[2 * i + 1];
        for (int axis = 0; axis < 2; ++axis) {
          const double an = axis == 0 ? su : sv, fd = est2d[axis][1];
          INFO("means2d axis " << axis << ": sum " << an << ", central difference " << fd << " ("
                               << est2d[axis][0] << " at 4x the step)");
          // Moving every Gaussian at once can cross a pixel's 1/255 or T-stop discontinuity:
          // then the two step sizes disagree and the axis is skipped (at most 2 of the 8).
          if (std::abs(est2d[axis][0] - fd) > 2e-3 * std::max(std::abs(fd), 1e-6)) {
            if (isa == Isa::kScalar) ++means2d_skipped;
            continue;
          }
          const double err = std::abs(fd - an) / std::max({std::abs(fd), std::abs(an), 1e-6});
          CHECK(err <= 5e-3);
          worst = std::max(worst, err);
        }
        WARN(path << " " << mode_name(mode) << " degree " << degree << ": worst relative error "
                  << worst);
      }
    }
  }
  CHECK(means2d_skipped <= 2);
}

TEST_CASE("train modes: the 3D filter is Mip-Splatting's compute_3D_filter", "[train]") {
  // Two cameras at the origin looking down +z (fx 100 and 50), 64 x 48, cx = 32, cy = 24.
  std::vector<Camera> cams(2);
  for (int k = 0; k < 2; ++k) {
    cams[k].name = "c" + std::to_string(k);
    cams[k].width = 64;
    cams[k].height = 48;
    cams[k].fx = cams[k].fy = k == 0 ? 100 : 50;
    cams[k].cx = 32;
    cams[k].cy = 24;
    cams[k].R = Eigen::Matrix3d::Identity();
    cams[k].t = Eigen::Vector3d(0, 0, k == 0 ? 0 : 1);  // camera 1 one unit further back
  }
  SplatParams p;
  p.resize(5, 0);
  const float means[5][3] = {
      {0, 0, 2},      // seen by both: depth 2 (camera 0) and 3 -> 2
      {0.3f, 0, 1},   // camera 0: x = 62 inside; camera 1: depth 2, x = 39.5 -> 1
      {0.45f, 0, 1},  // camera 0: x = 77 > 1.15 W = 73.6, out; camera 1: x = 43.25 -> 2
      {0, 0, 0.1f},   // camera 0: depth 0.1 <= 0.2; camera 1: depth 1.1 -> 1.1
      {0, 0, -5},     // behind both: the largest depth of those seen, 2
  };
  for (int i = 0; i < 5; ++i)
    for (int a = 0; a < 3; ++a) p.means[i * 3 + a] = means[i][a];
  for (int i = 0; i < 5; ++i) p.quats[i * 4] = 1;
  const std::vector<float> f = compute_filter_3d(p, cams);
  const double k = std::sqrt(0.2) / 100;  // the largest focal
  const double depth[5] = {2, 1, 2, 1.1, 2};
  for (int i = 0; i < 5; ++i) {
    INFO("Gaussian " << i);
    CHECK(f[size_t(i)] == Approx(depth[i] * k).epsilon(1e-6));
  }
}

TEST_CASE("train modes: a mip-mode run writes filter_3D, which loaders fold and --init accepts",
          "[train]") {
  const std::string g = test::golden_dir() + "/train";
  if (!std::filesystem::is_regular_file(g + "/init.ply")) {
    WARN("skipped: no golden train data at " << g);
    return;
  }
  test::TempDir tmp("train-mip-ply");
  const std::string base =
      "train --images " + g + "/images --cameras " + g +
      "/cameras.json --steps 3 --strategy none --lr-schedule constant"
      " --view-order sequential --sh-degree-interval 0 --scene-scale 1 --quiet";
  REQUIRE(test::run_macro(
              base + " --init " + g + "/init.ply --mode mip --out " + tmp.file("mip.ply"), tmp)
              .rc == 0);
  // The filter is the trained Gaussians' 3D filter from the training cameras.
  std::vector<float> filter;
  auto p = read_splat_params(tmp.file("mip.ply"), {}, &filter);
  REQUIRE(p.is_ok());
  auto cams = load_cameras(g + "/cameras.json");
  REQUIRE(cams.is_ok());
  CHECK(filter == compute_filter_3d(*p, cams->cameras));
  CHECK(filter.size() == p->size());
  // Without a place for the filter the file is refused by name; a classic run writes none.
  auto refused = read_splat_params(tmp.file("mip.ply"));
  REQUIRE_FALSE(refused.is_ok());
  CHECK(refused.status().message().find("filter_3D") != std::string::npos);
  REQUIRE(test::run_macro(base + " --init " + g + "/init.ply --out " + tmp.file("classic.ply"), tmp)
              .rc == 0);
  std::vector<float> none = {1.f};
  REQUIRE(read_splat_params(tmp.file("classic.ply"), {}, &none).is_ok());
  CHECK(none.empty());
  // The scene loader folds it: scales grow to sqrt(s^2 + f^2).
  auto cloud = load_scene(tmp.file("mip.ply"));
  REQUIRE(cloud.is_ok());
  const GaussianCloud raw = to_cloud(*p);
  for (size_t i = 0; i < p->size(); ++i)
    CHECK(cloud->scale[3 * i] ==
          Approx(std::sqrt(raw.scale[3 * i] * raw.scale[3 * i] + filter[i] * filter[i]))
              .epsilon(1e-5));
  // Fine-tuning from it: accepted in mip mode, refused (naming the property) otherwise.
  CHECK(test::run_macro(
            base + " --init " + tmp.file("mip.ply") + " --mode mip --out " + tmp.file("again.ply"),
            tmp)
            .rc == 0);
  const auto bad =
      test::run_macro(base + " --init " + tmp.file("mip.ply") + " --out " + tmp.file("x.ply"), tmp);
  CHECK(bad.rc == 1);
  CHECK(bad.err.find("filter_3D") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(tmp.file("x.ply")));
}
