// Tile rasterizer (gs/raster/rasterizer.h): analytic one- and two-Gaussian scenes, culling and errors,
// SIMD paths against the scalar twin, the naive baseline, thread-count determinism, and the gsplat
// goldens in golden/raster/<scene>/expected-<camera>.safetensors.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>

#include "attention/runtime/cpu.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/limits.h"
#include "gs/cameras/camera.h"
#include "gs/formats/scene_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/synth/random_scene.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;

namespace {

Camera test_camera(int w = 64, int h = 48, double f = 50.0) {
  Camera c;
  c.name = "test";
  c.width = w;
  c.height = h;
  c.fx = c.fy = f;
  c.cx = 0.5 * w + 0.5;  // the axis goes through the centre of pixel (w/2, h/2)
  c.cy = 0.5 * h + 0.5;
  return c;
}

// An isotropic Gaussian at camera-space (x, y, z), DC colour rgb, SH degree 0.
void add_gaussian(GaussianCloud& cloud, float x, float y, float z, float scale, float opacity,
                  std::array<float, 3> rgb) {
  cloud.sh_degree = 0;
  cloud.position.insert(cloud.position.end(), {x, y, z});
  cloud.scale.insert(cloud.scale.end(), {scale, scale, scale});
  cloud.rotation.insert(cloud.rotation.end(), {1.f, 0.f, 0.f, 0.f});
  cloud.opacity.push_back(opacity);
  for (float c : rgb) cloud.sh.push_back((c - 0.5f) / kShC0);
}

size_t px(const RenderResult& r, int i, int j) {
  return size_t(i) * size_t(r.width) + size_t(j);
}

RenderResult render_ok(const GaussianCloud& cloud, const Camera& cam, const RenderOptions& o = {},
                       ThreadPool& pool = ThreadPool::global()) {
  auto r = render(cloud, cam, o, pool);
  INFO(r.status().message());
  REQUIRE(r.is_ok());
  return std::move(r).value();
}

}  // namespace

TEST_CASE("raster: one Gaussian gives the analytic alpha, colour and depths", "[raster]") {
  const Camera cam = test_camera();
  GaussianCloud cloud;
  const float z = 4.f, s = 0.1f, o = 0.7f;
  add_gaussian(cloud, 0.f, 0.f, z, s, o, {0.9f, 0.4f, 0.2f});
  RenderResult r = render_ok(cloud, cam);
  REQUIRE(r.stats.visible == 1);
  const size_t c = px(r, 24, 32);  // mean exactly at this pixel centre
  CHECK(r.alpha[c] == Approx(o).margin(1e-6));
  CHECK(r.color[3 * c + 0] == Approx(0.9f * o).margin(1e-5));
  CHECK(r.color[3 * c + 1] == Approx(0.4f * o).margin(1e-5));
  CHECK(r.color[3 * c + 2] == Approx(0.2f * o).margin(1e-5));
  CHECK(r.depth_sum[c] / r.alpha[c] == Approx(z).epsilon(1e-6));
  CHECK(r.inv_depth_sum[c] == Approx(o / z).epsilon(1e-6));
  CHECK(r.expected_depth()[c] == Approx(z).epsilon(1e-6));
  // Off centre: alpha = o exp(-dx^2 / (2 (sigma^2 + 0.3))), sigma = f s / z in pixels.
  const double var = std::pow(50.0 * s / z, 2) + 0.3;
  for (int dx : {1, 2, 3}) {
    const double expect = o * std::exp(-0.5 * dx * dx / var);
    const size_t p = px(r, 24, 32 + dx);
    CHECK(r.alpha[p] == Approx(expect >= 1.0 / 255 ? expect : 0.0).margin(2e-6));
    CHECK(r.alpha[px(r, 24 - dx, 32)] == Approx(r.alpha[p]).margin(1e-6));
  }
  // Far pixels: below 1/255, nothing at all.
  CHECK(r.alpha[px(r, 0, 0)] == 0.f);
  CHECK(r.depth_sum[px(r, 47, 63)] == 0.f);
}

