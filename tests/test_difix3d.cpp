// Difix3D's progressive fine-tuning (enhance/baselines/difix3d.h) and the trainer pieces it rests
// on: per-view loss weights and masks on every path, the novel-view hook's draws, and the
// activated-cloud -> raw-parameter conversion of scenes in compact formats.
#include <catch2/catch.hpp>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <random>

#include "enhance/baselines/difix3d.h"
#include "enhance/baselines/progressive_cameras.h"
#include "gs/cameras/camera.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/loss.h"
#include "gs/train/step_gradient.h"
#include "gs/train/trainer.h"
#include "test_support.h"
#include "train_scene_fixture.h"

using namespace macro;
using namespace macro::gs;
using namespace macro::gs::train;

namespace {

// The tiny scene's truth, its 9 cameras and photos, and a target that differs from the render.
struct WeightCase {
  SplatParams params;
  Camera camera;
  std::vector<float> target;
};

WeightCase weight_case(const std::string& dir) {
  WeightCase w;
  test::write_tiny_scene(dir, &w.params);
  auto cams = load_cameras(dir + "/sparse/0");
  REQUIRE(cams.is_ok());
  w.camera = cams->cameras[3];
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.05f, 0.95f);
  w.target.resize(size_t(w.camera.width) * size_t(w.camera.height) * 3);
  for (float& v : w.target) v = u(rng);
  for (float& v : w.params.opacities) v -= 1.f;  // partly transparent: every gradient non-zero
  return w;
}

std::vector<const std::vector<float>*> grad_arrays(const SplatGrads& g) {
  return {&g.means, &g.scales, &g.quats, &g.opacities, &g.sh0, &g.means2d};
}

}  // namespace

TEST_CASE("train: a view's loss weight scales every gradient, its mask removes what lies outside",
          "[train][baselines]") {
  test::TempDir tmp("train-weight-mask");
  WeightCase w = weight_case(tmp.file("scene"));
  const size_t pixels = size_t(w.camera.width) * size_t(w.camera.height);
  std::vector<float> mask(pixels, 0.f), ones(pixels, 1.f);
  for (size_t p = 0; p < pixels; ++p) mask[p] = (p % size_t(w.camera.width)) < 20 ? 1.f : 0.f;
  // The target changed only where the mask is 0.
  std::vector<float> other = w.target;
  for (size_t p = 0; p < pixels; ++p)
    if (mask[p] == 0.f)
      for (int c = 0; c < 3; ++c) other[3 * p + c] = 1.f - other[3 * p + c];
  ThreadPool pool(2);
  std::vector<std::pair<std::string, Precision>> paths = {{"double", Precision::kDouble}};
  for (Isa isa : test::supported_isas())
    if (train_kernels_for(isa) != nullptr) paths.push_back({isa_name(isa), Precision::kFloat});
  for (const auto& [name, precision] : paths) {
    INFO("path " << name);
    test::IsaGuard restore;
    if (precision == Precision::kFloat) {
      for (Isa isa : test::supported_isas())
        if (name == isa_name(isa)) REQUIRE(set_isa(isa).is_ok());
    }
    auto run = [&](const std::vector<float>& target, const float* m, double weight, SplatGrads* g) {
      StepGradient sg(precision);
      auto loss = sg.compute(w.params, w.camera, target.data(), {}, g, pool, m, weight);
      REQUIRE(loss.is_ok());
      return *loss;
    };
    SplatGrads plain, weighted, all_ones, masked, masked_other;
    const LossValue l_plain = run(w.target, nullptr, 1, &plain);
    const LossValue l_weighted = run(w.target, nullptr, 2.5, &weighted);
    CHECK(l_weighted.loss == Approx(2.5 * l_plain.loss).epsilon(1e-12));
    CHECK(l_weighted.l1 == l_plain.l1);
    size_t nonzero = 0;
    for (size_t k = 0; k < grad_arrays(plain).size(); ++k) {
      const auto& a = *grad_arrays(plain)[k];
      const auto& b = *grad_arrays(weighted)[k];
      REQUIRE(a.size() == b.size());
      // The weight scales the image gradient before the backward: the float sums round again.
      std::vector<float> want(a.size());
      for (size_t i = 0; i < a.size(); ++i) {
        want[i] = float(2.5 * double(a[i]));
        nonzero += a[i] != 0;
      }
      INFO("array " << k << " rel L2 " << test::compare(b, want).rel_l2);
      CHECK(test::compare(b, want).rel_l2 <= (precision == Precision::kDouble ? 1e-7 : 1e-5));
    }
    CHECK(nonzero > 100);
    // A mask of ones changes nothing, bit for bit.
    const LossValue l_ones = run(w.target, ones.data(), 1, &all_ones);
    CHECK(l_ones.loss == l_plain.loss);
    for (size_t k = 0; k < grad_arrays(plain).size(); ++k)
      CHECK(*grad_arrays(all_ones)[k] == *grad_arrays(plain)[k]);
    // With a mask, the target outside it does not matter, and the loss is that of the masked
    // images.
    const LossValue l_masked = run(w.target, mask.data(), 1, &masked);
    const LossValue l_masked_other = run(other, mask.data(), 1, &masked_other);
    CHECK(l_masked.loss == l_masked_other.loss);
    for (size_t k = 0; k < grad_arrays(plain).size(); ++k)
      CHECK(*grad_arrays(masked)[k] == *grad_arrays(masked_other)[k]);
    CHECK(l_masked.loss != Approx(l_plain.loss));
    {
      DiffRenderer r;
      DiffImage img;
      REQUIRE(r.forward(w.params, w.camera, {}, &img, pool).is_ok());
      std::vector<double> x = img.color;
      std::vector<float> y = w.target;
      for (size_t i = 0; i < x.size(); ++i) {
        x[i] *= mask[i / 3];
        y[i] *= mask[i / 3];
      }
      auto want =
          photometric_loss(x.data(), y.data(), w.camera.width, w.camera.height, nullptr, pool);
      REQUIRE(want.is_ok());
      CHECK(l_masked.loss == Approx(want->loss).epsilon(1e-5));
    }
  }
}

