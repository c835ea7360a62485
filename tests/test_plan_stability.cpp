// Plan stability (enhance/macro/plan_stability.h) on an analytic scene: three fronto-parallel
// bands of Gaussians seen by a 96 x 64 close-up (12 x 8 latent tokens) and three reference
// candidates. The exact depth D0 is known (far band z = 5 over columns [0, 32), middle z = 3 over
// [32, 64), near z = 2 over [64, 96): a third of the pixels each, so the quantile start of
// 3-means lands on the three disparities and every band is one plane, 0 = far).
//  - planning from a given depth: errors name the size; the render's depth given back plans
//    exactly as the render (the default path);
//  - identical depths measure exactly zero;
//  - D0 scaled by (1 + e): no token moves, each crop's scale error is the crop maths' prediction
//    (plan_stability.h), each centre error the analytic projection centroids' distance;
//  - a rectangle of the far band pushed onto the middle plane: the tokens moved are its latent
//    cells, counted by hand; scales unchanged; the near plane's crops do not move;
//  - the middle band merged into the far one (2 planes against 3): planes matched by disparity;
//  - the rendered depth against D0, loose bounds, and the JSON;
//  - macro plan --true-scene on the demo SynthClose folder, the truth being its splat scaled by
//    1 + e about the close-up's centre (every close-up depth x (1 + e), the image unchanged).
#include <catch2/catch.hpp>

#include <Eigen/Geometry>
#include <cmath>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "enhance/macro/plan_stability.h"
#include "gs/formats/scene_io.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;

