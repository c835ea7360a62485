// The trainer (gs/train/) against ../shared/golden/train (gsplat conventions, float64 autograd):
// forward, loss and every parameter gradient per view, ten Adam steps; the same through
// `macro grad` and `macro train`; finite differences of the loss on small random scenes for every
// parameter kind; thread-count invariance; refusals of what is not implemented.
// Tolerances (../shared/golden/README.md "train/"): forward and loss max abs 2e-3, gradients
// relative L2 1e-3 per parameter, Adam parameters after 10 steps max abs 1e-4 for >= 99% of the
// entries of each tensor.
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "attention/runtime/io/safetensors.h"
#include "gs/cameras/camera.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/adam.h"
#include "gs/train/diff_render.h"
#include "gs/train/loss.h"
#include "gs/train/step_gradient.h"
#include "gs/train/train_job.h"
#include "gs/train/train_kernels.h"
#include "gs/train/trainer.h"
#include "test_support.h"
#include "train_fd.h"

using namespace macro;
using namespace macro::gs;
using namespace macro::gs::train;

namespace {

std::string train_dir() {
  return test::golden_dir() + "/train";
}

bool have_goldens() {
  if (std::filesystem::is_regular_file(train_dir() + "/expected.safetensors")) return true;
  WARN("skipped: no golden train data at " << train_dir());
  return false;
}

std::vector<float> golden(const SafeTensors& f, const std::string& name) {
  INFO("golden tensor " << name);
  auto v = f.read_f32(name);
  REQUIRE(v.is_ok());
  return *v;
}

std::vector<float> to_float(const std::vector<double>& v) {
  return std::vector<float>(v.begin(), v.end());
}

// The gradient tensors of a SplatGrads by their gsplat names.
std::vector<std::pair<std::string, const std::vector<float>*>> grad_tensors(const SplatGrads& g) {
  return {{"means", &g.means},         {"scales", &g.scales}, {"quats", &g.quats},
          {"opacities", &g.opacities}, {"sh0", &g.sh0},       {"shN", &g.shN},
          {"means2d", &g.means2d}};
}
std::vector<std::pair<std::string, const std::vector<float>*>> param_tensors(const SplatParams& p) {
  return {{"means", &p.means},         {"scales", &p.scales}, {"quats", &p.quats},
          {"opacities", &p.opacities}, {"sh0", &p.sh0},       {"shN", &p.shN}};
}

// Fraction of entries within tol.
double fraction_within(const std::vector<float>& a, const std::vector<float>& b, double tol,
                       double* max_abs) {
  size_t ok = 0;
  *max_abs = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const double d = std::abs(double(a[i]) - double(b[i]));
    ok += d <= tol;
    *max_abs = std::max(*max_abs, d);
  }
  return a.empty() ? 1.0 : double(ok) / double(a.size());
}

}  // namespace

TEST_CASE("train: forward, loss and gradients match the golden views", "[train]") {
  if (!have_goldens()) return;
  auto params = read_splat_params(train_dir() + "/init.ply");
  REQUIRE(params.is_ok());
  auto cams = load_cameras(train_dir() + "/cameras.json");
  REQUIRE(cams.is_ok());
  auto exp = SafeTensors::open(train_dir() + "/expected.safetensors");
  REQUIRE(exp.is_ok());
  for (const char* view : {"v0", "v1"}) {
    INFO("view " << view);
    auto cam = cams->find(view);
    REQUIRE(cam.is_ok());
    auto target = read_image(train_dir() + "/images/" + view + ".png");
    REQUIRE(target.is_ok());
    const std::vector<float> target_golden = golden(*exp, std::string("target.") + view);
    CHECK(test::compare(target->data, target_golden).max_abs <= 1e-7);  // byte / 255 in float

    DiffRenderer renderer;
    DiffImage image;
    REQUIRE(renderer.forward(*params, *cam, {}, &image).is_ok());
    const auto color =
        test::compare(to_float(image.color), golden(*exp, std::string(view) + ".color"));
    const auto alpha =
        test::compare(to_float(image.alpha), golden(*exp, std::string(view) + ".alpha"));
    INFO("color max abs " << color.max_abs << ", alpha max abs " << alpha.max_abs);
    CHECK(color.max_abs <= 2e-3);
    CHECK(alpha.max_abs <= 2e-3);

    std::vector<double> v_color;
    auto loss = photometric_loss(image.color.data(), target->data.data(), image.width, image.height,
                                 &v_color);
    REQUIRE(loss.is_ok());
    const double g_loss = golden(*exp, std::string(view) + ".loss")[0];
    const double g_l1 = golden(*exp, std::string(view) + ".l1")[0];
    const double g_ssim = golden(*exp, std::string(view) + ".ssim")[0];
    INFO("loss " << loss->loss << " vs " << g_loss << ", l1 " << loss->l1 << " vs " << g_l1
                 << ", ssim " << loss->ssim << " vs " << g_ssim);
    CHECK(std::abs(loss->loss - g_loss) <= 2e-3);
    CHECK(std::abs(loss->l1 - g_l1) <= 2e-3);
    CHECK(std::abs(loss->ssim - g_ssim) <= 2e-3);

    SplatGrads grads;
    renderer.backward(*params, v_color.data(), nullptr, &grads);
    for (const auto& [name, data] : grad_tensors(grads)) {
      const auto d = test::compare(*data, golden(*exp, std::string(view) + ".grad." + name));
      INFO("grad." << name << ": rel L2 " << d.rel_l2 << ", max abs " << d.max_abs);
      CHECK(d.rel_l2 <= 1e-3);
    }
  }
}

