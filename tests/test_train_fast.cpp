// The trainer's float path (gs/train/fast_render.h, train_kernels.h) against its double twin
// (diff_render.h, loss.h) on every ISA path the machine runs: forward max abs, loss value and
// gradients relative L2; the goldens (../shared/golden/train) through the float path; the same
// bits for 1, 2, 4 and 8 threads; the projection kernels against diff_project per Gaussian.
// Tolerances: forward and loss max abs 2e-3 against the goldens (README "train/"), 1e-4 against
// the twin (float rounding only); gradients relative L2 1e-3; Adam after 10 steps max abs 1e-4
// for >= 99% of each tensor.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>

#include "attention/runtime/io/safetensors.h"
#include "gs/cameras/camera.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/train/adam.h"
#include "gs/train/adam_kernels.h"
#include "gs/train/diff_project.h"
#include "gs/train/fast_render.h"
#include "gs/train/step_gradient.h"
#include "gs/train/train_memory.h"
#include "gs/train/trainer.h"
#include "test_support.h"
#include "tests/cli_run.h"

using namespace macro;
using namespace macro::gs;
using namespace macro::gs::train;

namespace {

// The ISA paths with a float table.
using IsaRestore = test::IsaGuard;
std::vector<Isa> float_isas() {
  std::vector<Isa> v;
  for (Isa isa : test::supported_isas())
    if (train_kernels_for(isa) != nullptr) v.push_back(isa);
  return v;
}

std::vector<std::pair<std::string, const std::vector<float>*>> grad_tensors(const SplatGrads& g) {
  return {{"means", &g.means},         {"scales", &g.scales}, {"quats", &g.quats},
          {"opacities", &g.opacities}, {"sh0", &g.sh0},       {"shN", &g.shN},
          {"means2d", &g.means2d}};
}
std::vector<float> to_float(const std::vector<double>& v) {
  return std::vector<float>(v.begin(), v.end());
}

// n Gaussians in front of a camera of w x h: many per tile (more than one 128-batch), some alpha
// clamped at 0.99, some large, raw quaternions of norm != 1.
struct Scene {
  SplatParams params;
  TrainView view;
};
Scene random_scene(uint32_t seed, size_t n, int degree, int w, int h) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> nd(0, 1);
  Scene s;
  Camera& cam = s.view.camera;
  cam.name = "random";
  cam.width = w;
  cam.height = h;
  cam.fx = cam.fy = 0.9 * w;
  cam.cx = 0.5 * w;
  cam.cy = 0.48 * h;
  cam.R = Eigen::Matrix3d::Identity();
  cam.t = Eigen::Vector3d(0, 0, 0);
  SplatParams& p = s.params;
  p.resize(n, degree);
  const size_t R = size_t(p.sh_rest());
  for (size_t i = 0; i < n; ++i) {
    const double z = 2 + 4 * u(rng);
    p.means[3 * i + 0] = float((u(rng) - 0.5) * 1.2 * z);
    p.means[3 * i + 1] = float((u(rng) - 0.5) * 0.8 * z);
    p.means[3 * i + 2] = float(z);
    const double log_s = (i % 11 == 0 ? -1.6 : -3.4) + 0.8 * u(rng);
    for (int a = 0; a < 3; ++a) p.scales[3 * i + a] = float(log_s + 0.4 * nd(rng));
    for (int a = 0; a < 4; ++a) p.quats[4 * i + a] = float(nd(rng) + (a == 0 ? 1.0 : 0.0));
    p.opacities[i] = float(i % 5 == 0 ? 6.0 : -1.5 + 3 * u(rng));
    for (int c = 0; c < 3; ++c) p.sh0[3 * i + c] = float(0.8 * nd(rng));
    for (size_t j = 0; j < R * 3; ++j) p.shN[i * R * 3 + j] = float(0.3 * nd(rng));
  }
  s.view.target.resize(size_t(w) * size_t(h) * 3);
  for (float& v : s.view.target) v = float(0.05 + 0.9 * u(rng));
  return s;
}