TEST_CASE("train: novel views are refreshed every N steps and drawn with the stated share",
          "[train][baselines]") {
  test::TempDir tmp("train-novel");
  SplatParams truth;
  test::write_tiny_scene(tmp.file("scene"), &truth);
  auto cams = load_cameras(tmp.file("scene/sparse/0"));
  REQUIRE(cams.is_ok());
  std::vector<TrainView> photos;
  for (int k = 0; k < 4; ++k) {
    TrainView v;
    v.camera = cams->cameras[size_t(k)];
    auto img = read_image(tmp.file("scene/images/" + v.camera.name));
    REQUIRE(img.is_ok());
    v.target = img->data;
    photos.push_back(v);
  }
  SplatParams start = truth;
  for (float& v : start.sh0) v *= 0.5f;
  auto run = [&](double p, int threads, std::vector<int>* refresh_steps,
                 std::vector<StepRecord>* records) {
    SplatParams params = start;
    TrainOptions o;
    o.steps = 400;
    o.shuffled_views = true;
    o.seed = 3;
    TrainHooks hooks;
    hooks.novel.every = 100;
    hooks.novel.real_probability = p;
    hooks.novel.refresh = [&](int step, const SplatParams& current,
                              std::vector<TrainView>* novel) -> Status {
      refresh_steps->push_back(step);
      CHECK(current.size() == params.size());
      novel->clear();
      for (int k = 0; k < 2; ++k) {
        TrainView v = photos[size_t(k)];
        v.camera.name += "@" + std::to_string(step);
        v.loss_weight = 0.3;
        v.mask.assign(size_t(v.camera.width) * size_t(v.camera.height), 1.f);
        novel->push_back(v);
      }
      return Status::ok();
    };
    ThreadPool pool(threads);
    REQUIRE(gs::train::train(
                &params, photos, o,
                [&](const StepRecord& r) {
                  records->push_back(r);
                  return Status::ok();
                },
                pool, hooks)
                .is_ok());
    return params;
  };
  std::vector<int> steps_a, steps_b;
  std::vector<StepRecord> rec_a, rec_b;
  const SplatParams a = run(0.7, 1, &steps_a, &rec_a);
  const SplatParams b = run(0.7, 4, &steps_b, &rec_b);
  CHECK(steps_a == std::vector<int>{0, 100, 200, 300});
  CHECK(a.means == b.means);  // any thread count: the same bits
  CHECK(a.sh0 == b.sh0);
  size_t novel = 0;
  for (const StepRecord& r : rec_a) {
    novel += r.novel_view;
    CHECK(r.view < (r.novel_view ? 2u : 4u));
  }
  // 400 draws at 0.3: mean 120, standard deviation 9.2; 4.5 sigma either way.
  CHECK(novel >= 79);
  CHECK(novel <= 161);
  std::vector<int> s1, s0;
  std::vector<StepRecord> r1, r0;
  run(1.0, 1, &s1, &r1);
  run(0.0, 1, &s0, &r0);
  for (const StepRecord& r : r1) CHECK(!r.novel_view);
  for (const StepRecord& r : r0) CHECK(r.novel_view);
  // A bad hook result names the view.
  SplatParams params = start;
  TrainOptions o;
  o.steps = 3;
  TrainHooks hooks;
  hooks.novel.every = 1;
  hooks.novel.refresh = [&](int, const SplatParams&, std::vector<TrainView>* novel) {
    TrainView v = photos[0];
    v.mask.resize(7);
    *novel = {v};
    return Status::ok();
  };
  const Status s = gs::train::train(&params, photos, o, {}, ThreadPool::global(), hooks);
  REQUIRE(!s.is_ok());
  CHECK(s.message().find("mask holds 7 values") != std::string::npos);
}