namespace {

// The golden views as TrainViews, in camera-file order.
std::vector<TrainView> golden_views() {
  auto cams = load_cameras(train_dir() + "/cameras.json");
  REQUIRE(cams.is_ok());
  std::vector<TrainView> views;
  for (const Camera& c : cams->cameras) {
    auto img = read_image(train_dir() + "/images/" + c.name + ".png");
    REQUIRE(img.is_ok());
    views.push_back({c, img->data});
  }
  return views;
}

// Adam parameters against adam.<prefix>.*: max abs 1e-4 for >= 99% of each tensor's entries.
void check_adam_params(const SplatParams& p, const SafeTensors& exp, const std::string& prefix) {
  for (const auto& [name, data] : param_tensors(p)) {
    const std::vector<float> want = golden(exp, prefix + name);
    REQUIRE(data->size() == want.size());
    double max_abs = 0;
    const double within = fraction_within(*data, want, 1e-4, &max_abs);
    INFO(prefix << name << ": " << within * 100 << "% within 1e-4, max abs " << max_abs);
    CHECK(within >= 0.99);
  }
}

}  // namespace

TEST_CASE("train: ten constant-rate Adam steps match the golden", "[train]") {
  if (!have_goldens()) return;
  auto exp = SafeTensors::open(train_dir() + "/expected.safetensors");
  REQUIRE(exp.is_ok());
  const std::vector<TrainView> views = golden_views();
  REQUIRE(views.size() == 2);
  auto init = read_splat_params(train_dir() + "/init.ply");
  REQUIRE(init.is_ok());

  SplatParams one = *init;
  TrainOptions options;
  options.steps = 1;
  REQUIRE(gs::train::train(&one, views, options).is_ok());
  check_adam_params(one, *exp, "adam.after1.");

  SplatParams ten = *init;
  options.steps = 10;
  std::vector<double> losses;
  REQUIRE(gs::train::train(&ten, views, options, [&](const StepRecord& r) {
            losses.push_back(r.loss);
            CHECK(r.step == int(losses.size()) - 1);
            CHECK(r.num_gaussians == 300);
            return Status::ok();
          }).is_ok());
  REQUIRE(losses.size() == 10);
  for (int s = 0; s < 10; ++s) {
    const double want = golden(*exp, "adam.loss.step" + std::to_string(s))[0];
    INFO("step " << s << ": loss " << losses[size_t(s)] << ", golden " << want);
    CHECK(std::abs(losses[size_t(s)] - want) <= 2e-3);
  }
  check_adam_params(ten, *exp, "adam.after10.");
}