namespace {

constexpr int kW = 96, kH = 64;
constexpr double kF = 80.0;
constexpr float kBandDepth[3] = {5.f, 3.f, 2.f};  // far, middle, near
constexpr int kBandCols = kW / 3;                 // 32 columns (4 latent columns) per band

gs::Camera pinhole(const std::string& name, const Eigen::Vector3d& eye, double yaw_deg) {
  gs::Camera c;
  c.name = name;
  c.width = kW;
  c.height = kH;
  c.fx = c.fy = kF;
  c.cx = 0.5 * kW + 1.5;  // off-centre: the centre ray is not the optical axis
  c.cy = 0.5 * kH - 0.5;
  const Eigen::Matrix3d r_c2w =
      Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  c.R = r_c2w.transpose();
  c.t = -c.R * eye;
  return c;
}

// A flat, opaque Gaussian facing the close-up (scale z tiny), grey.
void add_disc(gs::GaussianCloud& g, double x, double y, double z, double sigma) {
  g.position.insert(g.position.end(), {float(x), float(y), float(z)});
  g.scale.insert(g.scale.end(), {float(sigma), float(sigma), float(1e-3 * sigma)});
  g.rotation.insert(g.rotation.end(), {1.f, 0.f, 0.f, 0.f});
  g.opacity.push_back(0.98f);
  for (int c = 0; c < 3; ++c) g.sh.push_back(0.f);
}

struct BandScene {
  gs::Camera cu = pinhole("closeup", {0, 0, 0}, 0);
  SceneInputs in;
  std::vector<float> d0;  // [H,W] the exact depth
  BandScene() {
    in.closeup = cu;
    in.closeup_pose_source = "given";
    in.candidates = {pinhole("ref_axial", {0, 0, -1.0}, 0),  // straight behind the close-up
                     pinhole("ref_left", {-0.4, 0.05, -1.2}, 6),
                     pinhole("ref_right", {0.5, -0.05, -1.5}, -6)};
    // Each band: a grid of discs on z = d covering its columns exactly at the inner edges, the
    // outer edges and the rows extended by half (so the references see the bands too).
    gs::GaussianCloud& g = in.cloud;
    g.sh_degree = 0;
    for (int b = 0; b < 3; ++b) {
      const double d = kBandDepth[b], step = 0.8 * d / kF;  // 0.8 px apart in the close-up
      double x0 = (b * kBandCols - cu.cx) / kF * d, x1 = ((b + 1) * kBandCols - cu.cx) / kF * d;
      const double y0 = (-0.25 * kH - cu.cy) / kF * d, y1 = (1.25 * kH - cu.cy) / kF * d;
      if (b == 0) x0 -= 0.5 * (x1 - x0);
      if (b == 2) x1 += 0.5 * (x1 - x0);
      for (double y = y0; y <= y1; y += step)
        for (double x = x0 + 0.5 * step; x < x1; x += step) add_disc(g, x, y, d, 0.6 * step);
    }
    d0.resize(size_t(kW) * kH);
    for (int i = 0; i < kH; ++i)
      for (int j = 0; j < kW; ++j) d0[size_t(i) * kW + j] = kBandDepth[j / kBandCols];
  }
  PlanOptions options() const {
    PlanOptions o;
    o.refs = 2;
    return o;
  }
  MacroPlan plan(const std::vector<float>* depth) const {
    PlanOptions o = options();
    o.closeup_depth = depth;
    auto p = build_plan(in, o);
    INFO((p.is_ok() ? "" : p.status().message()));
    REQUIRE(p.is_ok());
    return std::move(p).value();
  }
};

// The plane (0 far .. 2 near) of a depth value of this scene.
int band_of(float z) {
  for (int b = 0; b < 3; ++b)
    if (std::abs(z - kBandDepth[b]) < 1e-3f * kBandDepth[b]) return b;
  return -1;
}

// Analytic crop centre: the mean projection into `ref` of the close-up pixels whose truth plane is
// `plane`, each unprojected at its index (j, i) (released pixel coordinates) at its depth `z`,
// kept when it lands inside the reference. plane_of[k] gives each pixel's plane.
Eigen::Vector2d centroid(const gs::Camera& cu, const std::vector<float>& z,
                         const std::vector<int>& plane_of, int plane, const gs::Camera& ref) {
  Eigen::Vector2d s(0, 0);
  int64_t n = 0;
  for (int i = 0; i < kH; ++i)
    for (int j = 0; j < kW; ++j) {
      const size_t k = size_t(i) * kW + j;
      if (plane_of[k] != plane) continue;
      const Eigen::Vector3d xc((j - cu.cx) / cu.fx * z[k], (i - cu.cy) / cu.fy * z[k], z[k]);
      const Eigen::Vector3d p = ref.project(cu.R.transpose() * (xc - cu.t));
      if (!(p.z() > 0 && p.x() >= 0 && p.x() < ref.width && p.y() >= 0 && p.y() < ref.height))
        continue;
      s += p.head<2>();
      ++n;
    }
  REQUIRE(n > 0);
  return s / double(n);
}

// The reference depth of the close-up centre ray's point at depth d (crops.h, --scale axis).
double ref_depth_of_centre(const gs::Camera& cu, const gs::Camera& ref, double d) {
  const Eigen::Vector3d xc((cu.width / 2.0 - cu.cx) / cu.fx * d,
                           (cu.height / 2.0 - cu.cy) / cu.fy * d, d);
  return ref.project(cu.R.transpose() * (xc - cu.t)).z();
}

std::vector<int> planes_of(const std::vector<float>& z) {
  std::vector<int> p(z.size());
  for (size_t k = 0; k < z.size(); ++k) p[k] = band_of(z[k]);
  return p;
}

void check_all_zero(const PlanStability& s) {
  CHECK(s.tokens_moved == 0);
  CHECK(s.pixels_moved == 0);
  CHECK(s.tokens_moved_fraction == 0.0);
  CHECK(s.scale_error_max == 0.0);
  CHECK(s.scale_error_mean == 0.0);
  CHECK(s.centre_error_max == 0.0);
  CHECK(s.centre_error_mean == 0.0);
  CHECK(s.depth_error_max == 0.0);
  CHECK(s.crops_unpaired_a == 0);
  CHECK(s.crops_unpaired_b == 0);
  CHECK(s.same_references);
  CHECK(s.planes_by_index);
}

}  // namespace

