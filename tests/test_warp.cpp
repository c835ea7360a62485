// The backward-warp ablation (enhance/macro/warp.h).
//  - Geometry, analytically: a ray-cast scene (a textured background plane and a nearer occluding
//    square, no Gaussians) seen by a close-up and a reference with other intrinsics, size and
//    pose. Where the reference sees the point, the warp equals the close-up's ground truth (bound
//    3e-3: bilinear interpolation of a smooth texture); pixels outside the reference or
//    without depth are invalid and black; occluded pixels take the occluder's colour
//    without the test (released) and are invalid with it (paper).
//  - The method end to end on a synthetic scene folder and the tiny Difix pipeline (goldens):
//    views, masks, determinism across thread counts, the CLI.
#include <catch2/catch.hpp>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "enhance/enhance.h"
#include "enhance/macro/warp.h"
#include "enhance_fixture.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;
namespace fs = std::filesystem;

namespace {

// ---- analytic scene -----------------------------------------------------------------------------
constexpr double kBackZ = 10.0;  // background plane z = 10 (world)
constexpr double kOccZ = 6.0;    // occluding square z = 6, x in [-1.4, 0.2], y in [-0.9, 0.7]
constexpr double kOx0 = -1.4, kOx1 = 0.2, kOy0 = -0.9, kOy1 = 0.7;
const Eigen::Vector3d kOccColour(0.9, 0.1, 0.2);

Eigen::Vector3d back_colour(double x, double y) {
  return {0.5 + 0.3 * std::sin(0.9 * x + 0.3 * y), 0.5 + 0.3 * std::cos(0.7 * y),
          0.4 + 0.2 * std::sin(0.5 * (x + y))};
}

struct Hit {
  bool occluder = false;
  Eigen::Vector3d point;
  Eigen::Vector3d colour;
};

// Ray from camera c through pixel centre (j + 0.5, i + 0.5).
Hit cast(const gs::Camera& c, double j, double i) {
  const Eigen::Vector3d o = c.center();
  const Eigen::Vector3d d =
      c.R.transpose() * Eigen::Vector3d((j + 0.5 - c.cx) / c.fx, (i + 0.5 - c.cy) / c.fy, 1.0);
  Hit h;
  const double to = (kOccZ - o.z()) / d.z();
  const Eigen::Vector3d po = o + to * d;
  if (to > 0 && po.x() >= kOx0 && po.x() <= kOx1 && po.y() >= kOy0 && po.y() <= kOy1) {
    h.occluder = true;
    h.point = po;
    h.colour = kOccColour;
    return h;
  }
  h.point = o + (kBackZ - o.z()) / d.z() * d;
  h.colour = back_colour(h.point.x(), h.point.y());
  return h;
}

gs::Camera make_camera(const std::string& name, int w, int h, double f, const Eigen::Vector3d& eye,
                       double yaw_deg) {
  gs::Camera c;
  c.name = name;
  c.width = w;
  c.height = h;
  c.fx = c.fy = f;
  c.cx = 0.5 * w + 1.5;  // off-centre principal point
  c.cy = 0.5 * h - 0.5;
  const Eigen::Matrix3d r_c2w =
      Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  c.R = r_c2w.transpose();
  c.t = -c.R * eye;
  return c;
}

struct AnalyticScene {
  gs::Camera cu, ref;
  DepthView cu_depth;
  gs::Image gt, ref_image;
  std::vector<float> ref_depth;
  std::vector<uint8_t> ref_occ;       // [Hr * Wr] reference pixel sees the occluder
  static constexpr int kSkyCols = 4;  // close-up columns with depth 0 (as sky)
  AnalyticScene() {
    cu = make_camera("cu", 96, 64, 80.0, {0.0, 0.0, 0.0}, 0.0);
    ref = make_camera("ref", 120, 76, 120.0, {1.6, 0.3, -1.5}, -8.0);
    cu_depth.camera = cu;
    cu_depth.depth.assign(size_t(cu.width) * cu.height, 0.f);
    gt = gs::Image(cu.width, cu.height, 3);
    for (int i = 0; i < cu.height; ++i)
      for (int j = 0; j < cu.width; ++j) {
        const Hit h = cast(cu, j, i);
        for (int c = 0; c < 3; ++c) gt.at(i, j, c) = float(h.colour[c]);
        if (j >= kSkyCols)
          cu_depth.depth[size_t(i) * cu.width + j] = float(cu.project(h.point).z());
      }
    ref_image = gs::Image(ref.width, ref.height, 3);
    ref_depth.assign(size_t(ref.width) * ref.height, 0.f);
    ref_occ.assign(ref_depth.size(), 0);
    for (int i = 0; i < ref.height; ++i)
      for (int j = 0; j < ref.width; ++j) {
        const Hit h = cast(ref, j, i);
        for (int c = 0; c < 3; ++c) ref_image.at(i, j, c) = float(h.colour[c]);
        ref_depth[size_t(i) * ref.width + j] = float(ref.project(h.point).z());
        ref_occ[size_t(i) * ref.width + j] = h.occluder;
      }
  }
  // Close-up pixel -> reference (u, v, z) through its depth (independent of warp.cpp's algebra).
  Eigen::Vector3d to_ref(int i, int j) const {
    const double z = cu_depth.depth[size_t(i) * cu.width + j];
    const Eigen::Vector3d xc((j + 0.5 - cu.cx) / cu.fx * z, (i + 0.5 - cu.cy) / cu.fy * z, z);
    return ref.project(cu.R.transpose() * (xc - cu.t));
  }
  // The four bilinear taps of (u, v) are inside the reference and all see `occluder`.
  bool taps_all(const Eigen::Vector3d& p, bool occluder) const {
    const int x0 = int(std::floor(p.x() - 0.5)), y0 = int(std::floor(p.y() - 0.5));
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx) {
        const int x = x0 + dx, y = y0 + dy;
        if (x < 0 || y < 0 || x >= ref.width || y >= ref.height) return false;
        if (bool(ref_occ[size_t(y) * ref.width + x]) != occluder) return false;
      }
    return true;
  }
};

}  // namespace

