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
#include "attention/runtime/safetensors.h"
#include "enhance/resample.h"
#include "pft_reference.h"
#include "test_support.h"

using namespace macro;
using namespace macro::nets;

namespace {

// Random weights for every tensor of `cfg`, scaled so activations stay O(1) and attention maps
// are far from uniform (the bias tables are wide), so top-k has clear winners.
test::PftWeights random_pft_weights(const PftConfig& cfg, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  test::PftWeights ws;
  for (const PftTensorSpec& s : pft_tensor_specs(cfg)) {
    if (s.name == "relative_position_index_SA") continue;
    int64_t numel = 1;
    for (int64_t v : s.shape) numel *= v;
    std::vector<float> v(static_cast<size_t>(numel));
    const auto ends = [&](const char* suf) {
      const std::string x(suf);
      return s.name.size() >= x.size() && s.name.compare(s.name.size() - x.size(), x.size(), x) == 0;
    };
    const bool norm = s.name.find("norm") != std::string::npos;
    float scale = 0.1f;
    if (ends("relative_position_bias_table")) scale = 2.0f;
    else if (norm && ends(".weight")) scale = 0.2f;
    else if (ends(".weight") && s.shape.size() >= 2) {
      int64_t fan_in = 1;
      for (size_t i = 1; i < s.shape.size(); ++i) fan_in *= s.shape[i];
      scale = float(1.5 / std::sqrt(double(fan_in)));
    }
    for (float& x : v) x = u(rng) * scale + (norm && ends(".weight") ? 1.f : 0.f);
    ws[s.name] = std::move(v);
  }
  return ws;
}

// Writes `ws` (+ the I64 index buffer) as a safetensors file; `drop`, `extra`, `reshape` make it
// wrong on purpose.
void write_pft_file(const std::string& path, const PftConfig& cfg, const test::PftWeights& ws,
                    const std::string& drop = "", bool extra = false,
                    const std::string& reshape = "", bool bad_index = false) {
  std::vector<TensorToWrite> t;
  std::vector<int64_t> rpi = pft_relative_position_index(cfg.window);
  if (bad_index) rpi[5] += 1;
  const int64_t n = int64_t(cfg.window) * cfg.window;
  std::vector<std::vector<int64_t>> shapes;
  shapes.reserve(ws.size() + 2);
  for (const PftTensorSpec& s : pft_tensor_specs(cfg)) {
    if (s.name == drop) continue;
    if (s.name == "relative_position_index_SA") {
      t.push_back({s.name, DType::kI64, {n, n}, rpi.data()});
      continue;
    }
    shapes.push_back(s.shape);
    if (s.name == reshape) shapes.back() = {int64_t(ws.at(s.name).size())};
    t.push_back({s.name, DType::kF32, shapes.back(), ws.at(s.name).data()});
  }
  static const float one = 1.f;
  if (extra) t.push_back({"layers.0.residual_group.layers.0.attn_win.logit_scale", DType::kF32, {1}, &one});
  REQUIRE(write_safetensors(path, t).is_ok());
}

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
    const std::string path = tmp.file(std::string("w") + std::to_string(sc.cfg.embed) + ".safetensors");
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
    for (int x = 0; x < 2 * 3; ++x) six[size_t(y * 6 + x)] = img[size_t((y < 3 ? y : 5 - y) * 6 + x)];
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