TEST_CASE("plan from a given depth: size errors, and the render's depth plans as the render",
          "[plan_stability]") {
  const BandScene sc;
  // Wrong size and bad values: errors naming what was expected and found.
  std::vector<float> small(size_t(kW) * (kH - 1), 1.f);
  PlanOptions o = sc.options();
  o.closeup_depth = &small;
  auto bad = build_plan(sc.in, o);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(),
             Catch::Contains("96x64 = 6144") && Catch::Contains("found 6048"));
  std::vector<float> nan = sc.d0;
  nan[size_t(5) * kW + 7] = NAN;
  o.closeup_depth = &nan;
  bad = build_plan(sc.in, o);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("row 5, column 7"));
  DepthView wrong{sc.cu, sc.d0};
  wrong.camera.height = kH / 2;
  auto bad_s = plan_stability(sc.in, sc.options(), wrong);
  REQUIRE_FALSE(bad_s.is_ok());
  CHECK_THAT(bad_s.status().message(), Catch::Contains("96x64") && Catch::Contains("96x32"));

  // The default plan against the plan given the render's own depth: the same plan in every field
  // (the JSON differs only by options.closeup_depth and the timings), the same masks.
  const MacroPlan a = sc.plan(nullptr);
  const MacroPlan b = sc.plan(&a.closeup_depth.depth);
  CHECK_FALSE(a.closeup_depth_given);
  CHECK(b.closeup_depth_given);
  CHECK(b.options.closeup_depth == nullptr);
  auto ja = nlohmann::json::parse(plan_to_json(a)), jb = nlohmann::json::parse(plan_to_json(b));
  CHECK_FALSE(ja["options"].contains("closeup_depth"));
  CHECK(jb["options"]["closeup_depth"] == "given");
  for (auto* j : {&ja, &jb}) {
    j->erase("timings_ms");
    (*j)["options"].erase("closeup_depth");
  }
  CHECK(ja == jb);
  REQUIRE(a.masks.masks.size() == b.masks.masks.size());
  for (size_t l = 0; l < a.masks.masks.size(); ++l)
    CHECK(a.masks.masks[l].to_dense() == b.masks.masks[l].to_dense());
  // A given depth reaches the planes and crops: D0's planes are the bands' exact depths.
  const MacroPlan t = sc.plan(&sc.d0);
  REQUIRE(t.planes.planes.size() == 3);
  for (int p = 0; p < 3; ++p) CHECK(t.planes.planes[size_t(p)].depth_median == kBandDepth[p]);
  CHECK(t.closeup_depth.depth == sc.d0);
  // The measure between the two plans from one depth is exactly zero (the library call: A from
  // the render, B from the render's depth given as the truth).
  auto s = plan_stability(sc.in, sc.options(), DepthView{sc.cu, a.closeup_depth.depth});
  REQUIRE(s.is_ok());
  check_all_zero(*s);
  CHECK(s->crops.size() == a.crops.size());
}

TEST_CASE("plan stability: identical depths measure exactly zero", "[plan_stability]") {
  const BandScene sc;
  const MacroPlan a = sc.plan(&sc.d0), b = sc.plan(&sc.d0);
  auto s = compare_plans(a, b);
  REQUIRE(s.is_ok());
  check_all_zero(*s);
  // 3 planes x 2 references, none rejected: six pairs, so the zeros above cover real crops.
  REQUIRE(a.crops.size() == 6);
  CHECK(s->crops.size() == 6);
  CHECK(s->tokens == 12 * 8);
  CHECK(s->planes_a == 3);
  CHECK(s->plane_match == std::vector<int>{0, 1, 2});
}