TEST_CASE("train: macro grad and macro train match the goldens through the CLI", "[train]") {
  if (!have_goldens()) return;
  auto exp = SafeTensors::open(train_dir() + "/expected.safetensors");
  REQUIRE(exp.is_ok());
  test::TempDir tmp("train-cli");
  const std::string g = train_dir();
  for (const char* view : {"v0", "v1"}) {
    INFO("view " << view);
    const std::string out = tmp.file(std::string(view) + ".safetensors");
    REQUIRE(test::run_command(test::macro_exe() + " grad --quiet --scene " + g + "/init.ply" +
                              " --cameras " + g + "/cameras.json --camera " + view + " --target " +
                              g + "/images/" + view + ".png --out " + out + " --mode classic") ==
            0);
    auto got = SafeTensors::open(out);
    REQUIRE(got.is_ok());
    for (const char* name : {"color", "alpha", "loss", "l1", "ssim"}) {
      const auto d =
          test::compare(golden(*got, name), golden(*exp, std::string(view) + "." + name));
      INFO(name << " max abs " << d.max_abs);
      CHECK(d.max_abs <= 2e-3);
    }
    for (const char* name : {"means", "scales", "quats", "opacities", "sh0", "shN", "means2d"}) {
      const std::string key = std::string("grad.") + name;
      const TensorEntry* e = got->find(key);
      const TensorEntry* w = exp->find(std::string(view) + "." + key);
      REQUIRE(e != nullptr);
      REQUIRE(w != nullptr);
      CHECK(e->shape == w->shape);
      const auto d = test::compare(golden(*got, key), golden(*exp, std::string(view) + "." + key));
      INFO(key << " rel L2 " << d.rel_l2);
      CHECK(d.rel_l2 <= 1e-3);
    }
  }

  const std::string ply = tmp.file("out.ply"), log = tmp.file("log.jsonl");
  REQUIRE(test::run_command(
              test::macro_exe() + " train --quiet --images " + g + "/images" + " --cameras " + g +
              "/cameras.json --init " + g + "/init.ply" + " --out " + ply + " --log " + log +
              " --steps 10 --strategy none --lr-schedule constant"
              " --view-order sequential --sh-degree-interval 0 --scene-scale 1") == 0);
  // The .ply stores log scales, logit opacities, raw quaternions and f_dc / channel-major f_rest:
  // read_splat_params maps them back onto gsplat's tensors.
  auto trained = read_splat_params(ply);
  REQUIRE(trained.is_ok());
  check_adam_params(*trained, *exp, "adam.after10.");
  std::ifstream in(log);
  int lines = 0;
  for (std::string line; std::getline(in, line); ++lines) {
    INFO(line);
    CHECK(line.find("\"step\": " + std::to_string(lines) + ",") != std::string::npos);
    for (const char* key :
         {"\"loss\"", "\"l1\"", "\"ssim\"", "\"num_gaussians\": 300", "\"seconds\""})
      CHECK(line.find(key) != std::string::npos);
  }
  CHECK(lines == 10);

  // Progress on stderr (step, loss, it/s, ETA) unless quiet.
  const std::string err = tmp.file("err.txt");
  REQUIRE(test::run_command("env -u MACRO_QUIET " + test::macro_exe() + " train --images " + g +
                            "/images --cameras " + g + "/cameras.json --init " + g +
                            "/init.ply --out " + ply +
                            " --steps 2 --strategy none"
                            " --lr-schedule constant --view-order sequential"
                            " --sh-degree-interval 0 --scene-scale 1 >/dev/null 2>" +
                            err) == 0);
  std::ifstream ef(err);
  std::stringstream es;
  es << ef.rdbuf();
  INFO(es.str());
  for (const char* key : {"[train] step 2/2", "loss 0.3", "it/s", "eta"})
    CHECK(es.str().find(key) != std::string::npos);
}

namespace {

// A small random scene in front of a rotated camera with an off-centre principal point: some
// Gaussians outside the Jacobian clamp limits but reaching the image, some peaking above the 0.99
// alpha clamp, one behind the near plane; raw quaternions of norm != 1.
struct RandomCase {
  SplatParams params;
  TrainView view;
};
RandomCase random_case(uint32_t seed, size_t n, int degree, int width, int height) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> nd(0, 1);
  RandomCase rc;
  Camera& cam = rc.view.camera;
  cam.name = "random";
  cam.width = width;
  cam.height = height;
  cam.fx = 0.9 * width;
  cam.fy = 0.95 * width;
  cam.cx = 0.47 * width;
  cam.cy = 0.53 * height;
  const double qn = std::sqrt(1 + 0.05 * 0.05 + 0.08 * 0.08 + 0.03 * 0.03);
  cam.R = rotation_from_quaternion_wxyz(1 / qn, 0.05 / qn, -0.08 / qn, 0.03 / qn);
  cam.t = Eigen::Vector3d(0.1, -0.05, 0.2);
  SplatParams& p = rc.params;
  p.resize(n, degree);
  const size_t R = size_t(p.sh_rest());
  for (size_t i = 0; i < n; ++i) {
    // Camera-space position, then back to world space.
    const double z = 2 + 3 * u(rng);
    double rx = (u(rng) - 0.5) * 1.0, ry = (u(rng) - 0.5) * 0.8;
    double log_s = -3.2 + 1.2 * u(rng);
    if (i % 7 == 3) rx = 0.85, log_s = -0.9;   // beyond lim_x_pos = 0.755, reaching the image
    if (i % 7 == 5) ry = -0.62, log_s = -0.9;  // beyond lim_y_neg = 0.537
    Eigen::Vector3d xc(rx * z, ry * z, z);
    if (i == 1) xc = Eigen::Vector3d(0, 0, 0.005);  // in front of the camera, before near
    const Eigen::Vector3d xw = cam.R.transpose() * (xc - cam.t);
    for (int a = 0; a < 3; ++a) p.means[i * 3 + a] = float(xw(a));
    for (int a = 0; a < 3; ++a) p.scales[i * 3 + a] = float(log_s + 0.4 * nd(rng));
    for (int a = 0; a < 4; ++a) p.quats[i * 4 + a] = float(nd(rng) + (a == 0 ? 1.0 : 0.0));
    p.opacities[i] = float(i % 5 == 0 ? 6.0 : -1 + 4 * u(rng));  // 6: alpha clamped at 0.99
    for (int c = 0; c < 3; ++c) p.sh0[i * 3 + c] = float(0.8 * nd(rng));
    for (size_t j = 0; j < R * 3; ++j) p.shN[i * R * 3 + j] = float(0.3 * nd(rng));
  }
  rc.view.target.resize(size_t(width) * size_t(height) * 3);
  for (float& v : rc.view.target) v = float(0.05 + 0.9 * u(rng));  // never exactly the render
  return rc;
}

