// gsplat's MCMC strategy (gs/train/strategy_mcmc.h) on analytic cases, and training checkpoints
// (gs/train/checkpoint.h): a run resumed from a checkpoint ends with the same bits as an
// uninterrupted one (library and CLI), and bad checkpoints are refused by name.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "attention/runtime/file_io.h"
#include "gs/formats/splat_params.h"
#include "gs/train/checkpoint.h"
#include "gs/train/strategy_mcmc.h"
#include "gs/train/trainer.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;
using namespace macro::gs::train;

namespace {

float logit(double o) {
  return float(std::log(o / (1 - o)));
}

SplatParams rows(const std::vector<double>& opacities) {
  SplatParams p;
  p.resize(opacities.size(), 1);
  for (size_t i = 0; i < opacities.size(); ++i) {
    for (int a = 0; a < 3; ++a) p.means[3 * i + a] = float(i) + 0.1f * float(a);
    for (int a = 0; a < 3; ++a) p.scales[3 * i + a] = float(-2.0 - 0.1 * double(i) - 0.01 * a);
    p.quats[4 * i] = 1;
    p.quats[4 * i + 1] = 0.1f * float(i);
    p.opacities[i] = logit(opacities[i]);
    for (int c = 0; c < 3; ++c) p.sh0[3 * i + c] = float(i) * 0.5f + float(c);
    for (int k = 0; k < 9; ++k) p.shN[9 * i + size_t(k)] = float(i) * 10 + float(k);
  }
  return p;
}

double sigmoid(float x) {
  return 1 / (1 + std::exp(-double(x)));
}

// A small scene for training runs: Gaussians in front of two cameras, random targets.
struct Scene {
  SplatParams params;
  std::vector<TrainView> views;
};
Scene small_scene() {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  Scene s;
  s.params.resize(60, 1);
  for (size_t i = 0; i < 60; ++i) {
    s.params.means[3 * i] = float(u(rng) - 0.5);
    s.params.means[3 * i + 1] = float(u(rng) - 0.5);
    s.params.means[3 * i + 2] = float(2.5 + u(rng));
    for (int a = 0; a < 3; ++a) s.params.scales[3 * i + a] = float(-2.5 + 0.5 * u(rng));
    for (int a = 0; a < 4; ++a) s.params.quats[4 * i + a] = float(u(rng) + (a == 0 ? 0.5 : 0));
    s.params.opacities[i] = float(i % 6 == 0 ? -6.0 : 2 * u(rng) - 0.5);  // some dead
    for (int c = 0; c < 3; ++c) s.params.sh0[3 * i + c] = float(u(rng) - 0.5);
  }
  for (int v = 0; v < 2; ++v) {
    TrainView view;
    view.camera.name = "v" + std::to_string(v);
    view.camera.width = 32;
    view.camera.height = 24;
    view.camera.fx = view.camera.fy = 30;
    view.camera.cx = 16;
    view.camera.cy = 12;
    view.camera.R = Eigen::Matrix3d::Identity();
    view.camera.t = Eigen::Vector3d(0.1 * v, 0, 0);
    view.target.resize(32 * 24 * 3);
    for (float& x : view.target) x = float(u(rng));
    s.views.push_back(view);
  }
  return s;
}

}  // namespace

TEST_CASE("mcmc: the relocation formula against hand-computed values", "[train]") {
  for (double o : {0.9, 0.5, 0.05}) {
    INFO("opacity " << o);
    const Relocation r1 = compute_relocation(o, 1);
    CHECK(r1.opacity == Approx(o).epsilon(1e-12));
    CHECK(r1.scale_factor == Approx(1.0).epsilon(1e-12));
    // n = 2: o' = 1 - sqrt(1 - o); sum = 2 o' - o'^2 / sqrt(2).
    const double a = 1 - std::sqrt(1 - o);
    const Relocation r2 = compute_relocation(o, 2);
    CHECK(r2.opacity == Approx(a).epsilon(1e-12));
    CHECK(r2.scale_factor == Approx(o / (2 * a - a * a / std::sqrt(2.0))).epsilon(1e-12));
    // n = 3: o' = 1 - (1 - o)^(1/3); sum = 3 o' - 3 o'^2 / sqrt(2) + o'^3 / sqrt(3).
    const double b = 1 - std::cbrt(1 - o);
    const Relocation r3 = compute_relocation(o, 3);
    CHECK(r3.opacity == Approx(b).epsilon(1e-12));
    CHECK(r3.scale_factor ==
          Approx(o / (3 * b - 3 * b * b / std::sqrt(2.0) + b * b * b / std::sqrt(3.0)))
              .epsilon(1e-12));
    // The n copies together are as opaque as the original: 1 - (1 - o')^n = o.
    CHECK(1 - std::pow(1 - r3.opacity, 3) == Approx(o).epsilon(1e-12));
  }
  // Ratios are clamped to gsplat's table, [1, 51].
  CHECK(compute_relocation(0.5, 80).opacity == compute_relocation(0.5, 51).opacity);
  CHECK(compute_relocation(0.5, 0).opacity == compute_relocation(0.5, 1).opacity);
}