TEST_CASE(
    "plan stability: depth scaled by (1 + e) -> the predicted crop scale error, no token moves",
    "[plan_stability]") {
  const BandScene sc;
  const MacroPlan b = sc.plan(&sc.d0);
  REQUIRE(b.crops.size() == 6);
  const std::vector<int> bands = planes_of(sc.d0);
  for (double e : {0.25, -0.25}) {  // 1 + e exact in float: the scaled depths are exact too
    INFO("e = " << e);
    std::vector<float> scaled(sc.d0.size());
    for (size_t k = 0; k < scaled.size(); ++k) scaled[k] = float(sc.d0[k] * (1.0 + e));
    const MacroPlan a = sc.plan(&scaled);
    auto s = compare_plans(a, b);
    REQUIRE(s.is_ok());
    // Disparities all scale by 1 / (1 + e): the same labels, so nothing moves.
    CHECK(s->planes_a == 3);
    CHECK(s->tokens_moved == 0);
    CHECK(s->pixels_moved == 0);
    CHECK(s->same_references);
    REQUIRE(s->crops.size() == 6);
    CHECK(s->depth_error_max == Approx(std::abs(e)).margin(1e-12));
    double max_err = 0;
    for (const CropStability& c : s->crops) {
      const gs::Camera& ref = b.ref_cameras[size_t(c.ref_b)];
      INFO("plane " << c.plane_a << " ref " << c.reference);
      CHECK(c.plane_a == c.plane_b);
      const double d = kBandDepth[c.plane_b];
      // scale = (d_ref / d_in) (fx_cu / fx_ref) in each plan; the error of A against B.
      const double sb = ref_depth_of_centre(sc.cu, ref, d) / d * (sc.cu.fx / ref.fx);
      const double sa =
          ref_depth_of_centre(sc.cu, ref, (1 + e) * d) / ((1 + e) * d) * (sc.cu.fx / ref.fx);
      CHECK(c.scale_b == Approx(sb).epsilon(1e-12));
      CHECK(c.scale_error == Approx(std::abs(sa / sb - 1)).margin(1e-12));
      // The closed form: |e| / (1 + e) * |b| / d_ref,B, b = the reference depth at d_in = 0.
      const double b0 = ref_depth_of_centre(sc.cu, ref, 0.0);
      const double closed =
          std::abs(e) / (1 + e) * std::abs(b0) / ref_depth_of_centre(sc.cu, ref, d);
      CHECK(c.scale_error == Approx(closed).margin(1e-12));
      if (ref.name == "ref_axial")  // d_ref = d + 1: |e| / ((1 + e)(d + 1))
        CHECK(c.scale_error == Approx(std::abs(e) / ((1 + e) * (d + 1))).margin(1e-12));
      // Centres: the analytic projection centroids of the band at either depth.
      const Eigen::Vector2d ca = centroid(sc.cu, scaled, bands, c.plane_a, ref);
      const Eigen::Vector2d cb = centroid(sc.cu, sc.d0, bands, c.plane_b, ref);
      CHECK(c.centre_b_u == Approx(cb.x()).margin(1e-6));
      CHECK(c.centre_b_v == Approx(cb.y()).margin(1e-6));
      CHECK(c.centre_error == Approx((ca - cb).norm()).margin(1e-6));
      max_err = std::max(max_err, c.scale_error);
    }
    CHECK(s->scale_error_max == Approx(max_err).margin(0));
    // Every reference is behind the close-up (b > 0): the error is below the limit
    // |1 / (1 + e) - 1| and above a tenth of it at these depths.
    CHECK(s->scale_error_max < std::abs(1 / (1 + e) - 1));
    CHECK(s->scale_error_mean > 0.1 * std::abs(1 / (1 + e) - 1));
    std::printf(
        "plan stability, depth x %.2f: scale error mean %.4f max %.4f (limit %.4f), centre "
        "error mean %.2f max %.2f px\n",
        1 + e, s->scale_error_mean, s->scale_error_max, std::abs(1 / (1 + e) - 1),
        s->centre_error_mean, s->centre_error_max);
  }
}