double loss_of(const SplatParams& p, const TrainView& view, ThreadPool& pool) {
  DiffRenderer r;
  DiffImage img;
  REQUIRE(r.forward(p, view.camera, {}, &img, pool).is_ok());
  auto l =
      photometric_loss(img.color.data(), view.target.data(), img.width, img.height, nullptr, pool);
  REQUIRE(l.is_ok());
  return l->loss;
}

}  // namespace

TEST_CASE("train: gradients agree with central differences for every parameter kind", "[train]") {
  ThreadPool pool(1);
  // The double reference and every float table, against central differences of the double loss.
  const auto paths = test::train_gradient_paths();
  for (int degree : {3, 0}) {
    INFO("SH degree " << degree);
    RandomCase rc = random_case(7 + uint32_t(degree), 14, degree, 32, 24);
    const std::vector<test::ParamKind> kinds = test::param_kinds(degree);
    const auto loss = [&](const SplatParams& p) { return loss_of(p, rc.view, pool); };
    std::vector<std::vector<std::array<double, 2>>> est;
    for (const test::ParamKind& k : kinds)
      est.push_back(test::fd_estimates(rc.params, k.field, loss));
    for (const auto& [path, isa] : paths) {
      INFO("path " << path);
      test::IsaGuard restore;
      REQUIRE(set_isa(isa).is_ok());
      StepGradient sg(isa == Isa::kScalar ? Precision::kDouble : Precision::kFloat);
      SplatGrads g;
      REQUIRE(sg.compute(rc.params, rc.view.camera, rc.view.target.data(), {}, &g, pool).is_ok());
      if (isa != Isa::kScalar) REQUIRE(std::string(sg.path_name()) == path);
      // Culled near-plane Gaussian 1: zero gradients. Gaussians 3, 10 (x) and 5, 12 (y) lie
      // beyond gsplat's Jacobian clamp limits (W - cx)/fx + 0.3 tan_fovx, cy/fy + 0.3 tan_fovy:
      // at least one of each pair reaches the image.
      for (int a = 0; a < 3; ++a) CHECK(g.means[3 + a] == 0.f);
      const Camera& cam = rc.view.camera;
      const double lim_x = (cam.width - cam.cx) / cam.fx + 0.3 * 0.5 * cam.width / cam.fx;
      const double lim_y = cam.cy / cam.fy + 0.3 * 0.5 * cam.height / cam.fy;
      int clamped_x = 0, clamped_y = 0;
      for (size_t i : {3, 10, 5, 12}) {
        const Eigen::Vector3d xw(rc.params.means[3 * i], rc.params.means[3 * i + 1],
                                 rc.params.means[3 * i + 2]);
        const Eigen::Vector3d xc = cam.R * xw + cam.t;
        const bool reaches = g.means2d[2 * i] != 0.f;
        clamped_x += xc(0) / xc(2) > lim_x && reaches;
        clamped_y += xc(1) / xc(2) < -lim_y && reaches;
      }
      CHECK(clamped_x >= 1);
      CHECK(clamped_y >= 1);
      double worst = 0;
      for (size_t k = 0; k < kinds.size(); ++k)
        worst = std::max(worst, test::check_fd(g.*(kinds[k].grad), est[k], kinds[k].name));
      WARN(path << " classic degree " << degree << ": worst relative error " << worst);
    }
  }
}

