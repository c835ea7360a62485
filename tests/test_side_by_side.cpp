// enhance/figures/side_by_side.h and enhance/side_by_side.h: panel positions and gaps, caption
// text in the caption strips, zoom insets copied pixel for pixel (nearest neighbour) from the
// source, the metric caption, and the --zoom-inset checks (library and CLI).
#include <catch2/catch.hpp>

#include <filesystem>
#include <random>

#include "enhance/figures/side_by_side.h"
#include "enhance/side_by_side.h"
#include "tests/cli_run.h"
#include "tests/test_support.h"

namespace macro::enhance {
namespace {

gs::Image solid(int w, int h, float r, float g, float b) {
  gs::Image img(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) img.at(y, x, 0) = r, img.at(y, x, 1) = g, img.at(y, x, 2) = b;
  return img;
}

// Random 8-bit values (exact through the figure's 8-bit surface).
gs::Image noise(int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  gs::Image img(w, h, 3);
  for (float& v : img.data) v = float(rng() % 256) / 255.f;
  return img;
}

bool is_white(const gs::Image& img, int y, int x) {
  return img.at(y, x, 0) == 1.f && img.at(y, x, 1) == 1.f && img.at(y, x, 2) == 1.f;
}

size_t ink_in(const gs::Image& img, const PixelRect& r) {
  size_t n = 0;
  for (int y = r.y; y < r.y + r.h; ++y)
    for (int x = r.x; x < r.x + r.w; ++x) n += !is_white(img, y, x);
  return n;
}

}  // namespace

TEST_CASE("side-by-side: panels in a row with gaps, captions under each", "[figures]") {
  const gs::Image a = solid(64, 40, 1, 0, 0), b = solid(64, 40, 0, 1, 0),
                  c = solid(64, 40, 0, 0, 1);
  auto fig = compose_side_by_side({{&a, "3DGS render", {"PSNR 19.26 dB"}},
                                   {&b, "enhanced: transfer", {"PSNR 19.30 dB"}},
                                   {&c, "ground truth", {}}});
  REQUIRE(fig.is_ok());
  const gs::Image& img = fig->image;
  const SideBySideLayout& L = fig->layout;
  REQUIRE(L.panels.size() == 3);
  CHECK(img.width == 2 * kFigureMargin + 3 * 64 + 2 * kFigureGap);
  const float colours[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int k = 0; k < 3; ++k) {
    INFO("panel " << k);
    const PixelRect& p = L.panels[size_t(k)];
    CHECK(p.x == kFigureMargin + k * (64 + kFigureGap));
    CHECK(p.y == kFigureMargin);
    CHECK(p.w == 64);
    for (int y : {p.y, p.y + p.h - 1})
      for (int x : {p.x, p.x + p.w - 1})
        for (int ch = 0; ch < 3; ++ch) CHECK(img.at(y, x, ch) == colours[k][ch]);
    if (k < 2)  // the gap after the panel is background
      for (int x = p.x + p.w; x < p.x + p.w + kFigureGap; ++x) CHECK(is_white(img, p.y + 5, x));
    // The caption strip under the panel holds text (dark pixels), the margin left of it none.
    const PixelRect& cap = L.captions[size_t(k)];
    CHECK(cap.y >= p.y + p.h);
    CHECK(cap.y + cap.h <= img.height);
    CHECK(ink_in(img, cap) > 40);
  }
  CHECK(L.inset_scale == 0);
  // Without caption text the strips are empty (the check above can fail).
  auto blank = compose_side_by_side({{&a, "", {}}, {&b, "", {}}});
  REQUIRE(blank.is_ok());
  CHECK(ink_in(blank->image, blank->layout.captions[0]) == 0);
  // A longer title shrinks to fit its own panel: no ink in the gap beside the caption.
  auto longer = compose_side_by_side(
      {{&a, "a very long title that would not fit a sixty-four pixel panel", {}}, {&b, "b", {}}});
  REQUIRE(longer.is_ok());
  const PixelRect& cap0 = longer->layout.captions[0];
  CHECK(ink_in(longer->image, {cap0.x + cap0.w + 1, cap0.y, kFigureGap - 2, cap0.h}) == 0);
  // Bad panels.
  const gs::Image small = solid(32, 40, 1, 1, 1);
  auto mismatch = compose_side_by_side({{&a, "a", {}}, {&small, "b", {}}});
  REQUIRE_FALSE(mismatch.is_ok());
  CHECK(mismatch.status().message().find("32x40x3, expected 64x40x3") != std::string::npos);
  CHECK_FALSE(compose_side_by_side({}).is_ok());
}

TEST_CASE("side-by-side: zoom insets copy the source pixel for pixel (nearest)", "[figures]") {
  const gs::Image a = noise(96, 64, 1), b = noise(96, 64, 2);
  const std::vector<PixelRect> insets = {{10, 8, 12, 9}, {70, 40, 20, 16}};
  auto fig = compose_side_by_side({{&a, "a", {"x"}}, {&b, "b", {"y"}}}, insets);
  REQUIRE(fig.is_ok());
  const SideBySideLayout& L = fig->layout;
  // The largest integer scale that fits: width (96 - 2*2*2 - 8) / 32 = 2, height (64 - 4) / 16.
  CHECK(L.inset_scale == 2);
  const gs::Image* src[2] = {&a, &b};
  for (int k = 0; k < 2; ++k)
    for (size_t i = 0; i < insets.size(); ++i) {
      INFO("panel " << k << " inset " << i);
      const PixelRect& r = insets[i];
      const PixelRect& d = L.insets[size_t(k)][i];
      REQUIRE(d.w == r.w * L.inset_scale);
      REQUIRE(d.h == r.h * L.inset_scale);
      CHECK(d.y >= L.panels[size_t(k)].y + L.panels[size_t(k)].h);  // below the panel
      CHECK(d.x >= L.panels[size_t(k)].x);
      CHECK(d.x + d.w <= L.panels[size_t(k)].x + L.panels[size_t(k)].w);
      size_t wrong = 0;
      for (int y = 0; y < d.h; ++y)
        for (int x = 0; x < d.w; ++x)
          for (int c = 0; c < 3; ++c)
            wrong += fig->image.at(d.y + y, d.x + x, c) !=
                     src[k]->at(r.y + y / L.inset_scale, r.x + x / L.inset_scale, c);
      CHECK(wrong == 0);
      // The frames lie outside: the panel's pixels inside the outlined region are untouched.
      const PixelRect& p = L.panels[size_t(k)];
      for (int y = 0; y < r.h; ++y)
        for (int x = 0; x < r.w; ++x)
          wrong +=
              fig->image.at(p.y + r.y + y, p.x + r.x + x, 1) != src[k]->at(r.y + y, r.x + x, 1);
      CHECK(wrong == 0);
      // ... and the outline is drawn just outside it, in the inset's colour (not the source's).
      CHECK(fig->image.at(p.y + r.y - 1, p.x + r.x + 2, 0) != src[k]->at(r.y - 1, r.x + 2, 0));
    }
  // The caption of each panel still comes below its insets.
  CHECK(L.captions[0].y >= L.insets[0][1].y + L.insets[0][1].h);
}

TEST_CASE("side-by-side: --zoom-inset parsing and checks name the flag", "[figures]") {
  auto ok = parse_inset_rect("10,20,30,40", "--zoom-inset");
  REQUIRE(ok.is_ok());
  CHECK((ok->x == 10 && ok->y == 20 && ok->w == 30 && ok->h == 40));
  for (const char* bad : {"", "1,2,3", "1,2,3,4,5", "a,b,c,d", "-1,2,3,4", "1,2,0,4", "1, 2,3,4",
                          "1,2,3,4x", "99999999,1,1,1"}) {
    INFO(bad);
    auto r = parse_inset_rect(bad, "--zoom-inset");
    REQUIRE_FALSE(r.is_ok());
    CHECK(r.status().message().rfind("--zoom-inset: expected x,y,w,h", 0) == 0);
    CHECK(r.status().message().find(std::string("found '") + bad + "'") != std::string::npos);
  }
  CHECK(check_insets({{0, 0, 36, 26}}, 40, 30, "--zoom-inset").is_ok());
  // Inside, but its framed copy cannot fit under the panel.
  CHECK(check_insets({{0, 0, 40, 30}}, 40, 30, "--zoom-inset").message().find("do not fit") !=
        std::string::npos);
  const Status out = check_insets({{30, 10, 20, 5}}, 40, 30, "--zoom-inset");
  REQUIRE_FALSE(out.is_ok());
  CHECK(out.message() ==
        "--zoom-inset 30,10,20,5: the rectangle [30, 50) x [10, 15) is not inside the 40x30 "
        "close-up");
  const Status wide = check_insets({{0, 0, 30, 5}, {0, 10, 30, 5}}, 40, 30, "--zoom-inset");
  REQUIRE_FALSE(wide.is_ok());
  CHECK(wide.message().find("do not fit side by side") != std::string::npos);
}

TEST_CASE("side-by-side: the metric caption prints only computed metrics", "[figures]") {
  std::vector<MetricValue> v(3);
  v[0] = {"psnr", true, 19.256, "dB", ""};
  v[1] = {"ssim", true, 0.3789, "", ""};
  v[2] = {"lpips_alex", false, 0, "", "backbone missing"};
  CHECK(metrics_caption(v) == "PSNR 19.26 dB  \u00b7  SSIM 0.379");
  v[2].computed = true, v[2].value = 0.25;
  CHECK(metrics_caption(v) == "PSNR 19.26 dB  \u00b7  SSIM 0.379  \u00b7  LPIPS 0.250");
  v[0].value = INFINITY;
  CHECK(metrics_caption(v).rfind("PSNR inf", 0) == 0);
  CHECK(metrics_caption({}).empty());
}

TEST_CASE("side-by-side: macro enhance --zoom-inset is checked before any work", "[figures][cli]") {
  namespace fs = std::filesystem;
  test::TempDir tmp("sbs-cli");
  const std::string scene = test::source_dir() + "/data/scenes/synthclose";
  const std::string base = "enhance --scene-dir " + scene + " --closeup closeup_01.png --out " +
                           tmp.file("e.png") + " --side-by-side " + tmp.file("s.png");
  test::Run r = test::run_macro(base + " --zoom-inset 10,10,5", tmp);
  CHECK(r.rc == 1);
  CHECK(r.err.find("--zoom-inset: expected x,y,w,h") != std::string::npos);
  r = test::run_macro(base + " --zoom-inset 600,300,64,64", tmp);  // the close-up is 640x360
  CHECK(r.rc == 1);
  CHECK(r.err.find("--zoom-inset 600,300,64,64: the rectangle [600, 664) x [300, 364) is not "
                   "inside the 640x360 close-up") != std::string::npos);
  CHECK(r.err.find("[enhance] render") == std::string::npos);  // failed before rendering
  r = test::run_macro("enhance --scene-dir " + scene + " --closeup closeup_01.png --out " +
                          tmp.file("e.png") + " --zoom-inset 1,1,8,8",
                      tmp);
  CHECK(r.rc == 1);
  CHECK(r.err.find("--zoom-inset: only with --side-by-side") != std::string::npos);
  CHECK_FALSE(fs::exists(tmp.file("e.png")));
  CHECK_FALSE(fs::exists(tmp.file("s.png")));
}

}  // namespace macro::enhance