void check_against_twin(const SplatParams& params, const TrainView& view,
                        const DiffRenderOptions& options = {}) {
  auto ref = view_gradient(params, view, options, ThreadPool::global(), Precision::kDouble);
  REQUIRE(ref.is_ok());
  for (Isa isa : float_isas()) {
    IsaRestore restore;
    REQUIRE(set_isa(isa).is_ok());
    INFO("path " << isa_name(isa));
    auto got = view_gradient(params, view, options, ThreadPool::global(), Precision::kFloat);
    REQUIRE(got.is_ok());
    const auto color = test::compare(to_float(got->image.color), to_float(ref->image.color));
    const auto alpha = test::compare(to_float(got->image.alpha), to_float(ref->image.alpha));
    INFO("color max abs " << color.max_abs << ", alpha max abs " << alpha.max_abs);
    CHECK(color.max_abs <= 1e-4);
    CHECK(alpha.max_abs <= 1e-4);
    INFO("loss " << got->loss.loss << " vs " << ref->loss.loss);
    CHECK(std::abs(got->loss.loss - ref->loss.loss) <= 1e-5);
    CHECK(std::abs(got->loss.ssim - ref->loss.ssim) <= 1e-5);
    CHECK(std::abs(got->loss.l1 - ref->loss.l1) <= 1e-5);
    const auto want = grad_tensors(ref->grads);
    const auto have = grad_tensors(got->grads);
    for (size_t k = 0; k < want.size(); ++k) {
      const auto d = test::compare(*have[k].second, *want[k].second);
      INFO("grad." << want[k].first << ": rel L2 " << d.rel_l2 << ", max abs " << d.max_abs);
      CHECK(d.rel_l2 <= 1e-3);
    }
  }
}

}  // namespace

TEST_CASE("train fast: every float path matches the double twin on random scenes",
          "[train][train_fast]") {
  if (float_isas().empty()) WARN("no float path on this machine: only the double reference runs");
  for (int degree : {0, 3}) {
    INFO("SH degree " << degree);
    Scene s = random_scene(7 + uint32_t(degree), 2500, degree, 83, 61);
    check_against_twin(s.params, s.view);
    DiffRenderOptions grey;  // a background reaches the backward through T
    grey.background = {0.2, 0.4, 0.6};
    check_against_twin(s.params, s.view, grey);
    // The antialiased and mip modes (opacity compensation, 3D filter) on the float path too.
    DiffRenderOptions aa;
    aa.mode = RasterMode::kAntialiased;
    check_against_twin(s.params, s.view, aa);
    const std::vector<float> filter = compute_filter_3d(s.params, {s.view.camera});
    DiffRenderOptions mip;
    mip.mode = RasterMode::kMip;
    mip.filter_3d = &filter;
    check_against_twin(s.params, s.view, mip);
  }
}

TEST_CASE("train fast: the float path matches the goldens and the twin on the golden views",
          "[train][train_fast]") {
  const std::string dir = test::golden_dir() + "/train";
  auto params = read_splat_params(dir + "/init.ply");
  if (!params) {
    WARN("skipped: no golden train data at " << dir);
    return;
  }
  auto cams = load_cameras(dir + "/cameras.json");
  REQUIRE(cams.is_ok());
  auto exp = SafeTensors::open(dir + "/expected.safetensors");
  REQUIRE(exp.is_ok());
  auto golden = [&](const std::string& name) {
    INFO("golden tensor " << name);
    auto t = exp->read_f32(name);
    REQUIRE(t.is_ok());
    return *t;
  };
  for (const char* name : {"v0", "v1"}) {
    INFO("view " << name);
    auto cam = cams->find(name);
    REQUIRE(cam.is_ok());
    auto target = read_image(dir + "/images/" + name + ".png");
    REQUIRE(target.is_ok());
    const TrainView view{*cam, target->data};
    check_against_twin(*params, view);
    for (Isa isa : float_isas()) {
      IsaRestore restore;
      REQUIRE(set_isa(isa).is_ok());
      INFO("path " << isa_name(isa));
      auto got = view_gradient(*params, view, {}, ThreadPool::global(), Precision::kFloat);
      REQUIRE(got.is_ok());
      CHECK(
          test::compare(to_float(got->image.color), golden(std::string(name) + ".color")).max_abs <=
          2e-3);
      CHECK(std::abs(got->loss.loss - golden(std::string(name) + ".loss")[0]) <= 2e-3);
      for (const auto& [g, data] : grad_tensors(got->grads)) {
        const auto d = test::compare(*data, golden(std::string(name) + ".grad." + g));
        INFO("grad." << g << ": rel L2 " << d.rel_l2);
        CHECK(d.rel_l2 <= 1e-3);
      }
    }
  }
}

