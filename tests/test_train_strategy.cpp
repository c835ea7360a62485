// gs/train's schedules and gsplat's DefaultStrategy (docs/training.md §2.5, §2.7): which
// Gaussians duplicate, split and prune on hand-made clouds with known accumulated gradients, the
// split children's positions for known samples, the opacity reset, the Adam moments of new and
// kept rows, the learning-rate and SH-degree schedules and the per-epoch view order.
#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "gs/cameras/camera.h"
#include "gs/cameras/colmap_points.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/synth/synth_random.h"
#include "gs/train/adam.h"
#include "gs/train/scene_inputs.h"
#include "gs/train/schedule.h"
#include "gs/train/strategy_default.h"
#include "gs/train/trainer.h"
#include "test_support.h"
#include "train_scene_fixture.h"

using namespace macro;
using namespace macro::gs;
using namespace macro::gs::train;

namespace {

// n Gaussians with row-tagged values: mean (i, 0, 5), log scale log(0.001) (small), identity
// quaternion, opacity logit 0 (0.5), sh0 (i, i, i).
SplatParams tagged_cloud(size_t n, int degree = 0) {
  SplatParams p;
  p.resize(n, degree);
  for (size_t i = 0; i < n; ++i) {
    p.means[3 * i] = float(i);
    p.means[3 * i + 2] = 5.f;
    for (int a = 0; a < 3; ++a) p.scales[3 * i + a] = float(std::log(0.001));
    p.quats[4 * i] = 1.f;
    for (int c = 0; c < 3; ++c) p.sh0[3 * i + c] = float(i);
  }
  return p;
}

// An Adam whose moments are non-zero everywhere (one step on gradients 1 + row).
SplatAdam stepped_adam(SplatParams* p) {
  SplatAdam adam(*p, AdamOptions{});
  SplatGrads g;
  g.resize(p->size(), p->sh_degree);
  auto fill = [](std::vector<float>& v, size_t width) {
    for (size_t i = 0; i < v.size(); ++i) v[i] = float(1 + i / width);
  };
  fill(g.means, 3);
  fill(g.scales, 3);
  fill(g.quats, 4);
  fill(g.opacities, 1);
  fill(g.sh0, 3);
  fill(g.shN, size_t(std::max(1, p->sh_rest() * 3)));
  adam.step(g, p);
  return adam;
}

// The first moment of group `name`, row r (width values).
std::vector<float> moment_row(const SplatAdam& adam, const std::string& name, size_t r,
                              size_t width) {
  const std::vector<float>& m = *adam.exp_avg(name);
  return std::vector<float>(m.begin() + r * width, m.begin() + (r + 1) * width);
}

}  // namespace