TEST_CASE("train: the loss gradient agrees with central differences", "[train]") {
  ThreadPool pool(1);
  const int W = 23, H = 17;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> x(size_t(W) * H * 3);
  std::vector<float> y(x.size());
  for (size_t i = 0; i < x.size(); ++i) x[i] = u(rng), y[i] = float(u(rng));
  std::vector<double> grad;
  auto l = photometric_loss(x.data(), y.data(), W, H, &grad, pool);
  REQUIRE(l.is_ok());
  CHECK(l->loss == Approx(0.8 * l->l1 + 0.2 * (1 - l->ssim)).epsilon(1e-12));
  double worst = 0;
  for (size_t i = 0; i < x.size(); i += 7) {
    const double x0 = x[i], h = 1e-6;
    x[i] = x0 + h;
    const double lp = photometric_loss(x.data(), y.data(), W, H, nullptr, pool)->loss;
    x[i] = x0 - h;
    const double lm = photometric_loss(x.data(), y.data(), W, H, nullptr, pool)->loss;
    x[i] = x0;
    worst = std::max(worst, std::abs((lp - lm) / (2 * h) - grad[i]));
  }
  INFO("worst abs error " << worst);
  CHECK(worst <= 1e-8);
  // Identical images: SSIM 1, L1 0.
  std::vector<double> same(y.begin(), y.end());
  auto s = photometric_loss(same.data(), y.data(), W, H, nullptr, pool);
  CHECK(s->ssim == Approx(1.0).epsilon(1e-12));
  CHECK(s->l1 == 0.0);
  CHECK_FALSE(photometric_loss(x.data(), y.data(), 10, 40, nullptr, pool).is_ok());
}

TEST_CASE("train: the forward is the rasterizer's render, 1 and 2 threads give identical bits",
          "[train]") {
  RandomCase rc = random_case(11, 3000, 2, 96, 72);
  auto ref = render(to_cloud(rc.params), rc.view.camera);
  REQUIRE(ref.is_ok());
  ThreadPool one(1), two(2);
  SplatGrads g1, g2;
  DiffImage i1, i2;
  {
    DiffRenderer r;
    REQUIRE(r.forward(rc.params, rc.view.camera, {}, &i1, one).is_ok());
    std::vector<double> v;
    REQUIRE(photometric_loss(i1.color.data(), rc.view.target.data(), 96, 72, &v, one).is_ok());
    r.backward(rc.params, v.data(), nullptr, &g1, one);
  }
  {
    DiffRenderer r;
    REQUIRE(r.forward(rc.params, rc.view.camera, {}, &i2, two).is_ok());
    std::vector<double> v;
    REQUIRE(photometric_loss(i2.color.data(), rc.view.target.data(), 96, 72, &v, two).is_ok());
    r.backward(rc.params, v.data(), nullptr, &g2, two);
    CHECK(r.stats().visible > 2000);
  }
  const auto color = test::compare(to_float(i1.color), ref->color);
  const auto alpha = test::compare(to_float(i1.alpha), ref->alpha);
  INFO("vs gs::render: color max abs " << color.max_abs << ", alpha max abs " << alpha.max_abs);
  CHECK(color.max_abs <= 1e-4);
  CHECK(alpha.max_abs <= 1e-4);
  CHECK(i1.color == i2.color);
  CHECK(i1.alpha == i2.alpha);
  const auto t1 = grad_tensors(g1), t2 = grad_tensors(g2);
  for (size_t k = 0; k < t1.size(); ++k) {
    INFO(t1[k].first);
    CHECK(*t1[k].second == *t2[k].second);
  }

  // Ten Adam steps: identical parameters.
  SplatParams p1 = rc.params, p2 = rc.params;
  TrainOptions options;
  options.steps = 3;
  REQUIRE(gs::train::train(&p1, {rc.view}, options, {}, one).is_ok());
  REQUIRE(gs::train::train(&p2, {rc.view}, options, {}, two).is_ok());
  const auto q1 = param_tensors(p1), q2 = param_tensors(p2);
  for (size_t k = 0; k < q1.size(); ++k) {
    INFO(q1[k].first);
    CHECK(*q1[k].second == *q2[k].second);
  }
}