TEST_CASE("raster: two overlapping Gaussians blend front to back, background added", "[raster]") {
  const Camera cam = test_camera();
  GaussianCloud cloud;
  // Listed back first: the sort must put the near one in front.
  add_gaussian(cloud, 0.f, 0.f, 6.f, 0.2f, 0.5f, {0.f, 1.f, 0.f});  // back, green
  add_gaussian(cloud, 0.f, 0.f, 3.f, 0.1f, 0.6f, {1.f, 0.f, 0.f});  // front, red
  RenderOptions opt;
  opt.background = {0.1f, 0.2f, 0.3f};
  RenderResult r = render_ok(cloud, cam, opt);
  const size_t c = px(r, 24, 32);
  const float T = (1.f - 0.6f) * (1.f - 0.5f);
  CHECK(r.alpha[c] == Approx(1.f - T).margin(1e-6));
  CHECK(r.color[3 * c + 0] == Approx(0.6f + T * 0.1f).margin(1e-5));
  CHECK(r.color[3 * c + 1] == Approx(0.5f * 0.4f + T * 0.2f).margin(1e-5));
  CHECK(r.color[3 * c + 2] == Approx(T * 0.3f).margin(1e-5));
  CHECK(r.depth_sum[c] == Approx(3.f * 0.6f + 6.f * 0.2f).epsilon(1e-5));
  CHECK(r.inv_depth_sum[c] == Approx(0.6f / 3.f + 0.2f / 6.f).epsilon(1e-5));
  // Empty pixels show the background, alpha 0.
  CHECK(r.color[3 * px(r, 0, 0) + 2] == Approx(0.3f));
  CHECK(r.alpha[px(r, 0, 0)] == 0.f);
}

TEST_CASE("raster: a pixel stops before the Gaussian that would take T to 1e-4", "[raster]") {
  const Camera cam = test_camera();
  GaussianCloud cloud;
  for (int k = 0; k < 3; ++k)
    add_gaussian(cloud, 0.f, 0.f, 2.f + float(k), 0.2f, 1.f, {float(k == 0), float(k == 1), 0.f});
  RenderResult r = render_ok(cloud, cam);
  const size_t c = px(r, 24, 32);
  // First: alpha 0.99, T = 0.01. Second would give T = 1e-4 <= 1e-4: stop, not blended.
  CHECK(r.alpha[c] == Approx(0.99f).margin(1e-6));
  CHECK(r.color[3 * c + 0] == Approx(0.99f).margin(1e-6));
  CHECK(r.color[3 * c + 1] == 0.f);
  CHECK(r.depth_sum[c] == Approx(2.f * 0.99f).epsilon(1e-6));
}

TEST_CASE("raster: antialiased and mip modes scale opacity as gsplat / Mip-Splatting", "[raster]") {
  const Camera cam = test_camera();
  GaussianCloud cloud;
  const float z = 5.f, s = 0.02f, o = 0.8f;
  add_gaussian(cloud, 0.f, 0.f, z, s, o, {1.f, 1.f, 1.f});
  const double v0 = std::pow(50.0 * s / z, 2);  // 2D variance before dilation (isotropic)
  const size_t c = 24 * 64 + 32;
  RenderOptions opt;
  opt.mode = RasterMode::kAntialiased;
  RenderResult aa = render_ok(cloud, cam, opt);
  const double comp = std::sqrt(std::max(0.005 * 0.005, (v0 * v0) / ((v0 + 0.3) * (v0 + 0.3))));
  CHECK(aa.alpha[c] == Approx(o * comp).epsilon(1e-4));
  opt.mode = RasterMode::kMip;
  RenderResult mip = render_ok(cloud, cam, opt);
  const double d0 = v0 * v0, d1 = (v0 + 0.1) * (v0 + 0.1);
  const double coef = std::sqrt(d0 / (d1 + 1e-6) + 1e-6);
  CHECK(mip.alpha[c] == Approx(o * coef).epsilon(1e-4));
  // Mip's dilation is 0.1: the neighbour falls off with variance v0 + 0.1.
  CHECK(mip.alpha[px(mip, 24, 33)] / mip.alpha[c] ==
        Approx(std::exp(-0.5 / (v0 + 0.1))).epsilon(1e-4));
}