TEST_CASE("train strategy: duplicate, split and prune pick gsplat's Gaussians", "[train]") {
  // scene_scale 1: small <=> max scale <= 0.01; prune_scale3d 0.1.
  SplatParams p = tagged_cloud(6);
  // Row 1 and 4 large (0.05), row 5 too big (0.5); row 3 transparent (sigmoid(-6) < 0.005).
  for (int a = 0; a < 3; ++a) {
    p.scales[3 * 1 + a] = float(std::log(0.05));
    p.scales[3 * 4 + a] = float(std::log(0.05));
    p.scales[3 * 5 + a] = float(std::log(0.5));
  }
  p.opacities[3] = -6.f;
  DefaultStrategyState st;
  // avg = grad2d / max(count, 1): rows 0, 1 high (3e-4), row 2 exactly at 2e-4 (not high), row 4
  // high only because count 0 counts as 1, row 5 low.
  st.grad2d = {6e-4, 9e-4, 4e-4, 1.0, 3e-4, 0.0};
  st.count = {2, 3, 2, 1, 0, 1};
  DefaultStrategyOptions o;
  NormalRng rng(1);
  auto grown = grow_gaussians(o, 1.0, rng, &p, nullptr, &st);
  REQUIRE(grown.is_ok());
  // Row 3 is high too (1.0) and small: duplicated, as gsplat (pruning comes after growth).
  CHECK(grown->first == 2);   // rows 0, 3
  CHECK(grown->second == 2);  // rows 1, 4
  // Kept rows 0 2 3 5, the copies of 0 and 3, then children 0 of (1, 4), children 1 of (1, 4).
  REQUIRE(p.size() == 6 + 2 + 2);
  const std::vector<float> expect_sh0 = {0, 2, 3, 5, 0, 3, 1, 4, 1, 4};
  for (size_t i = 0; i < p.size(); ++i) {
    INFO("row " << i);
    CHECK(p.sh0[3 * i] == expect_sh0[i]);
  }
  // The state follows the rows.
  CHECK(st.grad2d.size() == p.size());
  CHECK(st.count[4] == 2);  // copy of row 0
  // Copies are exact; children have scale / 1.6.
  CHECK(p.means[3 * 4] == 0.f);
  CHECK(p.scales[3 * 4] == float(std::log(0.001)));
  CHECK(std::abs(std::exp(double(p.scales[3 * 6])) - 0.05 / 1.6) < 1e-8);

  // Prune at step 600 (<= reset_every): only the transparent rows (3 and its copy).
  const SplatParams grown_p = p;
  DefaultStrategyState st2 = st;
  CHECK(prune_gaussians(o, 600, 1.0, &p, nullptr, &st2) == 2);
  REQUIRE(p.size() == 8);
  const std::vector<float> after_prune = {0, 2, 5, 0, 1, 4, 1, 4};
  for (size_t i = 0; i < p.size(); ++i) CHECK(p.sh0[3 * i] == after_prune[i]);
  // After the first reset (step > 3000) also the too big row 5 (0.5 > 0.1); the children
  // (0.05 / 1.6) stay.
  p = grown_p;
  st2 = st;
  CHECK(prune_gaussians(o, 3001, 1.0, &p, nullptr, &st2) == 3);
  const std::vector<float> after_prune2 = {0, 2, 0, 1, 4, 1, 4};
  REQUIRE(p.size() == after_prune2.size());
  for (size_t i = 0; i < p.size(); ++i) CHECK(p.sh0[3 * i] == after_prune2[i]);
  // The scene scale scales both thresholds: at scene scale 10 row 5 (0.5 <= 1) stays.
  p = grown_p;
  st2 = st;
  CHECK(prune_gaussians(o, 3001, 10.0, &p, nullptr, &st2) == 2);
}

TEST_CASE("train strategy: the 2D gradient is accumulated in normalised screen units", "[train]") {
  DefaultStrategyState st;
  const std::vector<float> g = {0.3f, 0.4f, 1.f, 1.f, -0.1f, 0.f};
  const std::vector<uint8_t> visible = {1, 0, 1};
  accumulate_grad2d(g, visible, 20, 10, &st);  // x * 10, y * 5
  accumulate_grad2d(g, visible, 20, 10, &st);
  CHECK(st.grad2d[0] == Approx(2 * std::hypot(0.3 * 10, 0.4 * 5)).epsilon(1e-6));
  CHECK(st.grad2d[1] == 0.0);
  CHECK(st.grad2d[2] == Approx(2 * 1.0).epsilon(1e-6));
  CHECK(st.count == std::vector<int32_t>{2, 0, 2});
}

TEST_CASE("train strategy: split children lie at mean + R (s * z) for the drawn samples",
          "[train]") {
  SplatParams p = tagged_cloud(3);
  // Row 1: anisotropic scales and a rotation of 90 degrees about z (raw quaternion, norm 2).
  const double sc[3] = {0.2, 0.05, 0.01};
  for (int a = 0; a < 3; ++a) p.scales[3 + a] = float(std::log(sc[a]));
  const float h = float(2 * std::sqrt(0.5));
  p.quats[4] = h;
  p.quats[7] = h;
  const SplatParams before = p;
  NormalRng rng(123), copy(123);
  split_gaussians({0, 1, 0}, rng, &p, nullptr, nullptr);
  REQUIRE(p.size() == 4);
  // Kept 0 and 2, then the two children of row 1; samples drawn as [2, 1, 3].
  for (int b = 0; b < 2; ++b) {
    const double z0 = copy.next(), z1 = copy.next(), z2 = copy.next();
    CHECK(z0 != 0.0);
    // R_z(90): (x, y, z) -> (-y, x, z).
    const double d[3] = {-sc[1] * z1, sc[0] * z0, sc[2] * z2};
    const size_t row = 2 + size_t(b);
    for (int a = 0; a < 3; ++a) {
      INFO("child " << b << " axis " << a);
      CHECK(p.means[3 * row + a] == Approx(before.means[3 + a] + d[a]).margin(1e-6));
      CHECK(std::exp(double(p.scales[3 * row + a])) == Approx(sc[a] / 1.6).epsilon(1e-6));
      CHECK(p.quats[4 * row + a] == before.quats[4 + a]);
    }
    CHECK(p.opacities[row] == before.opacities[1]);  // revised_opacity False
    CHECK(p.sh0[3 * row] == 1.f);
  }
  CHECK(p.means[3 * 1] == 2.f);  // row 2 moved up to row 1
  // The normal stream: mean ~0 and variance ~1 over many draws.
  NormalRng n(7);
  double s = 0, s2 = 0;
  for (int i = 0; i < 20000; ++i) {
    const double x = n.next();
    s += x;
    s2 += x * x;
  }
  CHECK(std::abs(s / 20000) < 0.03);
  CHECK(std::abs(s2 / 20000 - 1) < 0.04);
}