TEST_CASE("train fast: 1, 2, 4 and 8 threads give identical bits on every float path",
          "[train][train_fast]") {
  Scene s = random_scene(3, 4000, 3, 96, 72);
  for (Isa isa : float_isas()) {
    IsaRestore restore;
    REQUIRE(set_isa(isa).is_ok());
    INFO("path " << isa_name(isa));
    ThreadPool one(1);
    auto ref = view_gradient(s.params, s.view, {}, one, Precision::kFloat);
    REQUIRE(ref.is_ok());
    for (int threads : {2, 4, 8}) {
      INFO(threads << " threads");
      ThreadPool pool(threads);
      auto got = view_gradient(s.params, s.view, {}, pool, Precision::kFloat);
      REQUIRE(got.is_ok());
      CHECK(got->image.color == ref->image.color);
      CHECK(got->loss.loss == ref->loss.loss);
      const auto want = grad_tensors(ref->grads);
      const auto have = grad_tensors(got->grads);
      for (size_t k = 0; k < want.size(); ++k) {
        INFO("grad." << want[k].first);
        CHECK(*have[k].second == *want[k].second);
      }
    }
  }
}

TEST_CASE("train fast: every Adam path gives the scalar twin's bits", "[train][train_fast]") {
  std::mt19937 rng(5);
  std::normal_distribution<double> nd(0, 1);
  const size_t n = 1003;  // a tail after the last full vector
  std::vector<float> m(n), v(n);
  std::vector<float> g(n), p(n);
  for (size_t i = 0; i < n; ++i) {
    m[i] = float(1e-3 * nd(rng));
    v[i] = float(1e-6 * std::abs(nd(rng)));
    g[i] = float(1e-3 * nd(rng));
    p[i] = float(nd(rng));
  }
  const AdamCoefficients c{
      0.1f, 0.999f, 0.001f, float(1.6e-4 / 0.19), float(std::sqrt(1 - 0.999 * 0.999)), 1e-15f};
  std::vector<float> m0 = m, v0 = v;
  std::vector<float> p0 = p;
  adam_rows_scalar(m0.data(), v0.data(), g.data(), p0.data(), n, c);
  CHECK(p0 != p);
  for (Isa isa : test::supported_isas()) {
    INFO("path " << isa_name(isa));
    std::vector<float> m1 = m, v1 = v;
    std::vector<float> p1 = p;
    adam_rows_for(isa)(m1.data(), v1.data(), g.data(), p1.data(), n, c);
    CHECK(m1 == m0);
    CHECK(v1 == v0);
    CHECK(p1 == p0);
  }
}

TEST_CASE("train fast: --precision is validated by name, double runs the reference", "[train]") {
  test::TempDir tmp("train-precision");
  Scene s = random_scene(9, 200, 1, 40, 30);
  REQUIRE(write_splat_params(s.params, tmp.file("s.ply")).is_ok());
  CameraSet set;
  set.cameras.push_back(s.view.camera);
  REQUIRE(save_cameras_json(set, tmp.file("cameras.json")).is_ok());
  Image target(40, 30, 3);
  target.data = s.view.target;
  REQUIRE(write_png(tmp.file("t.png"), target).is_ok());
  const std::string common = "grad --scene " + tmp.file("s.ply") + " --cameras " +
                             tmp.file("cameras.json") + " --camera random --target " +
                             tmp.file("t.png") + " --out " + tmp.file("g.safetensors");
  const test::Run bad = test::run_macro(common + " --precision half", tmp);
  CHECK(bad.rc == 1);
  CHECK(bad.err.find("--precision: expected float or double, found 'half'") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(tmp.file("g.safetensors")));
  const test::Run train_bad = test::run_macro(
      "train --images " + tmp.path + " --cameras " + tmp.file("cameras.json") + " --init " +
          tmp.file("s.ply") + " --out " + tmp.file("o.ply") + " --steps 1 --precision fp16",
      tmp);
  CHECK(train_bad.rc == 1);
  CHECK(train_bad.err.find("--precision: expected float or double, found 'fp16'") !=
        std::string::npos);

  auto back = read_image(tmp.file("t.png"));
  REQUIRE(back.is_ok());
  s.view.target = back->data;
  auto want = view_gradient(s.params, s.view, {}, ThreadPool::global(), Precision::kDouble);
  REQUIRE(want.is_ok());
  REQUIRE(test::run_macro(common + " --precision double --quiet", tmp).rc == 0);
  auto got = SafeTensors::open(tmp.file("g.safetensors"));
  REQUIRE(got.is_ok());
  auto means = got->read_f32("grad.means");
  REQUIRE(means.is_ok());
  CHECK(*means == want->grads.means);
}

