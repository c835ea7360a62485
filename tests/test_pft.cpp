// PFT-SR network (attention/nets/pft.h) against the double-precision reference of the module's
// maths (tests/pft_reference.h) on small configs that drop keys, shift windows and pad, on every
// ISA path; loader errors; the released light models' tensor names and shapes; the MACRO
// upsampling loop (enhance/resample.h pft_upsample, PftSrUpsampler).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include "attention/nets/pft.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/io/safetensors.h"
#include "enhance/resample.h"
#include "pft_reference.h"
#include "test_support.h"

using namespace macro;
using namespace macro::nets;

using test::random_pft_weights;
using test::write_pft_file;

namespace {

Result<std::unique_ptr<PftNet>> load_pft(const std::string& path, const PftConfig& cfg) {
  MACRO_ASSIGN_OR_RETURN(SafeTensors st, SafeTensors::open(path));
  return PftNet::load(st, cfg);
}

std::vector<float> random_image(int h, int w, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<float> im(size_t(h) * w * 3);
  for (float& v : im) v = u(rng);
  return im;
}

// ||a - b|| / ||b - mean||: the error against the part the network adds to the mean.
double rel_err(const std::vector<float>& a, const std::vector<double>& b, const PftConfig& cfg) {
  double num = 0, den = 0;
  for (size_t i = 0; i < b.size(); ++i) {
    num += (a[i] - b[i]) * (a[i] - b[i]);
    den += (b[i] - cfg.mean[i % 3]) * (b[i] - cfg.mean[i % 3]);
  }
  return std::sqrt(num / den);
}

struct SmallCase {
  const char* name;
  PftConfig cfg;
  int h, w;
};

std::vector<SmallCase> small_cases() {
  std::vector<SmallCase> v;
  {  // x2, window 8 (n 64), dense -> dense+focus -> sparse; shifted top-24 keeps masked keys (ties)
    PftConfig c;
    c.embed = 8, c.depths = {2, 4}, c.heads = 2, c.window = 8, c.ffn_kernel = 5, c.mlp_hidden = 12;
    c.topk = {64, 64, 24, 24, 12, 10};
    c.upscale = 2;
    v.push_back({"x2 ws8", c, 13, 19});
  }
  {  // x4, window 4 (n 16), odd depths (parity by local index), top-k on the very first layer
    PftConfig c;
    c.embed = 12, c.depths = {1, 3}, c.heads = 3, c.window = 4, c.ffn_kernel = 3, c.mlp_hidden = 12;
    c.topk = {10, 6, 16, 4};
    c.upscale = 4;
    v.push_back({"x4 ws4", c, 9, 7});
  }
  {  // classic-style bias table (C > 100: one column per head), a dense chain of two maps
    PftConfig c;
    c.embed = 104, c.depths = {6}, c.heads = 2, c.window = 4, c.ffn_kernel = 3, c.mlp_hidden = 16;
    c.topk = {16, 16, 16, 16, 5, 4};
    c.upscale = 2;
    v.push_back({"x2 C104", c, 8, 6});
  }
  return v;
}

}  // namespace

TEST_CASE("pft: small configs match the double reference on every ISA path", "[pft]") {
  const Isa saved = active_isa();
  test::TempDir tmp("pft-small");
  for (const SmallCase& sc : small_cases()) {
    REQUIRE(sc.cfg.validate().is_ok());
    const test::PftWeights ws = random_pft_weights(sc.cfg, 7);
    std::string name = std::to_string(sc.cfg.embed);
    name += ".safetensors";
    const std::string path = tmp.file(name);
    write_pft_file(path, sc.cfg, ws);
    const std::vector<float> img = random_image(sc.h, sc.w, 3);
    const std::vector<double> ref = test::pft_reference_forward(sc.cfg, ws, img, sc.h, sc.w);
    for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
      if (!isa_supported(isa)) {
        std::printf("pft %s: %s not supported here, skipped\n", sc.name, isa_name(isa));
        continue;
      }
      REQUIRE(set_isa(isa).is_ok());
      auto net = load_pft(path, sc.cfg);
      REQUIRE(net.is_ok());
      auto out = (*net)->forward(img.data(), sc.h, sc.w);
      REQUIRE(out.is_ok());
      REQUIRE(out->size() == ref.size());
      const double e = rel_err(*out, ref, sc.cfg);
      std::printf("pft %-8s [%s]: rel L2 %.2e\n", sc.name, isa_name(isa), e);
      CHECK(e < 2e-5);  // fp32 vs double through 4-6 layers; a flipped top-k choice is ~1e-2
      // The calling thread alone gives the same numbers (work split never changes the maths).
      auto single = (*net)->forward(img.data(), sc.h, sc.w, nullptr);
      REQUIRE(single.is_ok());
      CHECK(*single == *out);
    }
    REQUIRE(set_isa(saved).is_ok());
  }
}