TEST_CASE("train strategy: new rows get zero Adam moments, kept rows keep theirs", "[train]") {
  SplatParams p = tagged_cloud(4, 1);
  SplatAdam adam = stepped_adam(&p);
  const std::vector<float> m2 = moment_row(adam, "scales", 2, 3);
  const std::vector<float> m3 = moment_row(adam, "shN", 3, 9);
  REQUIRE(m2[0] != 0.0);
  duplicate_gaussians({1, 0, 0, 0}, &p, &adam, nullptr);  // rows 0 1 2 3 copy0
  REQUIRE(p.size() == 5);
  for (const std::string name : {"means", "scales", "quats", "opacities", "sh0", "shN"}) {
    INFO(name);
    const size_t w = adam.exp_avg(name)->size() / 5;
    for (size_t k = 0; k < w; ++k) {
      CHECK((*adam.exp_avg(name))[4 * w + k] == 0.0);
      CHECK((*adam.exp_avg_sq(name))[4 * w + k] == 0.0);
      CHECK((*adam.exp_avg(name))[0 * w + k] != 0.0);
    }
  }
  NormalRng rng(3);
  split_gaussians({0, 0, 1, 0, 0}, rng, &p, &adam, nullptr);  // 0 1 3 copy0 c2 c2
  REQUIRE(p.size() == 6);
  CHECK(moment_row(adam, "shN", 2, 9) == m3);
  for (size_t r : {4, 5}) CHECK(moment_row(adam, "scales", r, 3) == std::vector<float>(3, 0.f));
  remove_gaussians({1, 0, 0, 0, 0, 0}, &p, &adam, nullptr);  // 1 3 copy0 c2 c2
  REQUIRE(p.size() == 5);
  CHECK(moment_row(adam, "shN", 1, 9) == m3);
  CHECK(adam.exp_avg("means")->size() == 15);
  CHECK(adam.exp_avg("shN")->size() == 45);
  // A step after the changes runs on the new sizes.
  SplatGrads g;
  g.resize(p.size(), 1);
  adam.step(g, &p);
  CHECK(adam.steps() == 2);
  (void)m2;
}

TEST_CASE("train strategy: the opacity reset caps at logit(2 prune_opa) and zeros its moments",
          "[train]") {
  SplatParams p = tagged_cloud(3);
  p.opacities = {3.f, -2.f, -8.f};
  SplatAdam adam = stepped_adam(&p);
  const std::vector<float> after_step = p.opacities;
  reset_opacities(0.01, &p, &adam);
  const float cap = float(std::log(0.01 / 0.99));
  CHECK(p.opacities[0] == cap);
  CHECK(p.opacities[1] == cap);
  CHECK(p.opacities[2] == after_step[2]);  // already below
  for (double v : *adam.exp_avg("opacities")) CHECK(v == 0.0);
  for (double v : *adam.exp_avg_sq("opacities")) CHECK(v == 0.0);
  CHECK((*adam.exp_avg("means"))[0] != 0.0);  // the other groups keep theirs
  // Through the step function: reset at multiples of reset_every (not 0), refinement only after
  // refine_start_iter at multiples of refine_every, nothing from refine_stop_iter on.
  DefaultStrategyOptions o;
  o.prune_opa = 0.0;  // nothing pruned by opacity
  DefaultStrategyState st;
  NormalRng rng(1);
  const std::vector<float> g2(6, 0.f);
  const std::vector<uint8_t> vis(3, 1);
  auto at = [&](int step) {
    auto r = default_strategy_step(o, step, 1.0, g2, vis, 10, 10, rng, &p, &adam, &st);
    REQUIRE(r.is_ok());
    return *r;
  };
  CHECK_FALSE(at(0).reset);
  CHECK_FALSE(at(500).refined);
  CHECK(at(600).refined);
  CHECK_FALSE(at(650).refined);
  CHECK(st.count == std::vector<int32_t>{1, 1, 1});  // zeroed at 600, then step 650
  const RefineReport r3000 = at(3000);
  CHECK(r3000.reset);
  CHECK(r3000.refined);
  CHECK_FALSE(at(15000).refined);
  CHECK_FALSE(at(15000).reset);
  CHECK(st.count == std::vector<int32_t>{0, 0, 0});  // zeroed at 3000, 15000 not accumulated
}