TEST_CASE("train fast: empty and fully culled scenes match the twin on every float path",
          "[train][train_fast]") {
  for (size_t n : {size_t(0), size_t(5)}) {
    INFO(n << " Gaussians");
    Scene s = random_scene(11, n, 2, 33, 21);
    for (size_t i = 0; i < n; ++i) s.params.means[3 * i + 2] = -1.f;  // behind the camera
    DiffRenderOptions opt;
    opt.background = {0.25, 0.5, 0.75};
    auto ref = view_gradient(s.params, s.view, opt, ThreadPool::global(), Precision::kDouble);
    REQUIRE(ref.is_ok());
    for (Isa isa : float_isas()) {
      IsaRestore restore;
      REQUIRE(set_isa(isa).is_ok());
      INFO("path " << isa_name(isa));
      auto got = view_gradient(s.params, s.view, opt, ThreadPool::global(), Precision::kFloat);
      REQUIRE(got.is_ok());
      CHECK(test::compare(to_float(got->image.color), to_float(ref->image.color)).max_abs <= 1e-6);
      CHECK(std::abs(got->loss.loss - ref->loss.loss) <= 1e-5);
      const auto want = grad_tensors(ref->grads);
      const auto have = grad_tensors(got->grads);
      for (size_t k = 0; k < want.size(); ++k) CHECK(*have[k].second == *want[k].second);
    }
  }
}

namespace {

// Gaussians around a rotated camera (off-centre principal point) with every culling case the
// projection has: behind the camera or before the near plane, a zero or non-finite quaternion, a
// non-finite mean, too faint, off the image, far beyond the Jacobian clamp limits, huge and tiny.
SplatParams projection_cases(uint32_t seed, size_t n, int degree, Camera* cam) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> nd(0, 1);
  cam->name = "projection";
  cam->width = 120;
  cam->height = 90;
  cam->fx = 110;
  cam->fy = 104;
  cam->cx = 57.5;
  cam->cy = 47.25;
  const double qn = std::sqrt(1 + 0.06 * 0.06 + 0.09 * 0.09 + 0.02 * 0.02);
  cam->R = rotation_from_quaternion_wxyz(1 / qn, 0.06 / qn, -0.09 / qn, 0.02 / qn);
  cam->t = Eigen::Vector3d(0.2, -0.1, 0.3);
  SplatParams p;
  p.resize(n, degree);
  const size_t R = size_t(p.sh_rest());
  for (size_t i = 0; i < n; ++i) {
    const double z = 0.5 + 6 * u(rng);
    Eigen::Vector3d xc((u(rng) - 0.5) * 2.2 * z, (u(rng) - 0.5) * 1.8 * z, z);
    if (i % 13 == 1) xc.z() = -xc.z();  // behind
    if (i % 13 == 2) xc.z() = 0.004;    // before the near plane
    const Eigen::Vector3d xw = cam->R.transpose() * (xc - cam->t);
    for (int a = 0; a < 3; ++a) p.means[i * 3 + a] = float(xw(a));
    const double log_s = (i % 17 == 3 ? -0.3 : i % 17 == 4 ? -7.0 : -3.0) + 0.8 * u(rng);
    for (int a = 0; a < 3; ++a) p.scales[i * 3 + a] = float(log_s + 0.5 * nd(rng));
    for (int a = 0; a < 4; ++a) p.quats[i * 4 + a] = float(nd(rng) + (a == 0 ? 0.8 : 0.0));
    if (i % 19 == 5) std::fill_n(&p.quats[i * 4], 4, 0.f);
    if (i % 23 == 6) p.quats[i * 4 + 2] = std::numeric_limits<float>::quiet_NaN();
    if (i % 29 == 7) p.means[i * 3] = std::numeric_limits<float>::infinity();
    p.opacities[i] = float(i % 11 == 8 ? -9.0 : -2 + 6 * u(rng));
    for (int c = 0; c < 3; ++c) p.sh0[i * 3 + c] = float(0.9 * nd(rng));
    for (size_t j = 0; j < R * 3; ++j) p.shN[i * R * 3 + j] = float(0.3 * nd(rng));
  }
  return p;
}