TEST_CASE("splat params: from_cloud inverts to_cloud and clamps what a compact format stores",
          "[train][formats]") {
  test::TempDir tmp("from-cloud");
  SplatParams p;
  test::write_tiny_scene(tmp.file("scene"), &p);
  const GaussianCloud c = to_cloud(p);
  auto back = from_cloud(c, "tiny");
  REQUIRE(back.is_ok());
  const GaussianCloud c2 = to_cloud(*back);
  CHECK(test::compare(c2.position, c.position).max_abs == 0);
  CHECK(test::compare(c2.scale, c.scale).rel_l2 <= 1e-6);
  CHECK(test::compare(c2.opacity, c.opacity).max_abs <= 1e-6);
  CHECK(test::compare(c2.rotation, c.rotation).max_abs <= 1e-7);
  CHECK(c2.sh == c.sh);
  GaussianCloud q = c;
  q.opacity[0] = 1.f;
  q.opacity[1] = 0.f;
  q.scale[0] = 0.f;
  auto clamped = from_cloud(q, "quantised");
  REQUIRE(clamped.is_ok());
  for (float v : clamped->opacities) CHECK(std::isfinite(v));
  CHECK(std::isfinite(clamped->scales[0]));
  CHECK(clamped->opacities[0] > 13.f);
  q.mip_filter_3d_applied = true;
  auto mip = from_cloud(q, "mip.spz");
  REQUIRE(!mip.is_ok());
  CHECK(mip.status().message().find("mip.spz") != std::string::npos);
}

namespace {

// The tiny scene as a close-up's inputs: the truth blurred (a degraded 3DGS), the 9 photos as
// candidates, and a close-up 1.4 units nearer than v4 along its axis.
enhance::SceneInputs tiny_inputs(const std::string& dir) {
  SplatParams truth;
  test::write_tiny_scene(dir, &truth);
  for (float& s : truth.scales) s += 0.3f;
  enhance::SceneInputs in;
  in.scene_path = dir + "/scene";
  in.cloud = to_cloud(truth);
  auto cams = load_cameras(dir + "/sparse/0");
  REQUIRE(cams.is_ok());
  for (const Camera& c : cams->cameras) {
    in.candidates.push_back(c);
    in.candidate_images.push_back(dir + "/images/" + c.name);
  }
  Camera close = cams->cameras[4];
  close.name = "close";
  const Eigen::Vector3d centre = close.center() * (1.6 / close.center().norm());
  close.t = -close.R * centre;
  close.width = 64;
  close.height = 48;
  close.fx = close.fy = 60;
  close.cx = 32;
  close.cy = 24;
  in.closeup = close;
  in.closeup_pose_source = "given";
  return in;
}

}  // namespace