TEST_CASE("mcmc: draws follow the weights, dead Gaussians become copies of drawn live ones",
          "[train]") {
  // Frequencies of 200k draws with weights 1, 2, 7 (and a zero weight never drawn).
  uint64_t state = 11;
  const std::vector<double> w = {1, 0, 2, 7};
  const auto d = multinomial_draw(w, {0, 1, 2, 3}, 200000, &state);
  double f[4] = {0, 0, 0, 0};
  for (size_t i : d) f[i] += 1.0 / 200000;
  CHECK(f[0] == Approx(0.1).margin(0.005));
  CHECK(f[1] == 0.0);
  CHECK(f[2] == Approx(0.2).margin(0.005));
  CHECK(f[3] == Approx(0.7).margin(0.005));

  // Rows 1 and 3 dead (opacity <= 0.005), 0, 2, 4 alive.
  SplatParams p = rows({0.6, 0.004, 0.3, 0.001, 0.9});
  const SplatParams before = p;
  AdamOptions ao;
  SplatAdam adam(p, ao);
  SplatGrads g;
  g.resize(p.size(), p.sh_degree);
  for (float& x : g.means) x = 1;
  for (float& x : g.opacities) x = 1;
  adam.step(g, &p);  // non-zero moments everywhere
  const SplatParams stepped = p;
  McmcStrategyOptions mo;
  McmcState st = McmcState::seeded(3);
  McmcState replay = st;
  REQUIRE(mcmc_relocate(mo, &st, &p, &adam) == 2);
  // The same draws, by hand.
  std::vector<double> o(p.size());
  for (size_t i = 0; i < p.size(); ++i) o[i] = sigmoid(stepped.opacities[i]);
  const auto drawn = multinomial_draw(o, {0, 2, 4}, 2, &replay.sample_state);
  REQUIRE(drawn.size() == 2);
  const size_t dead[2] = {1, 3};
  for (int k = 0; k < 2; ++k) {
    const size_t j = drawn[size_t(k)], r = dead[k];
    INFO("dead row " << r << " drawn from " << j);
    const int count = 1 + int(drawn[0] == j) + int(drawn[1] == j);
    const Relocation rel = compute_relocation(o[j], count);
    CHECK(sigmoid(p.opacities[j]) == Approx(rel.opacity).epsilon(1e-6));
    for (int a = 0; a < 3; ++a)
      CHECK(std::exp(double(p.scales[3 * j + a])) ==
            Approx(std::exp(double(stepped.scales[3 * j + a])) * rel.scale_factor).epsilon(1e-6));
    // The dead row is a copy of the drawn one, every group.
    for (int a = 0; a < 3; ++a) CHECK(p.means[3 * r + a] == p.means[3 * j + a]);
    for (int a = 0; a < 4; ++a) CHECK(p.quats[4 * r + a] == p.quats[4 * j + a]);
    CHECK(p.opacities[r] == p.opacities[j]);
    for (int k2 = 0; k2 < 9; ++k2) CHECK(p.shN[9 * r + size_t(k2)] == p.shN[9 * j + size_t(k2)]);
    // Adam: the drawn row's moments zeroed, the dead row's kept (gsplat).
    CHECK((*adam.exp_avg("means"))[3 * j] == 0.0);
    CHECK((*adam.exp_avg("means"))[3 * r] != 0.0);
  }
  // A row neither dead nor drawn is unchanged.
  for (size_t i : {size_t(0), size_t(2), size_t(4)}) {
    if (i == drawn[0] || i == drawn[1]) continue;
    CHECK(p.opacities[i] == stepped.opacities[i]);
    CHECK((*adam.exp_avg("opacities"))[i] != 0.0);
  }
  (void)before;
}