TEST_CASE("pft: images smaller than half a window are mirrored periodically", "[pft]") {
  PftConfig c = small_cases()[0].cfg;
  const test::PftWeights ws = random_pft_weights(c, 11);
  test::TempDir tmp("pft-tiny");
  write_pft_file(tmp.file("w.safetensors"), c, ws);
  auto net = load_pft(tmp.file("w.safetensors"), c);
  REQUIRE(net.is_ok());
  // 3x2 -> padded 8x8: the reference module would fail (pad > side); we keep mirroring.
  const std::vector<float> img = random_image(3, 2, 5);
  auto out = (*net)->forward(img.data(), 3, 2);
  REQUIRE(out.is_ok());
  CHECK(out->size() == size_t(6 * 4 * 3));
  for (float v : *out) CHECK(std::isfinite(v));
  // Rows 0 1 2 2 1 0 | 0 1 ...: the same padded input as the 6-row image made of the first mirror
  // (which the reference can pad itself), so the first 3 output rows agree exactly.
  std::vector<float> six(size_t(6 * 2 * 3));
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 2 * 3; ++x)
      six[size_t(y * 6 + x)] = img[size_t((y < 3 ? y : 5 - y) * 6 + x)];
  auto out6 = (*net)->forward(six.data(), 6, 2);
  REQUIRE(out6.is_ok());
  for (size_t i = 0; i < out->size(); ++i) CHECK((*out)[i] == (*out6)[i]);
  CHECK_FALSE((*net)->forward(img.data(), 0, 2).is_ok());
}

TEST_CASE("pft: loader names missing, unused, mis-shaped and wrong tensors", "[pft]") {
  const PftConfig c = small_cases()[0].cfg;
  const test::PftWeights ws = random_pft_weights(c, 1);
  test::TempDir tmp("pft-load");
  const std::string f = tmp.file("w.safetensors");
  auto expect_error = [&](const std::string& needle) {
    auto net = load_pft(f, c);
    REQUIRE_FALSE(net.is_ok());
    INFO(net.status().message());
    CHECK(net.status().message().find(needle) != std::string::npos);
    CHECK(net.status().message().find(f) != std::string::npos);
  };
  write_pft_file(f, c, ws, "layers.1.residual_group.layers.2.convffn.fc1.bias");
  expect_error("missing (layers.1.residual_group.layers.2.convffn.fc1.bias [12])");
  write_pft_file(f, c, ws, "", true);
  expect_error("unused (layers.0.residual_group.layers.0.attn_win.logit_scale)");
  write_pft_file(f, c, ws, "", false, "layers.0.residual_group.layers.1.wqkv.weight");
  expect_error("layers.0.residual_group.layers.1.wqkv.weight: expected [24,8], found [192]");
  write_pft_file(f, c, ws, "", false, "", true);
  expect_error("relative_position_index_SA: element 5");
  // An x2 file given as x4: the upsample conv's shape is named.
  write_pft_file(f, c, ws);
  PftConfig c4 = c;
  c4.upscale = 4;
  auto net = load_pft(f, c4);
  REQUIRE_FALSE(net.is_ok());
  CHECK(net.status().message().find("upsample.0.weight: expected [48,8,3,3], found [12,8,3,3]") !=
        std::string::npos);
  // Non-finite weights are refused by name.
  test::PftWeights bad = ws;
  bad["norm.bias"][1] = std::nanf("");
  write_pft_file(f, c, bad);
  expect_error("norm.bias: non-finite");
  // A bad config is an error, not a crash.
  PftConfig wrong = c;
  wrong.topk = {64, 64, 24, 24, 30, 10};  // 30 > the 24 keys parity 0 still has
  CHECK_FALSE(wrong.validate().is_ok());
}