double rel(double got, double want, double floor) {
  return std::abs(got - want) / std::max(std::abs(want), floor);
}

}  // namespace

TEST_CASE("train fast: the projection kernels match diff_project per Gaussian on every float path",
          "[train][train_fast]") {
  for (RasterMode mode : {RasterMode::kClassic, RasterMode::kAntialiased, RasterMode::kMip}) {
    for (int degree : {0, 1, 2, 3}) {
      INFO("mode " << int(mode) << ", SH degree " << degree);
      Camera camera;
      const size_t n = 16 * 40 + 7;  // a tail call of 7
      const SplatParams p = projection_cases(40 + uint32_t(degree), n, degree, &camera);
      const std::vector<float> filter = compute_filter_3d(p, {camera});
      DiffRenderOptions o;
      o.mode = mode;
      if (mode == RasterMode::kMip) o.filter_3d = &filter;
      auto ps = project_settings(p, o);
      REQUIRE(ps.is_ok());
      const CameraD cam = make_camera_d(camera);
      const ProjectInput in = project_input(p, cam, *ps);
      // The twin, and its backward from seeded upstream gradients.
      std::mt19937 rng(7);
      std::normal_distribution<double> nd(0, 1);
      std::vector<double> sums(n * kPairGrad);
      for (double& v : sums) v = nd(rng);
      std::vector<uint8_t> has_pairs(n), want_visible(n);
      std::vector<ProjectedD> want(n);
      const size_t R3 = size_t(p.sh_rest()) * 3;
      SplatGrads want_g;
      want_g.means.assign(n * 3, 0.f);
      want_g.scales.assign(n * 3, 0.f);
      want_g.quats.assign(n * 4, 0.f);
      want_g.opacities.assign(n, 0.f);
      want_g.sh0.assign(n * 3, 0.f);
      want_g.shN.assign(n * R3, 0.f);
      size_t visible = 0;
      for (size_t g = 0; g < n; ++g) {
        want_visible[g] = project_forward(p, g, cam, *ps, &want[g]);
        visible += want_visible[g];
        has_pairs[g] = want_visible[g] && g % 7 != 3;  // only a visible Gaussian has pairs
        if (!has_pairs[g]) continue;
        ProjectedGrad up;
        const double* s = &sums[g * kPairGrad];
        for (int c = 0; c < 3; ++c) up.rgb[c] = s[c], up.conic[c] = s[3 + c];
        up.xy[0] = s[6], up.xy[1] = s[7], up.opacity = s[8];
        project_backward(p, g, cam, *ps, up,
                         {&want_g.means[3 * g], &want_g.scales[3 * g], &want_g.quats[4 * g],
                          &want_g.opacities[g], &want_g.sh0[3 * g], want_g.shN.data() + g * R3});
      }
      CHECK(visible > n / 5);
      CHECK(visible < n - n / 10);
      for (Isa isa : float_isas()) {
        INFO("path " << isa_name(isa));
        const TrainKernels& k = *train_kernels_for(isa);
        std::vector<raster::TileSplat> got(n);
        std::vector<uint8_t> got_visible(n);
        SplatGrads g;
        g.means.assign(n * 3, 9.f);  // every row must be written
        g.scales.assign(n * 3, 9.f);
        g.quats.assign(n * 4, 9.f);
        g.opacities.assign(n, 9.f);
        g.sh0.assign(n * 3, 9.f);
        g.shN.assign(n * R3, 9.f);
        const ProjectGradOut out{g.means.data(),     g.scales.data(), g.quats.data(),
                                 g.opacities.data(), g.sh0.data(),    g.shN.data()};
        for (size_t g0 = 0; g0 < n; g0 += 16) {
          const int cnt = int(std::min<size_t>(16, n - g0));
          k.project_forward(in, g0, cnt, &got[g0], &got_visible[g0]);
          k.project_backward(in, g0, cnt, &sums[g0 * kPairGrad], kPairGrad, &has_pairs[g0], out);
        }
        size_t differ = 0;
        double worst = 0;
        for (size_t i = 0; i < n; ++i) {
          if (got_visible[i] != want_visible[i]) {
            ++differ;
            continue;
          }
          if (!want_visible[i]) continue;
          const raster::TileSplat& t = got[i];
          const ProjectedD& w = want[i];
          uint32_t id;
          std::memcpy(&id, &t.inv_z, sizeof id);
          CHECK(id == i);
          const double ext = std::max(w.ext_x, w.ext_y);
          const double e[] = {rel(t.x, w.x, ext),
                              rel(t.y, w.y, ext),
                              rel(t.a, w.a, std::max(std::abs(w.a), std::abs(w.c))),
                              rel(t.b, w.b, std::max(std::abs(w.a), std::abs(w.c))),
                              rel(t.c, w.c, std::max(std::abs(w.a), std::abs(w.c))),
                              rel(t.opacity, w.opacity, 1e-3),
                              rel(t.r, w.rgb[0], 1e-2),
                              rel(t.g, w.rgb[1], 1e-2),
                              rel(t.bl, w.rgb[2], 1e-2),
                              rel(t.z, w.depth, 1e-3),
                              rel(t.ext_x, w.ext_x, 1e-3),
                              rel(t.ext_y, w.ext_y, 1e-3),
                              rel(t.row_k, w.cover.row_k, 1.0),
                              rel(t.row_a0, w.cover.row_a0, w.cover.row_a0),
                              rel(t.row_a1, w.cover.row_a1, w.cover.row_a1)};
          for (double x : e) worst = std::max(worst, x);
        }
        INFO("forward: " << differ << " visibility differences, worst relative error " << worst);
        CHECK(differ == 0);
        CHECK(worst <= 5e-5);
        // The backward: every row written; rows relative L2 against the twin's.
        const auto have = grad_tensors(g), wantt = grad_tensors(want_g);
        for (size_t t = 0; t < 6; ++t) {
          const std::vector<float>& a = *have[t].second;
          const std::vector<float>& b = *wantt[t].second;
          REQUIRE(a.size() == b.size());
          const size_t w = n == 0 ? 0 : a.size() / n;
          double worst_row = 0;
          for (size_t i = 0; i < n; ++i) {
            double d2 = 0, n2 = 0;
            for (size_t j = 0; j < w; ++j) {
              const double d = double(a[i * w + j]) - double(b[i * w + j]);
              d2 += d * d;
              n2 += double(b[i * w + j]) * b[i * w + j];
            }
            if (n2 == 0) {
              CHECK(d2 == 0);  // zero rows stay exactly zero (culled, no pairs)
              continue;
            }
            worst_row = std::max(worst_row, std::sqrt(d2 / n2));
          }
          INFO("grad." << have[t].first << ": worst row relative L2 " << worst_row);
          CHECK(worst_row <= 2e-4);
        }
      }
    }
  }
}