TEST_CASE("warp geometry: analytic plane scene, visible = GT, out of view and no depth invalid",
          "[warp]") {
  const AnalyticScene s;
  ThreadPool two(2);
  auto w = backward_warp(s.cu_depth, s.ref_image, s.ref, nullptr, kOcclusionTolerance, two);
  REQUIRE(w.is_ok());
  auto wo = backward_warp(s.cu_depth, s.ref_image, s.ref, &s.ref_depth, kOcclusionTolerance, two);
  REQUIRE(wo.is_ok());
  REQUIRE(w->image.width == s.cu.width);
  REQUIRE(w->image.height == s.cu.height);
  int64_t n_vis = 0, n_out = 0, n_sky = 0, n_occ = 0, n_mismatch = 0, n_valid = 0;
  double max_err = 0;
  for (int i = 0; i < s.cu.height; ++i)
    for (int j = 0; j < s.cu.width; ++j) {
      const size_t k = size_t(i) * s.cu.width + j;
      const bool valid = w->valid[k], valid_occ = wo->valid[k];
      n_valid += valid;
      auto pixel_is = [&](const gs::Image& im, const Eigen::Vector3d& c, double tol) {
        for (int ch = 0; ch < 3; ++ch)
          if (std::fabs(im.at(i, j, ch) - c[ch]) > tol) return false;
        return true;
      };
      if (j < AnalyticScene::kSkyCols) {  // no depth: invalid, black
        ++n_sky;
        CHECK_FALSE(valid);
        CHECK_FALSE(valid_occ);
        CHECK(pixel_is(w->image, Eigen::Vector3d::Zero(), 0));
        continue;
      }
      const Eigen::Vector3d p = s.to_ref(i, j);
      const bool inside =
          p.z() > 0 && p.x() >= 0 && p.x() < s.ref.width && p.y() >= 0 && p.y() < s.ref.height;
      n_mismatch += valid != inside;  // released validity: in front and inside, nothing else
      if (!inside) {
        ++n_out;
        CHECK_FALSE(valid_occ);
        CHECK(pixel_is(w->image, Eigen::Vector3d::Zero(), 0));
        CHECK(pixel_is(wo->image, Eigen::Vector3d::Zero(), 0));
        continue;
      }
      const Hit cu_hit = cast(s.cu, j, i);
      const Hit ref_hit = cast(s.ref, p.x() - 0.5, p.y() - 0.5);  // the ray through (u, v)
      const bool seen = (ref_hit.point - cu_hit.point).norm() < 1e-6;
      if (seen && s.taps_all(p, cu_hit.occluder)) {
        // Visible: the warp equals the close-up's ground truth, with and without the test.
        ++n_vis;
        CHECK(valid_occ);
        Eigen::Vector3d gt(s.gt.at(i, j, 0), s.gt.at(i, j, 1), s.gt.at(i, j, 2));
        for (int ch = 0; ch < 3; ++ch) {
          max_err = std::max(max_err, double(std::fabs(w->image.at(i, j, ch) - gt[ch])));
          max_err = std::max(max_err, double(std::fabs(wo->image.at(i, j, ch) - gt[ch])));
        }
      } else if (!seen && !cu_hit.occluder && ref_hit.occluder && s.taps_all(p, true)) {
        // Occluded in the reference: released takes the occluder's colour; the test drops it.
        ++n_occ;
        CHECK(valid);
        CHECK(pixel_is(w->image, kOccColour, 1e-6));
        CHECK_FALSE(valid_occ);
        CHECK(pixel_is(wo->image, Eigen::Vector3d::Zero(), 0));
      }
    }
  std::printf(
      "warp geometry: %lld visible (max |warp - GT| %.2e), %lld occluded, %lld outside, "
      "%lld without depth, %lld valid\n",
      (long long)n_vis, max_err, (long long)n_occ, (long long)n_out, (long long)n_sky,
      (long long)n_valid);
  CHECK(n_mismatch == 0);
  CHECK(n_valid == w->valid_pixels);
  CHECK(max_err < 3e-3);
  // Each category is well populated, so the checks above mean something.
  CHECK(n_vis > 2000);
  CHECK(n_occ > 50);
  CHECK(n_out > 50);
  CHECK(n_sky == int64_t(AnalyticScene::kSkyCols) * s.cu.height);

  // Thread-count invariant, and bad inputs are errors naming what is wrong.
  ThreadPool one(1);
  auto w1 = backward_warp(s.cu_depth, s.ref_image, s.ref, &s.ref_depth, kOcclusionTolerance, one);
  REQUIRE(w1.is_ok());
  CHECK(w1->image.data == wo->image.data);
  CHECK(w1->valid == wo->valid);
  gs::Image small(10, 10, 3);
  auto bad = backward_warp(s.cu_depth, small, s.ref);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("'ref'") && Catch::Contains("120x76"));
  std::vector<float> short_depth(5);
  auto bad2 = backward_warp(s.cu_depth, s.ref_image, s.ref, &short_depth);
  REQUIRE_FALSE(bad2.is_ok());
  CHECK_THAT(bad2.status().message(), Catch::Contains("depth"));
}