TEST_CASE("raster: SH degree 1..3 colour follows the view direction", "[raster]") {
  // One Gaussian straight ahead: dir = (0, 0, 1), so only the z-terms survive:
  // deg1 basis C1 z (k=2), deg2 C2_2 (2z^2) (k=6), deg3 C3_3 z (2z^2) (k=12).
  const Camera cam = test_camera();
  GaussianCloud cloud;
  cloud.resize(1, 3);
  cloud.position = {0.f, 0.f, 4.f};
  cloud.scale = {0.1f, 0.1f, 0.1f};
  cloud.rotation = {1.f, 0.f, 0.f, 0.f};
  cloud.opacity = {0.5f};
  for (float& v : cloud.sh) v = 0.05f;  // every coefficient of every channel
  cloud.sh[0] = 0.2f;
  RenderResult r = render_ok(cloud, cam);
  const double C0 = 0.28209479177387814, C1 = 0.4886025119029199, C22 = 0.31539156525252005,
               C33 = 0.3731763325901154;
  const double red = 0.5 + C0 * 0.2 + 0.05 * (C1 + C22 * 2.0 + C33 * 2.0);
  const double green = 0.5 + C0 * 0.05 + 0.05 * (C1 + C22 * 2.0 + C33 * 2.0);
  const size_t c = px(r, 24, 32);
  CHECK(r.color[3 * c + 0] / 0.5 == Approx(red).epsilon(1e-5));
  CHECK(r.color[3 * c + 1] / 0.5 == Approx(green).epsilon(1e-5));
  // Capped at degree 0: only the DC term.
  RenderOptions opt;
  opt.sh_degree_cap = 0;
  RenderResult r0 = render_ok(cloud, cam, opt);
  CHECK(r0.color[3 * c + 0] / 0.5 == Approx(0.5 + C0 * 0.2).epsilon(1e-5));
}

TEST_CASE("raster: invalid, hidden and faint Gaussians are culled and counted", "[raster]") {
  const Camera cam = test_camera();
  GaussianCloud cloud;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  add_gaussian(cloud, 0.f, 0.f, 4.f, 0.1f, 0.7f, {1.f, 0.f, 0.f});  // visible
  add_gaussian(cloud, nan, 0.f, 4.f, 0.1f, 0.7f, {1.f, 0.f, 0.f});  // NaN position
  add_gaussian(cloud, 0.f, 0.f, 4.f, 0.1f, 0.7f, {1.f, 0.f, 0.f});
  cloud.rotation[8] = 0.f;  // zero quaternion
  add_gaussian(cloud, 0.f, 0.f, 4.f, std::numeric_limits<float>::infinity(), 0.7f, {1, 1, 1});
  add_gaussian(cloud, 0.f, 0.f, -3.f, 0.1f, 0.7f, {1.f, 0.f, 0.f});   // behind the camera
  add_gaussian(cloud, 0.f, 0.f, 0.01f, 0.1f, 0.7f, {1.f, 0.f, 0.f});  // at the near plane
  add_gaussian(cloud, 0.f, 0.f, 4.f, 0.1f, 0.002f, {1.f, 0.f, 0.f});  // below 1/255
  add_gaussian(cloud, 100.f, 0.f, 4.f, 0.1f, 0.7f, {1.f, 0.f, 0.f});  // far off screen
  add_gaussian(cloud, 0.f, 0.f, 4.f, 1e6f, 0.7f, {0.f, 0.f, 1.f});    // huge: covers everything
  RenderResult r = render_ok(cloud, cam);
  CHECK(r.stats.visible == 2);
  CHECK(r.stats.culled_invalid == 3);
  CHECK(r.stats.culled_depth == 2);
  CHECK(r.stats.culled_faint == 1);
  CHECK(r.stats.culled_offscreen == 1);
  // The huge one is clamped to the image: every tile once.
  CHECK(r.stats.tile_pairs >= 1 + size_t(4 * 3));
  CHECK(r.stats.tile_pairs <= 4 + size_t(4 * 3));
  for (float a : r.alpha) REQUIRE(std::isfinite(a));
}