TEST_CASE("mcmc: growth is 5% per refinement and never passes cap_max", "[train]") {
  std::vector<double> o(100, 0.5);
  SplatParams p = rows(o);
  SplatAdam adam(p, AdamOptions{});
  McmcStrategyOptions mo;
  McmcState st = McmcState::seeded(1);
  CHECK(mcmc_add(mo, &st, &p, &adam) == 5);
  CHECK(p.size() == 105);
  CHECK(adam.exp_avg("means")->size() == 105 * 3);
  mo.cap_max = 107;
  CHECK(mcmc_add(mo, &st, &p, &adam) == 2);
  CHECK(mcmc_add(mo, &st, &p, &adam) == 0);
  CHECK(p.size() == 107);
  CHECK(p.check_shapes().is_ok());

  // A whole run with frequent refinement: the count rises to the cap and stays there.
  Scene s = small_scene();
  TrainOptions options;
  options.steps = 40;
  options.strategy = Strategy::kMcmc;
  options.mcmc.cap_max = 70;
  options.mcmc.refine_start_iter = 1;
  options.mcmc.refine_every = 2;
  options.opacity_reg = options.scale_reg = 0.01;
  size_t most = 0, relocated = 0;
  ThreadPool pool(1);
  REQUIRE(gs::train::train(
              &s.params, s.views, options,
              [&](const StepRecord& r) {
                most = std::max(most, r.num_gaussians);
                relocated += r.mcmc.relocated;
                CHECK(r.num_gaussians <= 70);
                return Status::ok();
              },
              pool)
              .is_ok());
  CHECK(most == 70);
  CHECK(relocated >= 10);  // every sixth Gaussian starts dead
}

TEST_CASE("mcmc: position noise vanishes for opaque Gaussians and scales with the rate",
          "[train]") {
  SplatParams p = rows({0.999999, 0.001, 0.3});
  p.opacities[0] = 30;  // o = 1 - 1e-13
  McmcState st = McmcState::seeded(9);
  SplatParams a = p, b = p;
  McmcState sa = st, sb = st;
  mcmc_inject_noise(0.1, &sa, &a);
  mcmc_inject_noise(0.2, &sb, &b);
  for (int k = 0; k < 3; ++k) CHECK(a.means[size_t(k)] == p.means[size_t(k)]);
  // Row 1 (o = 0.001): Sigma (z sigmoid(100 (0.999 - 0.995)) scaler), z from the same stream.
  NormalRng z(0);
  z.restore(st.noise.snapshot());
  double zz[3][3];
  for (auto& row : zz)
    for (double& v : row) v = z.next();
  const size_t g = 1;
  const double w = p.quats[4], x = p.quats[5];
  const double qn = std::sqrt(w * w + x * x);
  const double qw = w / qn, qx = x / qn;
  // Rotation about x by the unit quaternion (qw, qx, 0, 0).
  const double R[9] = {1, 0, 0, 0, 1 - 2 * qx * qx, -2 * qw * qx, 0, 2 * qw * qx, 1 - 2 * qx * qx};
  const double gate = 1 / (1 + std::exp(-100 * ((1 - sigmoid(p.opacities[g])) - 0.995)));
  double v[3], s2[3], out[3];
  for (int k = 0; k < 3; ++k) {
    v[k] = zz[g][k] * gate * 0.1;
    s2[k] = std::exp(2 * double(p.scales[3 * g + size_t(k)]));
  }
  for (int i = 0; i < 3; ++i) {
    out[i] = 0;
    for (int k = 0; k < 3; ++k)
      for (int m = 0; m < 3; ++m) out[i] += R[3 * i + k] * s2[k] * R[3 * m + k] * v[m];
  }
  for (int k = 0; k < 3; ++k) {
    const double da = double(a.means[3 * g + size_t(k)]) - p.means[3 * g + size_t(k)];
    const double db = double(b.means[3 * g + size_t(k)]) - p.means[3 * g + size_t(k)];
    CHECK(da == Approx(out[k]).epsilon(1e-3).margin(1e-9));
    CHECK(db == Approx(2 * out[k]).epsilon(1e-3).margin(1e-9));
  }
  CHECK(std::abs(out[0]) + std::abs(out[1]) + std::abs(out[2]) > 1e-6);
}