TEST_CASE("train fast: the memory statement counts the arrays training holds", "[train]") {
  for (int degree : {0, 3}) {
    INFO("SH degree " << degree);
    Scene s = random_scene(3, 500, degree, 64, 48);
    SplatGrads g;
    StepGradient sg(Precision::kFloat);
    REQUIRE(sg.compute(s.params, s.view.camera, s.view.target.data(), {}, &g).is_ok());
    SplatAdam adam(s.params, AdamOptions{});
    const TrainMemory m = train_memory(s.params.size(), degree, 64 * 48, 2 * 64 * 48);
    auto bytes = [](std::initializer_list<const std::vector<float>*> v) {
      size_t b = 0;
      for (const auto* x : v) b += x->size() * sizeof(float);
      return b;
    };
    const SplatParams& p = s.params;
    CHECK(m.parameters == bytes({&p.means, &p.scales, &p.quats, &p.opacities, &p.sh0, &p.shN}));
    CHECK(m.gradients ==
          bytes({&g.means, &g.scales, &g.quats, &g.opacities, &g.sh0, &g.shN, &g.means2d}));
    size_t moments = 0;
    for (const SplatAdam::GroupState& st : adam.state())
      moments += (st.m->size() + st.v->size()) * sizeof(float);
    CHECK(m.adam == moments);
    CHECK(m.photos == 2 * 64 * 48 * 3 * sizeof(float));
    CHECK(m.fixed() == 500 * m.per_gaussian + 64 * 48 * m.per_pixel + m.photos);
    const std::string line = describe(m);
    CHECK(line.find("500 Gaussians x " + std::to_string(m.per_gaussian) + " B") == 0);
  }
}
