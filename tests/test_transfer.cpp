// The weight-free transfer enhancer (enhance/transfer/transfer.h): on synthetic textures with a known
// answer (GT = a random texture, render = GT blurred, sources = shifted copies of the texture),
// the transfer improves PSNR vs GT, is bit-identical for 1 and 2 threads, leaves a region with no
// match unchanged, and respects the plane mask; plus the CLI path on a synthetic scene folder.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>

#include "enhance/metrics/metrics.h"
#include "enhance/figures/side_by_side.h"
#include "enhance/transfer/transfer.h"
#include "enhance_fixture.h"
#include "gs/image_io.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;
namespace fs = std::filesystem;

namespace {

constexpr int kW = 160, kH = 112, kPad = 24;

// A colour texture [(H + 2 pad), (W + 2 pad)]: uniform noise (fixed LCG) smoothed by a 3x3 box,
// contrast about 0.1, around a per-seed base colour.
gs::Image texture(uint32_t seed, int w = kW + 2 * kPad, int h = kH + 2 * kPad) {
  gs::Image raw(w, h, 1), out(w, h, 3);
  uint32_t s = seed * 2654435761u + 12345u;
  for (float& v : raw.data) {
    s = s * 1664525u + 1013904223u;
    v = float(s >> 8) / float(1u << 24);
  }
  const float base[3] = {0.3f + 0.1f * float(seed % 3), 0.45f, 0.5f - 0.1f * float(seed % 2)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float a = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          a += raw.at(std::clamp(y + dy, 0, h - 1), std::clamp(x + dx, 0, w - 1), 0);
      a = a / 9.f - 0.5f;
      for (int c = 0; c < 3; ++c) out.at(y, x, c) = base[c] + 0.6f * a * (1.f - 0.2f * c);
    }
  return out;
}

gs::Image cut(const gs::Image& t, int y0, int x0, int w = kW, int h = kH) {
  gs::Image o(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) o.at(y, x, c) = t.at(y0 + y, x0 + x, c);
  return o;
}

// Separable Gaussian (edges clamped), the degradation of the tests' "render".
gs::Image gaussian_blur(const gs::Image& im, double sigma) {
  const int r = int(std::ceil(3 * sigma));
  std::vector<double> w(size_t(2 * r + 1));
  double sum = 0;
  for (int k = -r; k <= r; ++k) sum += w[size_t(k + r)] = std::exp(-0.5 * k * k / (sigma * sigma));
  for (double& x : w) x /= sum;
  gs::Image a = im, b = im;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      for (int c = 0; c < 3; ++c) {
        double s = 0;
        for (int k = -r; k <= r; ++k)
          s += w[size_t(k + r)] * im.at(y, std::clamp(x + k, 0, im.width - 1), c);
        a.at(y, x, c) = float(s);
      }
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      for (int c = 0; c < 3; ++c) {
        double s = 0;
        for (int k = -r; k <= r; ++k)
          s += w[size_t(k + r)] * a.at(std::clamp(y + k, 0, im.height - 1), x, c);
        b.at(y, x, c) = float(s);
      }
  return b;
}

TransferSourceImage source_of(gs::Image im, int plane) {
  TransferSourceImage s;
  s.valid.assign(im.pixels(), 1);
  s.image = std::move(im);
  s.plane = plane;
  return s;
}

double psnr_of(const gs::Image& a, const gs::Image& b) {
  auto p = psnr(a, b);
  REQUIRE(p.is_ok());
  return *p;
}

}  // namespace

TEST_CASE("transfer: detail from a shifted sharp copy raises PSNR over the blurred render",
          "[transfer]") {
  const gs::Image tex = texture(1);
  const gs::Image gt = cut(tex, kPad, kPad);
  const gs::Image render = gaussian_blur(gt, 2.0);
  std::vector<TransferSourceImage> sources;
  sources.push_back(source_of(cut(tex, kPad + 7, kPad - 5), 0));  // the same surface, shifted
  const std::vector<int32_t> labels(render.pixels(), 0);
  auto r = transfer_detail(render, labels, 1, sources, TransferParams{});
  REQUIRE(r.is_ok());
  const double before = psnr_of(render, gt), after = psnr_of(r->image, gt);
  INFO("PSNR render " << before << " dB, transfer " << after << " dB, sigma " << r->sigma[0]
                      << ", mean confidence " << r->mean_confidence << ", tokens "
                      << r->transferred);
  // The blur estimate recovers the render's blur (the source is the sharp texture).
  CHECK(r->sigma[0] == Approx(2.0).margin(0.5));
  CHECK(after > before + 1.0);
  CHECK(r->transferred > r->token_h * r->token_w / 2);
  // Sharper: the gradient energy moves towards the GT's.
  const double g_gt = gradient_energy(gt), g_r = gradient_energy(render),
               g_t = gradient_energy(r->image);
  CHECK(std::abs(std::log(g_t / g_gt)) < std::abs(std::log(g_r / g_gt)));
}