TEST_CASE("raster: bad inputs are clear errors", "[raster]") {
  GaussianCloud cloud;
  add_gaussian(cloud, 0.f, 0.f, 4.f, 0.1f, 0.7f, {1.f, 0.f, 0.f});
  Camera cam = test_camera();
  SECTION("empty scene") {
    auto r = render(GaussianCloud{}, cam);
    REQUIRE_FALSE(r.is_ok());
    CHECK_THAT(r.status().message(), Catch::Contains("no Gaussians"));
  }
  SECTION("zero-size camera") {
    cam.width = 0;
    auto r = render(cloud, cam);
    REQUIRE_FALSE(r.is_ok());
    CHECK_THAT(r.status().message(), Catch::Contains("test"));
  }
  SECTION("non-finite focal length") {
    cam.fx = std::numeric_limits<double>::infinity();
    REQUIRE_FALSE(render(cloud, cam).is_ok());
  }
  SECTION("inconsistent arrays") {
    cloud.scale.pop_back();
    auto r = render(cloud, cam);
    REQUIRE_FALSE(r.is_ok());
    CHECK_THAT(r.status().message(), Catch::Contains("scale"));
  }
  SECTION("tile-pair limit") {
    add_gaussian(cloud, 0.f, 0.f, 4.f, 1e3f, 0.7f, {1.f, 0.f, 0.f});
    RenderOptions opt;
    opt.max_tile_pairs = 5;
    auto r = render(cloud, cam, opt);
    REQUIRE_FALSE(r.is_ok());
    CHECK_THAT(r.status().message(), Catch::Contains("max_tile_pairs"));
  }
}

TEST_CASE("raster: a tile-pair default sized from too little memory refuses before binning",
          "[raster][limits]") {
  // 64 KiB available -> kMemoryFraction of it at kTilePairBytes a pair = 2730 pairs; 300
  // frame-filling Gaussians on a 64x48 camera (12 tiles) need 3600.
  const ResourceLimits saved = resource_limits();
  set_available_memory_for_testing(64 << 10);
  set_resource_limits(default_resource_limits());
  const ResourceLimits sized = resource_limits();
  RenderOptions opt;  // takes its max_tile_pairs from the sized limits
  CHECK(sized.max_tile_pairs == uint64_t((64 << 10) * kMemoryFraction) / kTilePairBytes);
  CHECK(opt.max_tile_pairs == sized.max_tile_pairs);
  GaussianCloud cloud;
  for (int k = 0; k < 300; ++k)
    add_gaussian(cloud, 0.f, 0.f, 4.f + 0.01f * k, 1e3f, 0.5f, {1.f, 1.f, 1.f});
  Rasterizer raster;
  RenderResult result;
  const Status s = raster.render_into(cloud, test_camera(), opt, &result);
  REQUIRE_FALSE(s.is_ok());
  INFO(s.message());
  CHECK_THAT(s.message(), Catch::Contains("3600 (Gaussian, tile) pairs"));
  CHECK_THAT(s.message(), Catch::Contains("memory available (a figure set for a test)"));
  CHECK_THAT(s.message(), Catch::Contains("--max-tile-pairs"));
  CHECK(result.color.empty());  // refused before the blend buffers (and the binning scratch)
  CHECK(result.stats.tile_pairs == 3600);
  set_available_memory_for_testing(0);
  set_resource_limits(saved);
  // The same scene under the default limits renders.
  CHECK(raster.render_into(cloud, test_camera(), RenderOptions{}, &result).is_ok());
}