TEST_CASE("difix3d: the rounds follow the progressive schedule, PR-Difix3D's references grow",
          "[baselines]") {
  test::TempDir tmp("difix3d");
  const enhance::SceneInputs in = tiny_inputs(tmp.file("scene"));
  enhance::Difix3dOptions o;
  o.rounds = 4;
  o.round_steps = 6;
  o.progress = false;
  const auto schedule = enhance::progressive_schedule(in.candidates, {in.closeup}, 4, 0.5);
  for (bool pr : {false, true}) {
    INFO((pr ? "PR-Difix3D" : "Difix3D"));
    o.progressive_reference = pr;
    auto run = enhance::Difix3dRun::run(in, o);
    REQUIRE(run.is_ok());
    const enhance::Difix3dResult& r = (*run)->result();
    CHECK(r.enhancer == "transfer (weight-free)");
    CHECK(r.finetune_steps == 24);
    REQUIRE(r.rounds.size() == 4);
    for (size_t k = 0; k < 4; ++k) {
      INFO("round " << k + 1);
      const Camera& c = r.rounds[k].camera;
      CHECK(c.name == "close@" + std::to_string(k + 1));
      CHECK((c.center() - schedule[k][0].center()).norm() == Approx(0).margin(1e-12));
      CHECK(c.width == 48);  // the first training camera's size, not the close-up's
      CHECK(r.rounds[k].mask_fraction > 0.05);
      CHECK(r.rounds[k].mask_fraction <= 1.0);
    }
    // 1.4 units in 0.5 steps: 0.5, then the close-up itself (at most 0.5 would be left after
    // the second step), which stays.
    CHECK((r.rounds[0].camera.center() - in.candidates[4].center()).norm() == Approx(0.5));
    CHECK((r.rounds[1].camera.center() - in.closeup.center()).norm() == Approx(0).margin(1e-9));
    // Difix3D: always the nearest training photo (v4, on the close-up's axis). PR-Difix3D:
    // from round 2 the previous round's enhanced view, which is nearer.
    CHECK(r.rounds[0].reference == "v4.png");
    CHECK(r.rounds[1].reference == (pr ? "close@1" : "v4.png"));
    CHECK(r.rounds[2].reference == (pr ? "close@2" : "v4.png"));
    CHECK(r.rounds[3].reference == (pr ? "close@2" : "v4.png"));  // first of equal distances
    CHECK(r.render.width == 64);
    CHECK(r.render.height == 48);
    CHECK(r.seconds_finetune > 0);
    // The fine-tuning moved the 3DGS: the render is not the input's.
    RenderOptions ro;
    auto before = render(in.cloud, in.closeup, ro);
    REQUIRE(before.is_ok());
    CHECK(test::compare(before->color, r.render.data).max_abs > 0.01);
    auto plus = (*run)->enhance_final();
    REQUIRE(plus.is_ok());
    CHECK((*plus)->enhanced.width == 64);
    CHECK((*plus)->final_reference == (pr ? "close@2" : "v4.png"));
    CHECK(test::compare((*plus)->enhanced.data, r.render.data).max_abs > 0);
    // Again: the same bits.
    auto again = enhance::Difix3dRun::run(in, o);
    REQUIRE(again.is_ok());
    CHECK((*again)->result().render.data == r.render.data);
  }
  // Bad settings are refused by name.
  o.rounds = 0;
  auto bad = enhance::Difix3dRun::run(in, o);
  REQUIRE(!bad.is_ok());
  CHECK(bad.status().message().find("rounds 0") != std::string::npos);
}