TEST_CASE("checkpoint: a resumed run ends with the bits of an uninterrupted one", "[train]") {
  test::TempDir tmp("train-ckpt");
  ThreadPool pool(1);
  struct Config {
    const char* name;
    Strategy strategy;
    RasterMode mode;
  };
  for (const Config& cfg :
       {Config{"default, antialiased", Strategy::kDefault, RasterMode::kAntialiased},
        Config{"mcmc, mip", Strategy::kMcmc, RasterMode::kMip}}) {
    INFO(cfg.name);
    Scene s = small_scene();
    TrainOptions options;
    options.steps = 20;
    options.strategy = cfg.strategy;
    options.render.mode = cfg.mode;
    options.exponential_lr = options.shuffled_views = true;
    options.sh_degree_interval = 7;
    options.default_strategy.refine_start_iter = 3;
    options.default_strategy.refine_every = 4;
    options.default_strategy.reset_every = 13;
    options.default_strategy.grow_grad2d = 1e-6;  // some growth
    options.mcmc.refine_start_iter = 3;
    options.mcmc.refine_every = 4;
    options.mcmc.cap_max = 75;
    SplatParams straight = s.params;
    REQUIRE(gs::train::train(&straight, s.views, options, {}, pool).is_ok());
    CHECK(straight.size() != s.params.size());  // the strategy did something

    // The same run writing a checkpoint at step 10 (and continuing).
    const std::string ck = tmp.file("run.ckpt");
    SplatParams with = s.params;
    TrainHooks hooks;
    hooks.checkpoint_every = 10;
    int written = 0;
    hooks.checkpoint = [&](const SplatParams& p, const TrainState& st) {
      ++written;
      return write_checkpoint(ck, "k=v\n", p, st);
    };
    REQUIRE(gs::train::train(&with, s.views, options, {}, pool, hooks).is_ok());
    CHECK(written == 1);  // step 10 only: none after the last step
    auto c = read_checkpoint(ck, "k=v\n");
    REQUIRE(c.is_ok());
    CHECK(c->state.next_step == 10);
    SplatParams resumed = c->params;
    TrainHooks again;
    again.resume = &c->state;
    int first = -1;
    REQUIRE(gs::train::train(
                &resumed, s.views, options,
                [&](const StepRecord& r) {
                  if (first < 0) first = r.step;
                  return Status::ok();
                },
                pool, again)
                .is_ok());
    CHECK(first == 10);
    const std::string a = tmp.file("a.ply"), b = tmp.file("b.ply"), w = tmp.file("w.ply");
    REQUIRE(write_splat_params(straight, a).is_ok());
    REQUIRE(write_splat_params(resumed, b).is_ok());
    REQUIRE(write_splat_params(with, w).is_ok());
    auto fa = read_file(a), fb = read_file(b), fw = read_file(w);
    REQUIRE(fa.is_ok());
    CHECK(*fa == *fb);
    CHECK(*fa == *fw);
  }
}

TEST_CASE("checkpoint: bad checkpoints are refused with the reason", "[train]") {
  test::TempDir tmp("train-ckpt-bad");
  Scene s = small_scene();
  TrainState st;
  st.next_step = 4;
  SplatAdam adam(s.params, AdamOptions{});
  for (const SplatAdam::GroupState& g : adam.state())
    st.adam.push_back({g.name, *g.lr, *g.m, *g.v});
  const std::string ck = tmp.file("x.ckpt");
  REQUIRE(write_checkpoint(ck, "steps=20\nviews=v0:32x24,\n", s.params, st).is_ok());
  REQUIRE(read_checkpoint(ck, "steps=20\nviews=v0:32x24,\n").is_ok());
  auto other = read_checkpoint(ck, "steps=30\nviews=v0:32x24,\n");
  REQUIRE_FALSE(other.is_ok());
  CHECK(other.status().message().find("steps = 20, this run has steps = 30") != std::string::npos);
  auto bytes = read_file(ck);
  REQUIRE(bytes.is_ok());
  // One flipped byte in the parameters: the checksum.
  std::vector<uint8_t> bad = *bytes;
  bad[bad.size() / 2] ^= 0x40;
  REQUIRE(write_file_atomic(tmp.file("flip.ckpt"), bad.data(), bad.size()).is_ok());
  auto flip = read_checkpoint(tmp.file("flip.ckpt"), "");
  REQUIRE_FALSE(flip.is_ok());
  CHECK(flip.status().message().find("checksum") != std::string::npos);
  // Another version.
  bad = *bytes;
  bad[10] = 9;
  REQUIRE(write_file_atomic(tmp.file("ver.ckpt"), bad.data(), bad.size()).is_ok());
  auto ver = read_checkpoint(tmp.file("ver.ckpt"), "");
  REQUIRE_FALSE(ver.is_ok());
  CHECK(ver.status().message().find("version 9") != std::string::npos);
  // Not a checkpoint.
  REQUIRE(write_splat_params(s.params, tmp.file("p.ply")).is_ok());
  auto ply = read_checkpoint(tmp.file("p.ply"), "");
  REQUIRE_FALSE(ply.is_ok());
  CHECK(ply.status().message().find("not a training checkpoint") != std::string::npos);
  // A checkpoint of another size cannot resume this run's optimizer.
  TrainState wrong = st;
  wrong.adam[0].m.resize(3);
  SplatParams p = s.params;
  TrainHooks hooks;
  hooks.resume = &wrong;
  TrainOptions options;
  options.steps = 6;
  auto run = gs::train::train(&p, s.views, options, {}, ThreadPool::global(), hooks);
  REQUIRE_FALSE(run.is_ok());
  CHECK(run.message().find("optimizer group 0") != std::string::npos);
}