namespace {

struct ModeCase {
  RasterMode mode;
  const char* name;
};
const ModeCase kModes[] = {{RasterMode::kClassic, "classic"},
                           {RasterMode::kAntialiased, "antialiased"},
                           {RasterMode::kMip, "mip"}};

GaussianCloud small_random_scene(const Camera& cam, size_t n, uint64_t seed) {
  RandomSceneParams p;
  p.count = n;
  p.seed = seed;
  p.log_scale_mean = -3.5f;  // a few pixels to tens of pixels at 200x150, f=150
  return random_scene(p, cam);
}

void check_outputs_close(const RenderResult& a, const RenderResult& b, double bound,
                         const char* what) {
  const std::pair<const std::vector<float>*, const std::vector<float>*> outs[] = {
      {&a.color, &b.color},
      {&a.alpha, &b.alpha},
      {&a.depth_sum, &b.depth_sum},
      {&a.inv_depth_sum, &b.inv_depth_sum}};
  const char* names[] = {"color", "alpha", "depth_sum", "inv_depth_sum"};
  for (int k = 0; k < 4; ++k) {
    REQUIRE(outs[k].first->size() == outs[k].second->size());
    test::Diff d = test::compare(*outs[k].first, *outs[k].second);
    // depth_sum is in scene units (z up to 12): compare it relative to the depth range.
    const double scale = k == 2 ? 12.0 : 1.0;
    std::printf("%s %-13s max abs %.3g, PSNR %.1f dB\n", what, names[k], d.max_abs, d.psnr);
    CHECK(d.max_abs <= bound * scale);
  }
}

}  // namespace

TEST_CASE("raster: SIMD kernels match the scalar twin", "[raster][simd]") {
  const Camera cam = bench_camera(200, 150, 150.0);
  const GaussianCloud cloud = small_random_scene(cam, 20000, 7);
  const Isa before = active_isa();
  for (const ModeCase& m : kModes) {
    RenderOptions opt;
    opt.mode = m.mode;
    REQUIRE(set_isa(Isa::kScalar).is_ok());
    RenderResult ref = render_ok(cloud, cam, opt);
    CHECK(std::string(ref.stats.kernel) == "scalar");
    for (Isa isa : {Isa::kAvx2, Isa::kAvx512}) {
      if (!isa_supported(isa)) {
        WARN("path " << isa_name(isa) << " not supported here, not tested");
        continue;
      }
      REQUIRE(set_isa(isa).is_ok());
      RenderResult r = render_ok(cloud, cam, opt);
      CHECK(std::string(r.stats.kernel) == isa_name(isa));
      // Float with a polynomial exp (rel ~2e-7) against the double-precision decisions of the
      // scalar twin: measured max abs <= 3e-7 (colour, alpha, inv_depth_sum) and 2.4e-6
      // (depth_sum) here. The bound is 1e-5 (depth_sum 1.2e-4);
      // a contribution lying exactly on the 1/255 or T-stop threshold could flip one pixel by
      // ~4e-3, which this fixed scene does not contain.
      const std::string what = std::string(m.name) + " " + isa_name(isa) + " vs scalar";
      check_outputs_close(r, ref, 1e-5, what.c_str());
      test::Diff dc = test::compare(r.color, ref.color);
      INFO(m.name << " " << isa_name(isa) << " color psnr " << dc.psnr);
      CHECK(dc.psnr >= 90.0);
      CHECK(r.stats.tile_pairs == ref.stats.tile_pairs);
      CHECK(r.stats.evals_per_pixel == ref.stats.evals_per_pixel);
      CHECK(r.stats.blended_per_pixel == Approx(ref.stats.blended_per_pixel).epsilon(1e-6));
    }
  }
  REQUIRE(set_isa(before).is_ok());
}