TEST_CASE("train strategy: --max-gaussians refuses growth past the limit", "[train]") {
  SplatParams p = tagged_cloud(4);
  DefaultStrategyState st;
  st.grad2d = {1, 1, 1, 0};
  st.count = {1, 1, 1, 1};
  DefaultStrategyOptions o;
  o.max_gaussians = 6;
  NormalRng rng(1);
  auto r = grow_gaussians(o, 1.0, rng, &p, nullptr, &st);
  REQUIRE_FALSE(r.is_ok());
  CHECK(r.status().message().find("--max-gaussians 6") != std::string::npos);
  CHECK(r.status().message().find("to 7") != std::string::npos);
  CHECK(p.size() == 4);  // unchanged
  o.max_gaussians = 7;
  REQUIRE(grow_gaussians(o, 1.0, rng, &p, nullptr, &st).is_ok());
  CHECK(p.size() == 7);
}

TEST_CASE("train schedule: means lr, SH degree and the per-epoch view order", "[train]") {
  const int N = 30000;
  CHECK(means_lr_factor(0, N) == 1.0);
  CHECK(means_lr_factor(N / 2, N) == Approx(0.1).epsilon(1e-12));
  CHECK(means_lr_factor(N, N) == Approx(0.01).epsilon(1e-12));
  // The closed form is torch's product of N gammas up to rounding.
  double prod = 1, gamma = std::pow(0.01, 1.0 / N);
  for (int s = 0; s < N / 2; ++s) prod *= gamma;
  CHECK(means_lr_factor(N / 2, N) == Approx(prod).epsilon(1e-9));

  CHECK(active_sh_degree(0, 1000, 3) == 0);
  CHECK(active_sh_degree(999, 1000, 3) == 0);
  CHECK(active_sh_degree(1000, 1000, 3) == 1);
  CHECK(active_sh_degree(2999, 1000, 3) == 2);
  CHECK(active_sh_degree(3000, 1000, 3) == 3);
  CHECK(active_sh_degree(9000, 1000, 3) == 3);
  CHECK(active_sh_degree(5000, 1000, 1) == 1);
  CHECK(active_sh_degree(0, 0, 3) == 3);

  ViewOrder seq(3, false, 1);
  for (size_t s = 0; s < 7; ++s) CHECK(seq.next() == s % 3);
  ViewOrder a(10, true, 42), b(10, true, 42), c(10, true, 43);
  std::vector<std::vector<size_t>> epochs_a, epochs_c;
  for (int e = 0; e < 4; ++e) {
    std::vector<size_t> ea, ec;
    for (int i = 0; i < 10; ++i) {
      ea.push_back(a.next());
      CHECK(b.next() == ea.back());  // the seed fixes the order
      ec.push_back(c.next());
    }
    CHECK(std::set<size_t>(ea.begin(), ea.end()).size() == 10);  // a permutation per epoch
    epochs_a.push_back(ea);
    epochs_c.push_back(ec);
  }
  CHECK(epochs_a[0] != epochs_a[1]);  // a fresh permutation each epoch
  CHECK(epochs_a != epochs_c);        // another seed, another order
}