TEST_CASE("transfer: bit-identical for 1 and 2 threads", "[transfer]") {
  const gs::Image tex = texture(2);
  const gs::Image gt = cut(tex, kPad, kPad);
  const gs::Image render = gaussian_blur(gt, 1.5);
  std::vector<TransferSourceImage> sources;
  sources.push_back(source_of(cut(tex, kPad + 3, kPad + 9), 0));
  sources.push_back(source_of(cut(tex, kPad - 11, kPad + 2), 1));
  std::vector<int32_t> labels(render.pixels(), 0);
  for (int y = 0; y < kH; ++y)
    for (int x = kW / 2; x < kW; ++x) labels[size_t(y) * kW + x] = 1;
  ThreadPool one(1), two(2);
  auto a = transfer_detail(render, labels, 2, sources, TransferParams{}, one);
  auto b = transfer_detail(render, labels, 2, sources, TransferParams{}, two);
  REQUIRE(a.is_ok());
  REQUIRE(b.is_ok());
  CHECK(a->transferred > 0);
  CHECK(a->image.data == b->image.data);
  CHECK(a->confidence == b->confidence);
  CHECK(a->chosen == b->chosen);
  CHECK(a->sigma == b->sigma);
}

TEST_CASE("transfer: a region with no match in the sources is left unchanged", "[transfer]") {
  const gs::Image tex = texture(3), other = texture(4);
  // GT: left half from the texture the source holds, right half from one it does not.
  gs::Image gt = cut(tex, kPad, kPad);
  const gs::Image alien = cut(other, kPad, kPad);
  for (int y = 0; y < kH; ++y)
    for (int x = kW / 2; x < kW; ++x)
      for (int c = 0; c < 3; ++c) gt.at(y, x, c) = alien.at(y, x, c);
  const gs::Image render = gaussian_blur(gt, 2.0);
  std::vector<TransferSourceImage> sources;
  sources.push_back(source_of(cut(tex, kPad + 4, kPad + 6), 0));
  const std::vector<int32_t> labels(render.pixels(), 0);
  auto r = transfer_detail(render, labels, 1, sources, TransferParams{});
  REQUIRE(r.is_ok());
  // Tokens wholly inside the right half (windows 16 px): confidence 0, pixels untouched.
  double changed_left = 0, changed_right = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      double d = 0;
      for (int c = 0; c < 3; ++c) d += std::abs(r->image.at(y, x, c) - render.at(y, x, c));
      if (x < kW / 2 - 16) changed_left += d;
      if (x >= kW / 2 + 16) changed_right += d;
    }
  INFO("left change " << changed_left << ", right change " << changed_right);
  CHECK(changed_right == 0.0);
  CHECK(changed_left > 1.0);  // the matching half did get detail (the test can fail)
}

TEST_CASE("transfer: a token never takes detail from another plane's crop", "[transfer]") {
  // Both halves of the render show texture A; plane 0's crop holds A, plane 1's crop holds B.
  // Unmasked, plane 1's tokens would take A's detail from plane 0's crop; masked they must not.
  const gs::Image a = texture(5), b = texture(6);
  const gs::Image gt = cut(a, kPad, kPad);
  const gs::Image render = gaussian_blur(gt, 2.0);
  std::vector<int32_t> labels(render.pixels(), 0);
  for (int y = 0; y < kH; ++y)
    for (int x = kW / 2; x < kW; ++x) labels[size_t(y) * kW + x] = 1;
  std::vector<TransferSourceImage> sources;
  sources.push_back(source_of(cut(a, kPad + 5, kPad + 3), 0));
  sources.push_back(source_of(cut(b, kPad, kPad), 1));
  auto masked = transfer_detail(render, labels, 2, sources, TransferParams{});
  REQUIRE(masked.is_ok());
  const int th = masked->token_h, tw = masked->token_w;
  int plane1_tokens = 0, plane1_from_0 = 0, plane0_from_0 = 0;
  for (int i = 0; i < th; ++i)
    for (int j = 0; j < tw; ++j) {
      const int32_t c = masked->chosen[size_t(i) * tw + j];
      if (j * kTransferToken >= kW / 2) {
        ++plane1_tokens;
        plane1_from_0 += c == 0;
      } else {
        CHECK(c != 1);
        plane0_from_0 += c == 0;
      }
    }
  CHECK(plane1_tokens > 0);
  CHECK(plane1_from_0 == 0);
  CHECK(plane0_from_0 > 0);
  // Control: the same sources visible to every plane -> plane 1's tokens do use source 0.
  for (auto& s : sources) s.plane = -1;
  auto open = transfer_detail(render, labels, 2, sources, TransferParams{});
  REQUIRE(open.is_ok());
  int open_plane1_from_0 = 0;
  for (int i = 0; i < th; ++i)
    for (int j = tw / 2; j < tw; ++j) open_plane1_from_0 += open->chosen[size_t(i) * tw + j] == 0;
  CHECK(open_plane1_from_0 > 0);
}