TEST_CASE("raster: the fast path matches the naive tiled baseline", "[raster]") {
  const Camera cam = bench_camera(200, 150, 150.0);
  const GaussianCloud cloud = small_random_scene(cam, 20000, 11);
  for (const ModeCase& m : kModes) {
    RenderOptions opt;
    opt.mode = m.mode;
    RenderResult fast = render_ok(cloud, cam, opt);
    opt.naive_baseline = true;
    RenderResult naive = render_ok(cloud, cam, opt);
    CHECK(std::string(naive.stats.kernel) == "naive");
    const std::string what = std::string(m.name) + " fast vs naive";
    check_outputs_close(fast, naive, 1e-5, what.c_str());  // measured <= 5.4e-7 (depth 1.4e-6)
    test::Diff dc = test::compare(fast.color, naive.color);
    INFO(m.name << " color psnr " << dc.psnr << ", evals/px fast " << fast.stats.evals_per_pixel
                << " naive " << naive.stats.evals_per_pixel);
    CHECK(dc.psnr >= 90.0);
    // Exact culling: fewer pairs and evaluations, the same contributions.
    CHECK(fast.stats.tile_pairs < naive.stats.tile_pairs);
    CHECK(fast.stats.evals_per_pixel < naive.stats.evals_per_pixel);
    CHECK(fast.stats.blended_per_pixel == Approx(naive.stats.blended_per_pixel).epsilon(1e-3));
  }
}

TEST_CASE("raster: bit-identical for 1 and 2 threads, and across frames", "[raster]") {
  const Camera cam = bench_camera(200, 150, 150.0);
  const GaussianCloud cloud = small_random_scene(cam, 30000, 3);
  ThreadPool one(1), two(2);
  RenderResult a = render_ok(cloud, cam, {}, one);
  Rasterizer rasterizer;
  auto b1 = rasterizer.render(cloud, cam, {}, two);
  REQUIRE(b1.is_ok());
  auto b2 = rasterizer.render(cloud, cam, {}, two);  // reused buffers
  REQUIRE(b2.is_ok());
  for (const RenderResult* b : {&b1.value(), &b2.value()}) {
    REQUIRE(a.color.size() == b->color.size());
    CHECK(std::memcmp(a.color.data(), b->color.data(), a.color.size() * 4) == 0);
    CHECK(std::memcmp(a.alpha.data(), b->alpha.data(), a.alpha.size() * 4) == 0);
    CHECK(std::memcmp(a.depth_sum.data(), b->depth_sum.data(), a.depth_sum.size() * 4) == 0);
    CHECK(std::memcmp(a.inv_depth_sum.data(), b->inv_depth_sum.data(),
                      a.inv_depth_sum.size() * 4) == 0);
    CHECK(a.stats.evals_per_pixel == b->stats.evals_per_pixel);
  }
}

namespace {

// The same Gaussians in reverse order. Rendering both orders brackets every tie: Gaussians at
// exactly the same depth are blended lower id first, and the reversed cloud flips that.
GaussianCloud reversed(const GaussianCloud& c) {
  GaussianCloud r = c;
  const size_t n = c.size(), K = size_t(c.sh_coeffs()) * 3;
  for (size_t g = 0; g < n; ++g) {
    const size_t s = n - 1 - g;
    std::copy_n(&c.position[3 * s], 3, &r.position[3 * g]);
    std::copy_n(&c.scale[3 * s], 3, &r.scale[3 * g]);
    std::copy_n(&c.rotation[4 * s], 4, &r.rotation[4 * g]);
    r.opacity[g] = c.opacity[s];
    std::copy_n(&c.sh[K * s], K, &r.sh[K * g]);
  }
  return r;
}

}  // namespace

// Goldens: all four outputs within max abs 2e-3 and PSNR >= 60 dB.
// One caveat, measured: garden-points-sh1 holds 2,323 pairs of exactly coincident Gaussians (same
// position, scale, rotation, hence same depth); 217 of them differ in colour. Their order in the
// golden is not a function of the ids (about half each way, an unstable sort), and blending two
// equal-depth splats in the other order changes colour by up to ~1e-2. alpha, depth_sum and
// inv_depth_sum do not depend on that order and are held to the bound everywhere; colour is held
// to the bound against the nearer of the two tie orders per pixel (ids ascending / descending),
// and its PSNR against our own order must still be >= 60 dB.
TEST_CASE("raster: render_into reuses buffers without stale state", "[raster]") {
  const Camera cam = bench_camera(200, 150, 150.0);
  const GaussianCloud big = small_random_scene(cam, 20000, 5);
  GaussianCloud small;
  add_gaussian(small, 0.f, 0.f, 4.f, 0.1f, 0.7f, {1.f, 0.f, 0.f});
  Rasterizer rasterizer;
  RenderResult frame;
  REQUIRE(rasterizer.render_into(big, cam, {}, &frame).is_ok());
  REQUIRE(rasterizer.render_into(small, cam, {}, &frame).is_ok());  // fewer Gaussians, same size
  RenderResult fresh = render_ok(small, cam);
  CHECK(frame.color == fresh.color);
  CHECK(frame.alpha == fresh.alpha);
  CHECK(frame.depth_sum == fresh.depth_sum);
  CHECK(frame.inv_depth_sum == fresh.inv_depth_sum);
  CHECK(frame.stats.visible == 1);
  // An error leaves a clear message and the rasterizer usable.
  Camera bad = cam;
  bad.height = -1;
  CHECK_FALSE(rasterizer.render_into(small, bad, {}, &frame).is_ok());
  REQUIRE(rasterizer.render_into(big, cam, {}, &frame).is_ok());
  CHECK(frame.stats.visible > 1000);
}