TEST_CASE("plan stability: a rectangle pushed onto another plane moves its latent cells",
          "[plan_stability]") {
  const BandScene sc;
  // Rows [16, 40) x columns [8, 24) of the far band (z = 5) set to the middle depth (z = 3): 24 x
  // 16 px = 3 x 2 latent cells, cell-aligned. The bands then hold 1664 / 2432 / 2048 px, so the
  // quantiles 1/4, 1/2, 3/4 still fall in the far, middle and near bands: three planes.
  std::vector<float> moved = sc.d0;
  const int r0 = 16, r1 = 40, c0 = 8, c1 = 24;
  for (int i = r0; i < r1; ++i)
    for (int j = c0; j < c1; ++j) moved[size_t(i) * kW + j] = kBandDepth[1];
  const MacroPlan a = sc.plan(&moved), b = sc.plan(&sc.d0);
  auto s = compare_plans(a, b);
  REQUIRE(s.is_ok());
  REQUIRE(s->planes_a == 3);
  REQUIRE(s->planes_b == 3);
  const int64_t cells = int64_t((r1 - r0) / 8) * ((c1 - c0) / 8);  // 3 x 2 = 6
  CHECK(s->tokens_moved == cells);
  CHECK(s->tokens_moved_fraction == Approx(6.0 / 96.0).margin(1e-15));
  CHECK(s->pixels_moved == int64_t(r1 - r0) * (c1 - c0));
  // Every plane keeps its depth (one value per band): scales unchanged to the bit.
  CHECK(s->depth_error_max == 0.0);
  CHECK(s->scale_error_max == 0.0);
  REQUIRE(s->crops.size() == 6);
  const std::vector<int> pa = planes_of(moved), pb = planes_of(sc.d0);
  double max_centre = 0;
  for (const CropStability& c : s->crops) {
    INFO("plane " << c.plane_a << " ref " << c.reference);
    const gs::Camera& ref = b.ref_cameras[size_t(c.ref_b)];
    const double expect =
        (centroid(sc.cu, moved, pa, c.plane_a, ref) - centroid(sc.cu, sc.d0, pb, c.plane_b, ref))
            .norm();
    CHECK(c.centre_error == Approx(expect).margin(1e-6));
    if (c.plane_a == 2) {
      CHECK(c.centre_error == 0.0);  // the near plane's pixels are untouched
    } else {
      // 384 px left the far band (near its middle: under a pixel) and joined the middle band.
      CHECK(c.centre_error > 0.5);
    }
    max_centre = std::max(max_centre, c.centre_error);
  }
  CHECK(s->centre_error_max == max_centre);
}

TEST_CASE("plan stability: different plane counts are matched by disparity", "[plan_stability]") {
  const BandScene sc;
  // The middle band at the far depth: two distinct disparities, two of the three quantile starts
  // on the far one, so one k-means bin stays empty and A has planes {far, near}.
  std::vector<float> merged = sc.d0;
  for (int i = 0; i < kH; ++i)
    for (int j = kBandCols; j < 2 * kBandCols; ++j) merged[size_t(i) * kW + j] = kBandDepth[0];
  const MacroPlan a = sc.plan(&merged), b = sc.plan(&sc.d0);
  REQUIRE(a.planes.planes.size() == 2);
  CHECK(a.planes.dropped == 1);
  auto s = compare_plans(a, b);
  REQUIRE(s.is_ok());
  CHECK_FALSE(s->planes_by_index);
  CHECK(s->plane_match == std::vector<int>{0, 2});  // far -> far, near -> near
  CHECK(s->tokens_moved == 4 * 8);                  // the middle band's 4 x 8 cells
  CHECK(s->tokens_moved_fraction == Approx(1.0 / 3.0).margin(1e-15));
  CHECK(s->pixels_moved == int64_t(kBandCols) * kH);
  // A's crops pair with B's far and near crops; B's middle crops have no partner.
  CHECK(s->crops_a == 4);
  CHECK(s->crops_b == 6);
  CHECK(s->crops_unpaired_a == 0);
  CHECK(s->crops_unpaired_b == 2);
  REQUIRE(s->crops.size() == 4);
  CHECK(s->scale_error_max == 0.0);  // far median 5 either way, near unchanged
  for (const CropStability& c : s->crops) {
    CHECK(c.plane_b == (c.plane_a == 0 ? 0 : 2));
    if (c.plane_a == 1) CHECK(c.centre_error == 0.0);
    if (c.plane_a == 0) CHECK(c.centre_error > 1.0);
  }
}