TEST_CASE("pft: the released light x4 / x2 names and shapes, synthetic weights run", "[pft]") {
  for (int scale : {4, 2}) {
    const PftConfig c = PftConfig::light(scale);
    REQUIRE(c.validate().is_ok());
    CHECK(c.layers() == 24);
    CHECK(c.topk.size() == 24);
    CHECK(c.topk[1] == 1024);
    CHECK(c.topk[2] == 256);
    CHECK(c.topk[6] == 128);
    CHECK(c.topk[23] == 32);
    const std::vector<PftTensorSpec> specs = pft_tensor_specs(c);
    REQUIRE(specs.size() == 429);
    std::map<std::string, std::vector<int64_t>> m;
    for (const PftTensorSpec& s : specs) m[s.name] = s.shape;
    REQUIRE(m.size() == 429);
    using S = std::vector<int64_t>;
    CHECK(m.at("conv_first.weight") == S{52, 3, 3, 3});
    CHECK(m.at("relative_position_index_SA") == S{1024, 1024});
    CHECK(m.at("patch_embed.norm.weight") == S{52});
    const std::string l = "layers.4.residual_group.layers.5.";
    CHECK(m.at(l + "wqkv.weight") == S{156, 52});
    CHECK(m.at(l + "wqkv.bias") == S{156});
    CHECK(m.at(l + "v_LePE.depthwise_conv.0.weight") == S{52, 1, 7, 7});
    CHECK(m.at(l + "attn_win.relative_position_bias_table") == S{3969, 1});
    CHECK(m.at(l + "attn_win.proj.weight") == S{52, 52});
    CHECK(m.at(l + "convffn.fc1.weight") == S{52, 52});
    CHECK(m.at(l + "convffn.dwconv.depthwise_conv.0.weight") == S{52, 1, 7, 7});
    CHECK(m.at(l + "convffn.fc2.bias") == S{52});
    CHECK(m.at(l + "norm2.bias") == S{52});
    CHECK(m.count("layers.0.residual_group.layers.1.norm1.weight") == 1);
    CHECK(m.count("layers.0.residual_group.layers.2.norm1.weight") == 0);  // depth 2
    CHECK(m.at("layers.3.conv.weight") == S{52, 52, 3, 3});
    CHECK(m.at("norm.bias") == S{52});
    CHECK(m.at("conv_after_body.weight") == S{52, 52, 3, 3});
    CHECK(m.at("upsample.0.weight") == S{3 * scale * scale, 52, 3, 3});
    CHECK(m.at("upsample.0.bias") == S{3 * scale * scale});
    // Synthetic full-size weights load and run on a small image (one 32x32 window).
    const test::PftWeights ws = random_pft_weights(c, 21 + uint32_t(scale));
    test::TempDir tmp("pft-light");
    const std::string f = tmp.file("light.safetensors");
    write_pft_file(f, c, ws);
    auto net = load_pft(f, c);
    REQUIRE(net.is_ok());
    const std::vector<float> img = random_image(20, 27, 2);
    auto out = (*net)->forward(img.data(), 20, 27);
    REQUIRE(out.is_ok());
    CHECK(out->size() == size_t(20 * scale * 27 * scale * 3));
    bool finite = true;
    for (float v : *out) finite &= std::isfinite(v);
    CHECK(finite);
  }
}

// ---- the MACRO upsampling loop (enhance/resample.h) ---------------------------------------------

TEST_CASE("pft upsampling: pass scales and the stop rule", "[pft]") {
  using enhance::pft_pass_scales;
  using V = std::vector<int>;
  CHECK(pft_pass_scales(100, 60, 960, 536) == V{4, 4});       // 400x240 -> 1600x960
  CHECK(pft_pass_scales(10, 10, 960, 540) == V{4, 4, 4, 2});  // 640 > 512: then x2
  CHECK(pft_pass_scales(600, 300, 960, 536) == V{2});         // a side > 512: x2
  CHECK(pft_pass_scales(512, 512, 960, 960) == V{4});         // both <= 512: x4
  CHECK(pft_pass_scales(800, 200, 960, 900) == V{2});         // 1600 > 1500: stop short
  CHECK(pft_pass_scales(960, 536, 960, 536).empty());         // already there
  CHECK(pft_pass_scales(1000, 100, 960, 200) == V{2});        // one side short is enough
  CHECK(pft_pass_scales(1501, 10, 4000, 4000).empty());       // longer side already > 1500
}