TEST_CASE("raster: gsplat goldens, every scene and camera, all four outputs", "[raster][golden]") {
  namespace fs = std::filesystem;
  const std::string root = test::golden_dir() + "/raster";
  const char* scenes[] = {"random-sh3", "garden-points-sh1"};
  int compared = 0;
  for (const char* scene : scenes) {
    const std::string dir = root + "/" + scene;
    auto cloud = load_scene(dir + "/scene.ply");
    INFO(dir << ": " << cloud.status().message());
    REQUIRE(cloud.is_ok());
    const GaussianCloud flipped = reversed(*cloud);
    auto cams = load_cameras(dir + "/cameras.json");
    INFO(cams.status().message());
    REQUIRE(cams.is_ok());
    REQUIRE(!cams->cameras.empty());
    for (const Camera& cam : cams->cameras) {
      const std::string file = dir + "/expected-" + cam.name + ".safetensors";
      REQUIRE(fs::exists(file));
      auto st = SafeTensors::open(file);
      INFO(file << ": " << st.status().message());
      REQUIRE(st.is_ok());
      RenderResult r = render_ok(*cloud, cam);
      RenderResult rf = render_ok(flipped, cam);
      const int64_t H = cam.height, W = cam.width;
      struct Out {
        const char* name;
        std::vector<int64_t> shape;
        const std::vector<float>* got;
        const std::vector<float>* got_flipped;
      } outs[] = {{"color", {H, W, 3}, &r.color, &rf.color},
                  {"alpha", {H, W}, &r.alpha, &rf.alpha},
                  {"depth_sum", {H, W}, &r.depth_sum, &rf.depth_sum},
                  {"inv_depth_sum", {H, W}, &r.inv_depth_sum, &rf.inv_depth_sum}};
      for (const Out& o : outs) {
        auto expected = st->read_f32(o.name, o.shape);
        INFO(expected.status().message());
        REQUIRE(expected.is_ok());
        test::Diff d = test::compare(*o.got, *expected);
        // Per element, the nearer of the two tie orders.
        double max_tie = 0;
        size_t tie_elems = 0;
        for (size_t i = 0; i < expected->size(); ++i) {
          const double e = (*expected)[i];
          const double a = std::abs((*o.got)[i] - e), b = std::abs((*o.got_flipped)[i] - e);
          max_tie = std::max(max_tie, std::min(a, b));
          tie_elems += (*o.got)[i] != (*o.got_flipped)[i];
        }
        const bool order_free = std::string(o.name) != "color";
        const double max_abs = order_free ? d.max_abs : max_tie;
        std::printf(
            "golden %s/%s %-13s max abs %.3g (own tie order %.3g, %zu elements differ "
            "between tie orders), PSNR %.1f dB\n",
            scene, cam.name.c_str(), o.name, max_abs, d.max_abs, tie_elems, d.psnr);
        CHECK(max_abs <= 2e-3);
        if (order_free) CHECK(d.max_abs <= 2e-3);
        CHECK(d.psnr >= 60.0);
        ++compared;
      }
    }
  }
  CHECK(compared == 4 * 6);
}