// ---- the method on the tiny pipeline -----------------------------------------------------------
namespace {

constexpr int kW = test::kTinyW, kH = test::kTinyH;

struct TinyFolder : test::TinyEnhanceFolder {
  TinyFolder() : TinyEnhanceFolder("macro-warp") {}
};

}  // namespace

TEST_CASE("warp views: one warp per reference in bin-major order, masks over its validity",
          "[warp]") {
  TinyFolder f;
  const SceneInputs in = f.inputs();
  PlanOptions po;
  auto plan = build_plan(in, po);
  REQUIRE(plan.is_ok());
  REQUIRE(!plan->crops.empty());
  ThreadPool two(2);
  auto wv = build_warp_views(*plan, in, WarpOptions{}, two);
  INFO((wv.is_ok() ? "" : wv.status().message()));
  REQUIRE(wv.is_ok());
  REQUIRE(wv->images.size() == 1 + plan->crops.size());
  REQUIRE(wv->validity.size() == wv->images.size());
  for (const gs::Image& im : wv->images) {
    CHECK(im.width == plan->model.w);
    CHECK(im.height == plan->model.h);
    for (float v : im.data) REQUIRE((v >= 0.f && v <= 1.f));
  }
  // Views of the same reference hold the same warp, whatever their plane (the bin mask is
  // ignored); the released validity is a real subset of the frame.
  for (size_t a = 0; a < plan->crops.size(); ++a) {
    for (size_t b = a + 1; b < plan->crops.size(); ++b)
      if (plan->crops[a].ref == plan->crops[b].ref) {
        CHECK(wv->images[1 + a].data == wv->images[1 + b].data);
        CHECK(wv->validity[1 + a] == wv->validity[1 + b]);
      }
    size_t nv = 0;
    for (uint8_t v : wv->validity[1 + a]) nv += v;
    CHECK(nv > 0);
    // Invalid pixels were zeroed before the resize: far from any valid pixel they stay black.
  }
  for (double fr : wv->valid_fraction) CHECK((fr > 0.0 && fr <= 1.0));
  // Masks: one per U-Net level over V views, equal to the dense rule on the warp validities.
  REQUIRE(wv->masks.masks.size() == size_t(kUNetLevels));
  for (size_t l = 0; l < wv->masks.masks.size(); ++l) {
    const BlockSparseMask& m = wv->masks.masks[l];
    REQUIRE(m.validate().is_ok());
    const int N = wv->masks.grids[l].tokens();
    CHECK(m.nq == N * int(wv->images.size()));
    const auto dense = build_level_mask_dense(po.mask, N, wv->masks.closeup_plane[l],
                                              wv->masks.crop_plane, wv->masks.crop_valid[l]);
    CHECK(m.to_dense() == dense);
  }
  // The occlusion option keeps fewer (or as many) valid pixels.
  WarpOptions occ;
  occ.occlusion = true;
  auto wo = build_warp_views(*plan, in, occ, two);
  REQUIRE(wo.is_ok());
  for (size_t r = 0; r < wo->valid_fraction.size(); ++r)
    CHECK(wo->valid_fraction[r] <= wv->valid_fraction[r]);
  // Tight crops do not apply to the warp.
  MacroPlan tight = *plan;
  tight.options.crops.crop = CropMode::kTight;
  auto refused = build_warp_views(tight, in, WarpOptions{}, two);
  REQUIRE_FALSE(refused.is_ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("--crop full"));
}