TEST_CASE("pft upsampling: mask keeps padding black, 8-bit truncation, Lanczos to size", "[pft]") {
  // A canvas with a black band (padding) on the right; a stand-in pass that brightens everything.
  gs::Image canvas(10, 7, 3);
  for (int y = 0; y < 7; ++y)
    for (int x = 0; x < 6; ++x)
      for (int c = 0; c < 3; ++c)
        canvas.at(y, x, c) = float((y * 7 + x * 3 + c) % 200 + 20) / 255.f;
  canvas.at(3, 2, 0) = canvas.at(3, 2, 1) = canvas.at(3, 2, 2) = 0.f;  // a black pixel inside
  std::vector<std::pair<int, int>> seen;
  const enhance::SrPass pass = [&](const gs::Image& in, int s) -> Result<gs::Image> {
    seen.push_back({in.width, s});
    gs::Image out(in.width * s, in.height * s, 3);
    for (int y = 0; y < out.height; ++y)
      for (int x = 0; x < out.width; ++x)
        for (int c = 0; c < 3; ++c) out.at(y, x, c) = in.at(y / s, x / s, c) * 1.1f + 0.3f;
    return out;
  };
  gs::Image sr;
  auto out = enhance::pft_upsample(canvas, 96, 64, pass, &sr);
  REQUIRE(out.is_ok());
  CHECK(out->width == 96);
  CHECK(out->height == 64);
  REQUIRE(seen.size() == 2);  // 10x7 -> 40x28 -> 160x112
  CHECK(seen[0] == std::pair<int, int>{10, 4});
  CHECK(seen[1] == std::pair<int, int>{40, 4});
  REQUIRE(sr.width == 160);
  REQUIRE(sr.height == 112);
  for (int y = 0; y < 112; ++y)
    for (int x = 0; x < 160; ++x) {
      const bool pad = x / 16 >= 6 || (y / 16 == 3 && x / 16 == 2);
      for (int c = 0; c < 3; ++c) {
        const float v = canvas.at(y / 16, x / 16, c);
        float e = std::min(1.f, std::min(1.f, v * 1.1f + 0.3f) * 1.1f + 0.3f) * 255.f;
        e = pad ? 0.f : std::floor(e) / 255.f;  // truncation, not rounding
        if (sr.at(y, x, c) != e) FAIL("pixel " << x << "," << y << " c" << c);
      }
    }
  // The final image is Pillow's 8-bit Lanczos of that SR image.
  std::vector<uint8_t> u8(sr.data.size());
  for (size_t i = 0; i < u8.size(); ++i) u8[i] = uint8_t(std::lround(sr.data[i] * 255.f));
  const std::vector<uint8_t> want = enhance::resize_lanczos_u8(u8.data(), 160, 112, 3, 96, 64);
  for (size_t i = 0; i < want.size(); ++i) REQUIRE(out->data[i] == float(want[i]) / 255.f);
  // Far from the content the padding is still exactly black after Lanczos.
  for (int y = 0; y < 64; ++y)
    for (int x = 70; x < 96; ++x) CHECK(out->at(y, x, 0) == 0.f);
  // Already large enough: no pass, only the mask and the resize.
  seen.clear();
  auto down = enhance::pft_upsample(canvas, 8, 6, pass);
  REQUIRE(down.is_ok());
  CHECK(seen.empty());
  CHECK(down->width == 8);
  // Bad sizes are errors.
  CHECK_FALSE(enhance::pft_upsample(canvas, 0, 6, pass).is_ok());
  CHECK_FALSE(enhance::pft_upsample(gs::Image(), 8, 6, pass).is_ok());
}

TEST_CASE("pft upsampling: small networks in the loop, x4 then x2", "[pft]") {
  PftConfig c4 = small_cases()[1].cfg, c2 = small_cases()[0].cfg;  // x4 ws4, x2 ws8
  test::TempDir tmp("pft-loop");
  write_pft_file(tmp.file("x4.safetensors"), c4, random_pft_weights(c4, 3));
  write_pft_file(tmp.file("x2.safetensors"), c2, random_pft_weights(c2, 4));
  auto n4 = load_pft(tmp.file("x4.safetensors"), c4);
  auto n2 = load_pft(tmp.file("x2.safetensors"), c2);
  REQUIRE(n4.is_ok());
  REQUIRE(n2.is_ok());
  std::vector<std::pair<int, int>> seen;
  const enhance::SrPass pass = [&](const gs::Image& in, int s) -> Result<gs::Image> {
    seen.push_back({in.width, in.height});
    const PftNet& net = s == 4 ? **n4 : **n2;
    MACRO_ASSIGN_OR_RETURN(std::vector<float> y, net.forward(in.data.data(), in.height, in.width));
    gs::Image out(in.width * s, in.height * s, 3);
    out.data = std::move(y);
    return out;
  };
  // 9x6 canvas, right third black. Target 600x300: 36x24 -> 144x96 -> 576x384 -> (x2) 1152x768.
  gs::Image canvas(9, 6, 3);
  const std::vector<float> img = random_image(6, 9, 8);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 6; ++x)
      for (int ch = 0; ch < 3; ++ch) canvas.at(y, x, ch) = img[size_t((y * 9 + x) * 3 + ch)];
  gs::Image sr;
  auto out = enhance::pft_upsample(canvas, 600, 300, pass, &sr);
  REQUIRE(out.is_ok());
  const std::vector<std::pair<int, int>> want = {{9, 6}, {36, 24}, {144, 96}, {576, 384}};
  CHECK(seen == want);
  CHECK(sr.width == 1152);
  CHECK(out->width == 600);
  CHECK(out->height == 300);
  float in_max = 0.f, pad_max = 0.f;
  for (int y = 0; y < sr.height; ++y)
    for (int x = 0; x < sr.width; ++x)
      for (int ch = 0; ch < 3; ++ch) {
        float& m = x >= 6 * 128 ? pad_max : in_max;  // the canvas's black columns, x 128
        m = std::max(m, sr.at(y, x, ch));
      }
  CHECK(pad_max == 0.f);
  CHECK(in_max > 0.f);
}