TEST_CASE("train: SplatParams round-trips a .ply exactly and activates like load_scene",
          "[train]") {
  RandomCase rc = random_case(5, 40, 3, 32, 24);
  test::TempDir tmp("train-ply");
  REQUIRE(write_splat_params(rc.params, tmp.file("a.ply")).is_ok());
  auto back = read_splat_params(tmp.file("a.ply"));
  REQUIRE(back.is_ok());
  CHECK(back->sh_degree == 3);
  const auto a = param_tensors(rc.params), b = param_tensors(*back);
  for (size_t k = 0; k < a.size(); ++k) {
    INFO(a[k].first);
    CHECK(*a[k].second == *b[k].second);
  }
  auto cloud = load_scene(tmp.file("a.ply"));
  REQUIRE(cloud.is_ok());
  const GaussianCloud mine = to_cloud(*back);
  CHECK(test::compare(mine.sh, cloud->sh).max_abs == 0.0);  // f_dc / channel-major f_rest
  CHECK(test::compare(mine.position, cloud->position).max_abs == 0.0);
  CHECK(test::compare(mine.scale, cloud->scale).max_abs <= 1e-6);
  CHECK(test::compare(mine.rotation, cloud->rotation).max_abs <= 1e-6);
  CHECK(test::compare(mine.opacity, cloud->opacity).max_abs <= 1e-6);

  // Refusals name the vertex and property.
  SplatParams bad = rc.params;
  for (int a2 = 0; a2 < 4; ++a2) bad.quats[4 * 3 + a2] = 0.f;
  REQUIRE(write_splat_params(bad, tmp.file("zero-quat.ply")).is_ok());
  auto zq = read_splat_params(tmp.file("zero-quat.ply"));
  REQUIRE_FALSE(zq.is_ok());
  CHECK(zq.status().message().find("vertex 3") != std::string::npos);
  bad = rc.params;
  bad.scales[7] = NAN;
  REQUIRE(write_splat_params(bad, tmp.file("nan.ply")).is_ok());
  auto nn = read_splat_params(tmp.file("nan.ply"));
  REQUIRE_FALSE(nn.is_ok());
  CHECK(nn.status().message().find("'scale_1'") != std::string::npos);
  CHECK_FALSE(read_splat_params(tmp.file("missing.ply")).is_ok());
}

TEST_CASE("train: what is not implemented is refused by flag, bad inputs by name", "[train]") {
  if (!have_goldens()) return;
  test::TempDir tmp("train-refuse");
  const std::string g = train_dir();
  const std::string base = test::macro_exe() + " train --images " + g + "/images --cameras " + g +
                           "/cameras.json --init " + g + "/init.ply --out " + tmp.file("o.ply") +
                           " --steps 2";
  const std::string ok_flags =
      " --lr-schedule constant --view-order sequential --sh-degree-interval 0 --scene-scale 1";
  auto run = [&](const std::string& cmd) {
    const int rc =
        test::run_command(cmd + " >" + tmp.file("out.txt") + " 2>" + tmp.file("err.txt"));
    std::ifstream f(tmp.file("err.txt"));
    std::stringstream s;
    s << f.rdbuf();
    return std::make_pair(rc, s.str());
  };
  struct Case {
    std::string flags, expect;
  };
  const std::vector<Case> cases = {
      {" --strategy mcmc --cap-max 0" + ok_flags, "--cap-max"},
      {" --strategy fancy" + ok_flags, "--strategy: expected default, mcmc or none"},
      {" --strategy none --lr-schedule exponential --view-order sequential --sh-degree-interval 0",
       "--lr-schedule: expected gsplat or constant, found 'exponential'"},
      {" --strategy none --lr-schedule constant --view-order random --sh-degree-interval 0",
       "--view-order: expected shuffled or sequential, found 'random'"},
      {" --strategy none --sh-degree-interval -1", "--sh-degree-interval"},
      {" --strategy none --max-gaussians -5", "--max-gaussians: expected an integer"},
      {" --strategy none --scene-dir x" + ok_flags, "--scene-dir replaces --images and --cameras"},
      {" --strategy none --scene-scale -1 --lr-schedule constant --view-order sequential"
       " --sh-degree-interval 0",
       "--scene-scale"},
      {" --strategy mcmc --absgrad" + ok_flags,
       "--absgrad / --grow-grad2d: only with --strategy default, found --strategy mcmc"},
      {" --strategy default --grow-grad2d 0" + ok_flags, "--grow-grad2d"},
      {" --strategy default --grow-grad2d much" + ok_flags, "--grow-grad2d"},
  };
  for (const Case& c : cases) {
    INFO(c.flags);
    const auto [rc, err] = run(base + c.flags);
    CHECK(rc == 1);
    CHECK(err.find(c.expect) != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(tmp.file("o.ply")));
  }
  // A camera without a photo; a photo of the wrong size.
  std::filesystem::create_directories(tmp.file("imgs"));
  std::filesystem::copy_file(g + "/images/v0.png", tmp.file("imgs/v0.png"));
  auto [rc1, err1] = run(test::macro_exe() + " train --images " + tmp.file("imgs") + " --cameras " +
                         g + "/cameras.json --init " + g + "/init.ply --out " + tmp.file("o.ply") +
                         " --strategy none" + ok_flags);
  CHECK(rc1 == 1);
  CHECK(err1.find("no photo for camera 'v1'") != std::string::npos);
  Image small(8, 8, 3);
  REQUIRE(write_png(tmp.file("imgs/v1.png"), small).is_ok());
  auto [rc2, err2] = run(test::macro_exe() + " train --images " + tmp.file("imgs") + " --cameras " +
                         g + "/cameras.json --init " + g + "/init.ply --out " + tmp.file("o.ply") +
                         " --strategy none" + ok_flags);
  CHECK(rc2 == 1);
  CHECK(err2.find("8x8, expected the camera's 64x48") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(tmp.file("o.ply")));
  // grad: an unknown mode is refused by name; outputs only when everything succeeded.
  auto [rc3, err3] = run(test::macro_exe() + " grad --scene " + g + "/init.ply --cameras " + g +
                         "/cameras.json --camera v0 --target " + g + "/images/v0.png --out " +
                         tmp.file("g.safetensors") + " --mode fancy");
  CHECK(rc3 == 1);
  CHECK(err3.find("--mode: expected classic, antialiased or mip, found 'fancy'") !=
        std::string::npos);
  auto [rc4, err4] = run(test::macro_exe() + " grad --scene " + g + "/init.ply --cameras " + g +
                         "/cameras.json --camera v9 --target " + g + "/images/v0.png --out " +
                         tmp.file("g.safetensors"));
  CHECK(rc4 == 1);
  CHECK(err4.find("v9") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(tmp.file("g.safetensors")));
  // Distorted cameras: the photos would need undistorting first.
  auto cams = load_cameras(g + "/cameras.json");
  REQUIRE(cams.is_ok());
  cams->cameras[0].model = CameraModel::kOpenCV;
  cams->cameras[0].distortion = {0.1, 0, 0, 0};
  REQUIRE(save_cameras_json(*cams, tmp.file("distorted.json")).is_ok());
  auto [rc5, err5] = run(test::macro_exe() + " grad --scene " + g + "/init.ply --cameras " +
                         tmp.file("distorted.json") + " --camera v0 --target " + g +
                         "/images/v0.png --out " + tmp.file("g.safetensors"));
  CHECK(rc5 == 1);
  CHECK(err5.find("camera 'v0' has OPENCV distortion") != std::string::npos);
  auto [rc6, err6] = run(test::macro_exe() + " train --images " + g + "/images --cameras " +
                         tmp.file("distorted.json") + " --init " + g + "/init.ply --out " +
                         tmp.file("o.ply") + " --strategy none" + ok_flags);
  CHECK(rc6 == 1);
  CHECK(err6.find("not implemented yet") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(tmp.file("o.ply")));
}