TEST_CASE("plan stability: the rendered depth against the exact one, and the JSON",
          "[plan_stability]") {
  const BandScene sc;
  auto s = plan_stability(sc.in, sc.options(), DepthView{sc.cu, sc.d0});
  REQUIRE(s.is_ok());
  std::printf(
      "plan stability, render vs exact depth: %lld / %lld tokens moved, %lld px, scale error "
      "mean %.5f max %.5f, centre error mean %.3f max %.3f px, depth error max %.5f\n",
      (long long)s->tokens_moved, (long long)s->tokens, (long long)s->pixels_moved,
      s->scale_error_mean, s->scale_error_max, s->centre_error_mean, s->centre_error_max,
      s->depth_error_max);
  // The bands render opaque (MACRO depth = alpha-weighted z, alpha ~ 1): close to the truth, but
  // not equal to it (the measure sees the render's deviations).
  CHECK(s->planes_a == 3);
  CHECK(s->same_references);
  CHECK(s->tokens_moved_fraction <= 0.05);
  CHECK(s->pixels_moved_fraction < 0.1);
  CHECK(s->scale_error_max < 0.005);
  CHECK(s->centre_error_max < 1.5);
  CHECK(s->depth_error_max > 0);
  CHECK(s->depth_error_max < 0.01);

  // JSON: the fields carry the struct's values; the file is written atomically.
  test::TempDir tmp("plan-stability");
  REQUIRE(write_plan_stability_json(*s, tmp.file("stability.json")).is_ok());
  auto text = read_text_file(tmp.file("stability.json"));
  REQUIRE(text.is_ok());
  const auto j = nlohmann::json::parse(*text);
  CHECK(j["closeup"]["size"] == nlohmann::json::array({96, 64}));
  CHECK(j["closeup"]["latent"] == nlohmann::json::array({12, 8}));
  CHECK(j["tokens"]["moved"] == s->tokens_moved);
  CHECK(j["tokens"]["total"] == 96);
  CHECK(j["pixels"]["moved"] == s->pixels_moved);
  CHECK(j["planes"]["by_index"] == true);
  CHECK(j["planes"]["match"] == nlohmann::json::array({0, 1, 2}));
  CHECK(j["planes"]["depth"].size() == 3);
  CHECK(j["crops"]["pairs"].size() == s->crops.size());
  CHECK(j["crops"]["scale_error"]["max"].get<double>() == s->scale_error_max);
  CHECK(j["crops"]["centre_error_px"]["mean"].get<double>() == s->centre_error_mean);
  CHECK(j["references"]["same"] == true);
  CHECK(j["references"]["a"].size() == 2);
  // Plans of different close-ups are not compared.
  BandScene other;
  other.in.closeup.width = 88;
  other.in.closeup.cx -= 4;
  auto pa = build_plan(sc.in, sc.options());
  auto pb = build_plan(other.in, other.options());
  REQUIRE(pa.is_ok());
  REQUIRE(pb.is_ok());
  auto bad = compare_plans(*pa, *pb);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("96x64") && Catch::Contains("88x64"));
}