TEST_CASE("pft: depthwise row kernels match the scalar twin", "[pft]") {
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  int checked = 0;
  for (Isa isa : {Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
    if (!isa_supported(isa)) continue;
    const PftDwRow kern = pft_dw_row(isa);
    for (int64_t c : {12, 52, 70}) {
      for (int k : {3, 7}) {
        const int64_t h = 9, w = 11, ldx = c + 5, ldy = c + 3;
        std::vector<float> x(size_t(h * w * ldx)), taps(size_t(k * k * c)),
            bias(static_cast<size_t>(c));
        for (float& v : x) v = u(rng);
        for (float& v : taps) v = u(rng);
        for (float& v : bias) v = u(rng);
        std::vector<float> a(size_t(h * w * ldy), 7.f), b(a);
        for (int64_t oy = 0; oy < h; ++oy) {
          pft_dw_row_scalar(a.data() + oy * w * ldy, ldy, x.data(), ldx, h, w, oy, taps.data(),
                            bias.data(), c, k);
          kern(b.data() + oy * w * ldy, ldy, x.data(), ldx, h, w, oy, taps.data(), bias.data(), c,
               k);
        }
        double worst = 0;
        for (size_t i = 0; i < a.size(); ++i) {
          if (int64_t(i % size_t(ldy)) >= c) {  // row padding is never written
            REQUIRE(b[i] == 7.f);
            continue;
          }
          worst = std::max(worst, double(std::fabs(a[i] - b[i])));
        }
        INFO(isa_name(isa) << " c " << c << " k " << k);
        CHECK(worst < 1e-5);  // |sum| <= 50: FMA vs mul+add rounding only
        ++checked;
      }
    }
  }
  std::printf("pft depthwise kernels: %d ISA/shape cases checked\n", checked);
  CHECK(checked > 0);
}

TEST_CASE("pft: A.V row kernels match the scalar twin, dense and gathered", "[pft]") {
  std::mt19937 rng(10);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  int checked = 0;
  for (Isa isa : {Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
    if (!isa_supported(isa)) continue;
    const PftAvRows kern = pft_av_rows(isa);
    for (int64_t d : {13, 4, 20}) {
      for (int kk : {37, 64}) {
        const int rows = 9, nkeys = 64;
        std::vector<float> a(size_t(rows * kk)), v(size_t(nkeys * d));
        std::vector<uint16_t> idx(size_t(rows * kk));
        for (float& x : a) x = u(rng);
        for (float& x : v) x = u(rng);
        for (uint16_t& k : idx) k = uint16_t(rng() % nkeys);
        for (const uint16_t* ip :
             {static_cast<const uint16_t*>(nullptr), static_cast<const uint16_t*>(idx.data())}) {
          if (!ip && kk > nkeys) continue;
          std::vector<float> want(size_t(rows * d)), got(size_t(rows * d) + 8, 5.f);
          pft_av_rows_scalar(want.data(), a.data(), ip, v.data(), rows, kk, d);
          kern(got.data(), a.data(), ip, v.data(), rows, kk, d);
          double worst = 0;
          for (size_t i = 0; i < want.size(); ++i)
            worst = std::max(worst, double(std::fabs(want[i] - got[i])));
          INFO(isa_name(isa) << " d " << d << " kk " << kk << (ip ? " gathered" : " dense"));
          CHECK(worst < 1e-4);  // |terms| <= 1, <= 64 of them: FMA and order rounding only
          for (size_t i = want.size(); i < got.size(); ++i) CHECK(got[i] == 5.f);  // no overrun
          ++checked;
        }
      }
    }
  }
  CHECK(checked > 0);
}