TEST_CASE("train: macro grad on any SH degree and image size matches the library", "[train]") {
  test::TempDir tmp("train-grad");
  for (int degree : {0, 1, 2, 3}) {
    INFO("SH degree " << degree);
    RandomCase rc = random_case(20 + uint32_t(degree), 60, degree, 37, 29);
    REQUIRE(write_splat_params(rc.params, tmp.file("s.ply")).is_ok());
    CameraSet set;
    set.cameras.push_back(rc.view.camera);
    REQUIRE(save_cameras_json(set, tmp.file("cameras.json")).is_ok());
    Image target(37, 29, 3);
    target.data = rc.view.target;
    REQUIRE(write_png(tmp.file("t.png"), target).is_ok());
    auto back = read_image(tmp.file("t.png"));
    REQUIRE(back.is_ok());
    rc.view.target = back->data;  // the 8-bit values the command reads
    REQUIRE(test::run_command(test::macro_exe() + " grad --quiet --scene " + tmp.file("s.ply") +
                              " --cameras " + tmp.file("cameras.json") + " --camera random" +
                              " --target " + tmp.file("t.png") + " --out " +
                              tmp.file("g.safetensors")) == 0);
    auto got = SafeTensors::open(tmp.file("g.safetensors"));
    REQUIRE(got.is_ok());
    auto want = view_gradient(rc.params, rc.view, {});
    REQUIRE(want.is_ok());
    const int64_t N = 60, K1 = (degree + 1) * (degree + 1) - 1;
    const std::vector<std::pair<std::string, std::vector<int64_t>>> shapes = {
        {"color", {29, 37, 3}},  {"alpha", {29, 37}},     {"loss", {1}},
        {"grad.means", {N, 3}},  {"grad.scales", {N, 3}}, {"grad.quats", {N, 4}},
        {"grad.opacities", {N}}, {"grad.sh0", {N, 1, 3}}, {"grad.shN", {N, K1, 3}},
        {"grad.means2d", {N, 2}}};
    for (const auto& [name, shape] : shapes) {
      INFO(name);
      const TensorEntry* e = got->find(name);
      REQUIRE(e != nullptr);
      CHECK(e->shape == shape);
    }
    CHECK(golden(*got, "loss")[0] == float(want->loss.loss));
    for (const auto& [name, data] : grad_tensors(want->grads)) {
      INFO(name);
      CHECK(golden(*got, "grad." + name) == *data);
    }
  }
}