TEST_CASE("train schedule: inactive SH bands get zero gradients, train() applies the schedules",
          "[train]") {
  // Ten Gaussians in front of an identity camera, SH degree 3 with non-zero rest coefficients.
  TrainView view;
  view.camera.name = "c";
  view.camera.width = view.camera.height = 32;
  view.camera.fx = view.camera.fy = 30;
  view.camera.cx = view.camera.cy = 16;
  view.camera.R = Eigen::Matrix3d::Identity();
  view.camera.t = Eigen::Vector3d::Zero();
  SplatParams p = tagged_cloud(10, 3);
  for (size_t i = 0; i < 10; ++i) {
    p.means[3 * i] = float(-0.4 + 0.09 * double(i));
    p.means[3 * i + 1] = float(0.05 * double(i % 3) - 0.05);
    p.means[3 * i + 2] = 2.f;
    for (int a = 0; a < 3; ++a) p.scales[3 * i + a] = float(std::log(0.08));
    for (int c = 0; c < 3; ++c) p.sh0[3 * i + c] = 0.3f;
    for (size_t j = 0; j < 45; ++j) p.shN[45 * i + j] = float(0.05 * std::sin(double(i + j)));
  }
  view.target.assign(32 * 32 * 3, 0.7f);
  for (int active = 0; active <= 3; ++active) {
    DiffRenderOptions ro;
    ro.sh_degree = active;
    auto vg = view_gradient(p, view, ro);
    REQUIRE(vg.is_ok());
    const int K = (active + 1) * (active + 1);
    double inside = 0, outside = 0;
    for (size_t i = 0; i < 10; ++i)
      for (int k = 1; k < 16; ++k)
        for (int c = 0; c < 3; ++c)
          (k < K ? inside : outside) += std::abs(vg->grads.shN[45 * i + size_t(k - 1) * 3 + c]);
    INFO("active degree " << active);
    CHECK(outside == 0.0);
    if (active > 0) CHECK(inside > 0.0);
  }
  // train(): the records carry the schedules.
  TrainOptions to;
  to.steps = 20;
  to.exponential_lr = true;
  to.sh_degree_interval = 5;
  to.adam.scene_scale = 2.0;
  std::vector<StepRecord> recs;
  SplatParams q = p;
  REQUIRE(gs::train::train(&q, {view}, to, [&](const StepRecord& r) {
            recs.push_back(r);
            return Status::ok();
          }).is_ok());
  REQUIRE(recs.size() == 20);
  CHECK(recs[0].means_lr == Approx(1.6e-4 * 2).epsilon(1e-12));
  CHECK(recs[10].means_lr == Approx(1.6e-4 * 2 * 0.1).epsilon(1e-9));
  CHECK(recs[4].sh_degree == 0);
  CHECK(recs[5].sh_degree == 1);
  CHECK(recs[19].sh_degree == 3);
  CHECK(recs.back().loss < recs.front().loss);
}

// ---- --scene-dir inputs (the scene: train_scene_fixture.h) ---------------------------------

TEST_CASE("train inputs: test-every hold-out, SfM and random initialisation", "[train]") {
  const std::vector<bool> h = test_every_holdout(17, 8);
  for (size_t i = 0; i < 17; ++i) CHECK(h[i] == (i == 0 || i == 8 || i == 16));
  CHECK(test_every_holdout(5, 0) == std::vector<bool>(5, false));
  // Nearest neighbours: points on a line at 0, 1, 3, 7: for 0 the 3 nearest are 1, 3, 7.
  const std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {1, 0, 0}, {3, 0, 0}, {7, 0, 0}, {7, 5, 0}};
  const std::vector<double> d = knn_mean_distance(line, 3);
  CHECK(d[0] == Approx(std::sqrt((1 + 9 + 49) / 3.0)));
  CHECK(d[2] == Approx(std::sqrt((4 + 9 + 16) / 3.0)));    // 1, 0, 7
  CHECK(d[4] == Approx(std::sqrt((25 + 41 + 61) / 3.0)));  // (7,0), (3,0), (1,0)
  ColmapPoints pts;
  pts.xyz = line;
  pts.rgb = {255, 0, 128, 0, 0, 0, 10, 20, 30, 1, 2, 3, 4, 5, 6};
  SplatParams p = init_from_points(pts, 3, 5);
  REQUIRE(p.size() == 5);
  CHECK(p.sh_degree == 3);
  CHECK(p.sh0[0] == Approx(0.5 / 0.28209479177387814));
  CHECK(p.sh0[1] == Approx(-0.5 / 0.28209479177387814));
  CHECK(p.scales[0] == Approx(std::log(d[0])));
  CHECK(p.scales[2] == p.scales[0]);
  CHECK(p.opacities[3] == Approx(std::log(0.1 / 0.9)));
  for (float q : p.quats) CHECK((q >= 0.f && q < 1.f));
  for (float v : p.shN) CHECK(v == 0.f);
  SplatParams r = init_random(500, 2.5, 1, 9);
  float lo = 1e9f, hi = -1e9f;
  for (float m : r.means) lo = std::min(lo, m), hi = std::max(hi, m);
  CHECK(lo >= -2.5f);
  CHECK(hi <= 2.5f);
  CHECK(lo < -2.3f);
  CHECK(hi > 2.3f);
}