TEST_CASE("transfer: bad inputs are errors naming the argument", "[transfer]") {
  const gs::Image render = cut(texture(7), kPad, kPad);
  std::vector<int32_t> labels(render.pixels(), 0);
  std::vector<TransferSourceImage> sources;
  sources.push_back(source_of(cut(texture(7), 0, 0, kW / 2, kH), 0));
  auto r = transfer_detail(render, labels, 1, sources, TransferParams{});
  REQUIRE_FALSE(r.is_ok());
  CHECK(r.status().message().find("source 0") != std::string::npos);
  labels[5] = 3;
  sources[0] = source_of(render, 0);
  r = transfer_detail(render, labels, 1, sources, TransferParams{});
  REQUIRE_FALSE(r.is_ok());
  CHECK(r.status().message().find("labels") != std::string::npos);
  CHECK_FALSE(parse_transfer_source("half").is_ok());
  CHECK(*parse_transfer_source("whole") == TransferSource::kWhole);
}

TEST_CASE("transfer: macro enhance --enhancer transfer writes a PNG and a side-by-side",
          "[transfer]") {
  test::TempDir tmp("macro-transfer");
  const std::string dir = test::write_synth_scene(tmp, test::tiny_scene_params());
  const std::string out = tmp.file("out.png"), sbs = tmp.file("sbs.png");
  const std::string cmd = test::macro_exe() + " enhance --quiet --scene-dir " + dir +
                          " --closeup closeup.png --enhancer transfer --out " + out +
                          " --side-by-side " + sbs + " --zoom-inset 40,20,24,16";
  REQUIRE(test::run_command(cmd) == 0);
  auto img = gs::read_image(out);
  REQUIRE(img.is_ok());
  CHECK(img->width == 128);
  CHECK(img->height == 72);
  auto side = gs::read_image(sbs);
  REQUIRE(side.is_ok());
  // render | enhanced | GT (closeup_gt/ exists) with gaps; insets and captions below the panels.
  CHECK(side->width == 2 * kFigureMargin + 3 * 128 + 2 * kFigureGap);
  CHECK(side->height > kFigureMargin + 72 + 16 * 2);
  // Without weights, transfer is the default; difix without weights is a clear error.
  REQUIRE(test::run_command(test::macro_exe() + " enhance --quiet --scene-dir " + dir +
                            " --closeup closeup.png --out " + tmp.file("default.png")) == 0);
  CHECK(fs::exists(tmp.file("default.png")));
  // The output line names the enhancer that ran, not only the method.
  // (env -u: the line is not printed under MACRO_QUIET, which CTest sets.)
  REQUIRE(test::run_command("env -u MACRO_QUIET " + test::macro_exe() + " enhance --scene-dir " +
                            dir + " --closeup closeup.png --method difix --out " + tmp.file("d.png") +
                            " > " + tmp.file("line.txt") + " 2>/dev/null") == 0);
  {
    std::ifstream f(tmp.file("line.txt"));
    std::string line((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    CHECK(line.find("method difix, enhancer transfer (weight-free),") != std::string::npos);
  }
  CHECK(test::run_command(test::macro_exe() + " enhance --quiet --scene-dir " + dir +
                          " --closeup closeup.png --enhancer difix --out " + tmp.file("difix.png") +
                          " 2>/dev/null") != 0);
  CHECK_FALSE(fs::exists(tmp.file("difix.png")));
  // A super-resolution upsampler has no effect on the transfer enhancer: refused, named.
  const std::string log = tmp.file("pft.log");
  CHECK(test::run_command(test::macro_exe() + " enhance --quiet --scene-dir " + dir +
                          " --closeup closeup.png --enhancer transfer --upsampler pft-sr --out " +
                          tmp.file("pft.png") + " 2>" + log) != 0);
  CHECK_FALSE(fs::exists(tmp.file("pft.png")));
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), {});
  CHECK(text.find("--upsampler pft-sr") != std::string::npos);
  CHECK(text.find("--enhancer difix") != std::string::npos);
}