TEST_CASE("macro plan --true-scene: the splat scaled about the close-up's centre",
          "[plan_stability][cli]") {
  // Positions p -> c + (1 + e)(p - c) and sizes x (1 + e) about the close-up's centre c: every
  // Gaussian keeps its projection and footprint, so the close-up render is the same image with
  // each depth x (1 + e). The reconstruction's plan (A) is then off by 1 / (1 + e): the labels
  // stay, each crop's scale error is e |b| / d_ref,B (plan_stability.h with e' = 1 / (1 + e) - 1:
  // |e'| / (1 + e') = e).
  const std::string dir = test::source_dir() + "/data/scenes/synthclose";
  SceneInputOptions io;
  io.scene_dir = dir;
  io.closeup = "closeup.png";
  auto in = load_scene_inputs(io);
  REQUIRE(in.is_ok());
  const double e = 0.1;
  const Eigen::Vector3d c = in->closeup.center();
  gs::GaussianCloud truth = in->cloud;
  for (size_t n = 0; n < truth.size(); ++n)
    for (int a = 0; a < 3; ++a) {
      float& x = truth.position[n * 3 + size_t(a)];
      x = float(c[a] + (1 + e) * (double(x) - c[a]));
      truth.scale[n * 3 + size_t(a)] *= float(1 + e);
    }
  test::TempDir tmp("plan-stability-cli");
  REQUIRE(gs::save_scene(truth, tmp.file("gt.ply")).is_ok());
  const std::string exe = test::macro_exe(), base = exe + " plan --quiet --scene-dir " + dir +
                                                    " --closeup closeup.png --out " +
                                                    tmp.file("plan.json");
  REQUIRE(test::run_command(base + " --true-scene " + tmp.file("gt.ply") + " --stability-out " +
                            tmp.file("s.json") + " 2>" + tmp.file("err.txt")) == 0);
  auto text = read_text_file(tmp.file("s.json"));
  REQUIRE(text.is_ok());
  const auto j = nlohmann::json::parse(*text);

  // The library on the same inputs: the numbers the command wrote.
  auto gt = gs::load_scene(tmp.file("gt.ply"));
  REQUIRE(gt.is_ok());
  const PlanOptions o;
  auto depth = render_closeup_depth(*gt, in->closeup, o);
  REQUIRE(depth.is_ok());
  auto s = plan_stability(*in, o, *depth);
  REQUIRE(s.is_ok());
  CHECK(j["tokens"]["moved"] == s->tokens_moved);
  CHECK(j["crops"]["scale_error"]["max"].get<double>() == s->scale_error_max);
  CHECK(j["crops"]["pairs"].size() == s->crops.size());
  std::printf(
      "plan stability, synthclose splat x %.2f: %lld / %lld tokens moved, scale error mean "
      "%.4f max %.4f, centre error mean %.2f max %.2f px\n",
      1 + e, (long long)s->tokens_moved, (long long)s->tokens, s->scale_error_mean,
      s->scale_error_max, s->centre_error_mean, s->centre_error_max);
  // The premise: every plane depth / (1 + e), the same planes and references.
  REQUIRE(s->planes_by_index);
  CHECK(s->same_references);
  // Up to the rasteriser's parts that do not scale (the fixed 0.3 px screen-space dilation, the
  // near plane): a trained splat's many small Gaussians move the plane depths by ~2e-5.
  for (const PlaneStability& p : s->planes)
    CHECK(p.depth_error == Approx(1 - 1 / (1 + e)).margin(1e-4));
  CHECK(s->tokens_moved_fraction <= 0.01);
  // The predicted scale error per pair.
  REQUIRE(s->crops.size() >= 3);
  for (const CropStability& cs : s->crops) {
    const gs::Camera& ref = in->candidates[size_t(cs.candidate)];
    const double d_b = s->planes[size_t(cs.plane_a)].depth_b;
    const double b0 = ref_depth_of_centre(in->closeup, ref, 0.0);
    INFO("plane " << cs.plane_a << " " << cs.reference << " b " << b0);
    CHECK(cs.scale_error ==
          Approx(e * std::abs(b0) / ref_depth_of_centre(in->closeup, ref, d_b)).margin(1e-5));
  }
  CHECK(s->scale_error_max > 0);

  // Errors: one flag without the other; a missing splat named.
  CHECK(test::run_command(base + " --true-scene " + tmp.file("gt.ply") + " 2>" +
                          tmp.file("e1.txt")) == 1);
  auto e1 = read_text_file(tmp.file("e1.txt"));
  REQUIRE(e1.is_ok());
  CHECK_THAT(*e1, Catch::Contains("--stability-out"));
  CHECK(test::run_command(base + " --true-scene " + tmp.file("none.ply") + " --stability-out " +
                          tmp.file("s2.json") + " 2>" + tmp.file("e2.txt")) == 1);
  auto e2 = read_text_file(tmp.file("e2.txt"));
  REQUIRE(e2.is_ok());
  CHECK_THAT(*e2, Catch::Contains("none.ply"));
  CHECK_FALSE(file_exists(tmp.file("s2.json")));
}