TEST_CASE("train inputs: macro train --scene-dir holds out test views and raises the PSNR",
          "[train]") {
  test::TempDir tmp("train-scene-dir");
  const std::string dir = tmp.file("scene");
  SplatParams truth;
  test::write_tiny_scene(dir, &truth);
  SceneDirOptions so;
  auto in = load_scene_dir(dir, so);
  REQUIRE(in.is_ok());
  // 9 images sorted by name: v0 and v8 are test views.
  REQUIRE(in->test.size() == 2);
  CHECK(in->test[0].camera.name == "v0.png");
  CHECK(in->test[1].camera.name == "v8.png");
  REQUIRE(in->train.size() == 7);
  CHECK(in->init.size() == 40);
  // --data-factor 2 without images_2/: the photos are box-downscaled, the intrinsics halved.
  so.data_factor = 2;
  auto half = load_scene_dir(dir, so);
  REQUIRE(half.is_ok());
  CHECK(half->train[0].camera.width == 24);
  CHECK(half->train[0].camera.fx == 22.5);
  CHECK(half->train[0].target.size() == 24 * 18 * 3);

  const std::string out = tmp.file("out.ply"), log = tmp.file("log.jsonl");
  REQUIRE(test::run_command(test::macro_exe() + " train --quiet --scene-dir " + dir + " --out " +
                            out + " --log " + log + " --steps 120 --sh-degree-interval 40") == 0);
  auto trained = read_splat_params(out);
  REQUIRE(trained.is_ok());
  auto before = evaluate_views(in->init, in->train);
  auto after = evaluate_views(*trained, in->train);
  REQUIRE(before.is_ok());
  REQUIRE(after.is_ok());
  INFO("train PSNR " << before->psnr << " -> " << after->psnr);
  CHECK(after->psnr > before->psnr + 1.0);
  std::ifstream f(log);
  std::vector<std::string> lines;
  for (std::string l; std::getline(f, l);) lines.push_back(l);
  REQUIRE(lines.size() == 1 + 120 + 1);
  CHECK(lines[0].find("\"test_views\": [\"v0.png\", \"v8.png\"]") != std::string::npos);
  CHECK(lines[0].find("\"train_views\": [\"v1.png\"") != std::string::npos);
  CHECK(lines.back().find("\"eval\": \"test\"") != std::string::npos);
  CHECK(lines.back().find("\"psnr\"") != std::string::npos);
  // A split.json: only its training frames train, its close-up frames never; no hold-out.
  {
    std::ofstream sj(dir + "/split.json");
    sj << R"({"scene": "tiny", "data_factor": 1,
      "intrinsics": {"w": 48, "h": 36, "fl_x": 45, "fl_y": 45, "cx": 24, "cy": 18},
      "training_frames": ["v0.png", "v2.png", "v3.png", "v8.png"],
      "closeup_frames": ["v8.png"], "closeup_poses": {}})";
  }
  auto with_split = load_scene_dir(dir, SceneDirOptions{});
  REQUIRE(with_split.is_ok());
  REQUIRE(with_split->train.size() == 3);
  CHECK(with_split->train[0].camera.name == "v0.png");
  CHECK(with_split->train[2].camera.name == "v3.png");
  CHECK(with_split->test.empty());
  CHECK(with_split->closeup_frames_skipped == 1);
  CHECK(with_split->split_path == dir + "/split.json");
  // Bad inputs are refused by name.
  const int rc =
      test::run_command(test::macro_exe() + " train --quiet --scene-dir " + dir +
                        " --init cube --out " + tmp.file("x.ply") + " 2>" + tmp.file("err.txt"));
  CHECK(rc != 0);
  std::ifstream ef(tmp.file("err.txt"));
  std::stringstream es;
  es << ef.rdbuf();
  CHECK(es.str().find("cube") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(tmp.file("x.ply")));
}