TEST_CASE("enhance warp: runs on the tiny pipeline, thread-count invariant, differs from macro",
          "[warp][enhance]") {
  TinyFolder f;
  const SceneInputs in = f.inputs();
  EnhanceOptions o;
  o.weights = f.pipe;
  o.ctx_path = f.ctx;
  o.method = EnhanceMethod::kWarp;
  const test::OneAndTwoThreads r = test::enhance_on_1_and_2_threads(in, o);
  const EnhanceResult* a = &r.one;
  const EnhanceResult* b = &r.two;
  CHECK(a->image.width == kW);
  CHECK(a->image.height == kH);
  CHECK(a->views >= 2);
  CHECK(a->masked_levels == kUNetLevels);
  for (float v : a->image.data) REQUIRE((std::isfinite(v) && v >= 0.f && v <= 1.f));
  CHECK(a->image.data == b->image.data);
  o.method = EnhanceMethod::kMacro;
  auto m = enhance_closeup(in, o);
  REQUIRE(m.is_ok());
  CHECK(m->views == a->views);  // the same (plane, reference) views, other images
  double d = 0;
  for (size_t i = 0; i < m->image.data.size(); ++i)
    d += std::fabs(m->image.data[i] - a->image.data[i]);
  CHECK(d > 0);

  // CLI: --method warp needs the Difix weights (the message names the download, or the Difix
  // enhancer when the weight-free one is the default), and runs with them.
  const std::string base = test::macro_exe() + " enhance --quiet --scene-dir " + f.scene_dir +
                           " --closeup closeup.png --method warp";
  const std::string out = f.tmp.file("warp.png");
  CHECK(test::run_command(base + " --out " + out + " 2>" + f.tmp.file("err.txt")) == 1);
  auto err = read_text_file(f.tmp.file("err.txt"));
  REQUIRE(err.is_ok());
  CHECK_THAT(*err, Catch::Contains("difix"));
  CHECK_FALSE(fs::exists(out));
  REQUIRE(test::run_command(base + " --weights " + f.pipe + " --ctx " + f.ctx +
                            " --occlusion --threads 2 --out " + out) == 0);
  auto img = gs::read_image(out);
  REQUIRE(img.is_ok());
  CHECK(img->width == kW);
  CHECK(img->height == kH);
}