TEST_CASE("train: absgrad is the sum over pixels of the absolute per-pixel 2D-mean gradient",
          "[train]") {
  // The blend's dL/dmean2d is a sum of per-pixel terms, each linear in that pixel's dL/dcolor:
  // with dL/dcolor one-hot at pixel p, means2d is pixel p's term alone. So absgrad must equal
  // the sum over pixels of |means2d| of the one-hot backwards (per component).
  ThreadPool pool(1);
  RandomCase rc = random_case(13, 30, 1, 20, 14);
  DiffRenderOptions o;
  o.absgrad = true;
  DiffRenderer r;
  DiffImage img;
  REQUIRE(r.forward(rc.params, rc.view.camera, o, &img, pool).is_ok());
  std::vector<double> v_color;
  REQUIRE(photometric_loss(img.color.data(), rc.view.target.data(), img.width, img.height, &v_color,
                           pool)
              .is_ok());
  SplatGrads full;
  r.backward(rc.params, v_color.data(), nullptr, &full, pool);
  const size_t n = rc.params.size();
  REQUIRE(full.means2d_abs.size() == 2 * n);
  std::vector<double> want(2 * n, 0.0);
  std::vector<double> one_hot(v_color.size(), 0.0);
  for (size_t p = 0; p < size_t(img.width) * size_t(img.height); ++p) {
    for (int c = 0; c < 3; ++c) one_hot[3 * p + size_t(c)] = v_color[3 * p + size_t(c)];
    SplatGrads g;
    r.backward(rc.params, one_hot.data(), nullptr, &g, pool);
    for (size_t i = 0; i < 2 * n; ++i) want[i] += std::abs(double(g.means2d[i]));
    for (int c = 0; c < 3; ++c) one_hot[3 * p + size_t(c)] = 0.0;
  }
  size_t nonzero = 0, differs = 0;
  for (size_t i = 0; i < 2 * n; ++i) {
    INFO("entry " << i << ": absgrad " << full.means2d_abs[i] << ", sum of |one-hot| " << want[i]);
    CHECK(std::abs(full.means2d_abs[i] - want[i]) <= 1e-5 * std::max(1e-3, want[i]));
    nonzero += want[i] > 0;
    // |sum| <= sum |.|, and strictly below it where the pixels disagree in sign.
    CHECK(std::abs(full.means2d[i]) <= full.means2d_abs[i] * (1 + 1e-6) + 1e-12);
    differs += std::abs(full.means2d[i]) < 0.9 * full.means2d_abs[i];
  }
  CHECK(nonzero > n);
  CHECK(differs > n / 2);
  // Without the option there is no absgrad.
  DiffRenderer plain;
  REQUIRE(plain.forward(rc.params, rc.view.camera, {}, &img, pool).is_ok());
  SplatGrads g;
  plain.backward(rc.params, v_color.data(), nullptr, &g, pool);
  CHECK(g.means2d_abs.empty());
  CHECK(g.means2d == full.means2d);

  // Every float path against this twin.
  for (Isa isa : test::supported_isas()) {
    if (train_kernels_for(isa) == nullptr) continue;
    INFO("path " << isa_name(isa));
    test::IsaGuard restore;
    REQUIRE(set_isa(isa).is_ok());
    StepGradient sg(Precision::kFloat);
    SplatGrads fg;
    REQUIRE(sg.compute(rc.params, rc.view.camera, rc.view.target.data(), o, &fg, pool).is_ok());
    REQUIRE(fg.means2d_abs.size() == 2 * n);
    const auto d = test::compare(fg.means2d_abs, full.means2d_abs);
    INFO("means2d_abs rel L2 " << d.rel_l2);
    CHECK(d.rel_l2 <= 1e-4);
    StepGradient plain_sg(Precision::kFloat);
    SplatGrads pg;
    REQUIRE(
        plain_sg.compute(rc.params, rc.view.camera, rc.view.target.data(), {}, &pg, pool).is_ok());
    CHECK(pg.means2d_abs.empty());
    CHECK(pg.means2d == fg.means2d);  // absgrad changes nothing else
    CHECK(pg.means == fg.means);
  }
}
