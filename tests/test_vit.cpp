// The Vision Transformer (attention/nets/vit.*) against a double-precision reference written here
// from the maths (vit.h), on small configs covering every option: LayerScale, norm_pre, CLIP proj,
// QuickGELU, no qkv/patch bias, no final norm, another token grid (pos-embed resampling).
// Legend: D width, T tokens, p patch, gh x gw token grid.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "attention/nets/vit.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/io/safetensors.h"
#include "test_support.h"
#include "vit_reference.h"

using namespace macro;
using namespace macro::nets;

namespace {

using Weights = std::map<std::string, OverrideTensor>;

const std::vector<float>& w(const Weights& ws, const std::string& name) {
  auto it = ws.find(name);
  if (it == ws.end()) FAIL("reference: no tensor " << name);
  return it->second.values;
}

// vit_reference.h's double forward on a weight map. pos: the (resampled) pos_embed [T, D] to add.
test::VitRefOut reference_forward(const VitConfig& cfg, const Weights& ws,
                                  const std::vector<float>& image, int64_t h, int64_t wd,
                                  const std::vector<float>& pos) {
  return test::vit_reference_forward(
      cfg, [&](const std::string& name) -> const std::vector<float>& { return w(ws, name); },
      std::vector<double>(image.begin(), image.end()), h, wd, pos);
}

// Binds parameters straight from a weight map (no file).
struct MapVisitor : ParamVisitor {
  const Weights& ws;
  std::vector<std::string> missing;
  explicit MapVisitor(const Weights& w) : ws(w) {}
  void param(const std::string& name, Param& p, const std::vector<int64_t>& shape) override {
    auto it = ws.find(name);
    if (it == ws.end() || it->second.shape != shape) {
      missing.push_back(name);
      return;
    }
    p.data = it->second.values.data();
    p.shape = shape;
  }
};

std::vector<float> random_image(int64_t h, int64_t wd, uint32_t seed) {
  std::vector<float> img(size_t(3 * h * wd));
  uint32_t s = seed;
  for (float& v : img) {
    s = s * 1664525u + 1013904223u;
    v = float(s >> 8) / float(1 << 24) * 4.0f - 2.0f;  // normalised-image range
  }
  return img;
}

double rel_err(const std::vector<float>& got, const std::vector<double>& want) {
  double se = 0, ref = 0;
  for (size_t i = 0; i < want.size(); ++i) {
    se += std::pow(double(got[i]) - want[i], 2);
    ref += want[i] * want[i];
  }
  return std::sqrt(se / std::max(ref, 1e-300));
}

double max_rel(const std::vector<float>& got, const std::vector<double>& want) {
  double mx = 0, scale = 0;
  for (size_t i = 0; i < want.size(); ++i) {
    mx = std::max(mx, std::abs(double(got[i]) - want[i]));
    scale = std::max(scale, std::abs(want[i]));
  }
  return mx / std::max(scale, 1e-300);
}

VitConfig small_config() {
  VitConfig c;
  c.width = 32;
  c.depth = 2;
  c.heads = 2;
  c.mlp_hidden = 64;
  c.patch = 4;
  c.grid_h = 3;  // 12 x 16 images
  c.grid_w = 4;
  return c;
}

struct Variant {
  const char* name;
  VitConfig cfg;
};

std::vector<Variant> variants() {
  std::vector<Variant> v;
  VitConfig dino = small_config();  // DINOv2-like: GELU, LayerScale, final norm
  v.push_back({"dinov2-like", dino});
  VitConfig clip = small_config();  // CLIP-like: QuickGELU, ln_pre, proj, no patch bias
  clip.layer_scale = false;
  clip.act = VitAct::kQuickGelu;
  clip.norm_pre = true;
  clip.patch_bias = false;
  clip.proj_dim = 24;
  clip.ln_eps = 1e-5f;
  clip.prefix = "visual.";
  v.push_back({"clip-like", clip});
  VitConfig bare = small_config();  // no qkv bias, no final norm, 4 heads, 3 blocks
  bare.qkv_bias = false;
  bare.final_norm = false;
  bare.heads = 4;
  bare.depth = 3;
  v.push_back({"bare", bare});
  return v;
}

std::vector<float> stored_pos(const Weights& ws, const VitConfig& cfg) {
  return w(ws, cfg.prefix + "pos_embed");
}

}  // namespace

TEST_CASE("vit: forward matches the double reference for every option and ISA path", "[vit]") {
  const Isa saved = active_isa();
  const int64_t h = 12, wd = 16;
  const std::vector<float> image = random_image(h, wd, 7);
  for (const Variant& var : variants()) {
    const Weights ws = vit_random_weights(var.cfg, 11);
    const test::VitRefOut ref =
        reference_forward(var.cfg, ws, image, h, wd, stored_pos(ws, var.cfg));
    for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
      if (!isa_supported(isa)) {
        std::printf("vit %s: %s not supported here, skipped\n", var.name, isa_name(isa));
        continue;
      }
      REQUIRE(set_isa(isa).is_ok());
      auto model = VitModel::build(var.cfg);
      REQUIRE(model.is_ok());
      MapVisitor mv(ws);
      (*model)->visit(mv);
      INFO(var.name << " [" << isa_name(isa) << "] missing: " << mv.missing.size());
      REQUIRE(mv.missing.empty());
      (*model)->pack(Precision::kF32);
      auto out = (*model)->forward(image.data(), h, wd, &ThreadPool::global(), true);
      REQUIRE(out.is_ok());
      REQUIRE(out->cls.size() == size_t(var.cfg.out_dim()));
      REQUIRE(out->tokens.size() == ref.tokens.size());
      const double e_cls = max_rel(out->cls, ref.cls), e_tok = rel_err(out->tokens, ref.tokens);
      std::printf("vit %-11s [%s]: cls max rel %.2e, tokens rel L2 %.2e\n", var.name, isa_name(isa),
                  e_cls, e_tok);
      CHECK(e_cls < 1e-5);
      CHECK(e_tok < 1e-5);
      // CLS only (no token output): the same CLS, bit for bit.
      auto cls_only = (*model)->forward(image.data(), h, wd, nullptr);
      REQUIRE(cls_only.is_ok());
      CHECK(cls_only->tokens.empty());
      CHECK(cls_only->cls == out->cls);
    }
  }
  REQUIRE(set_isa(saved).is_ok());
}

TEST_CASE("vit: bf16 precision stays near the fp32 reference", "[vit]") {
  const VitConfig cfg = variants()[0].cfg;
  const Weights ws = vit_random_weights(cfg, 5);
  const std::vector<float> image = random_image(12, 16, 3);
  const test::VitRefOut ref = reference_forward(cfg, ws, image, 12, 16, stored_pos(ws, cfg));
  auto model = VitModel::build(cfg);
  REQUIRE(model.is_ok());
  MapVisitor mv(ws);
  (*model)->visit(mv);
  REQUIRE(mv.missing.empty());
  (*model)->pack(Precision::kBf16);
  auto out = (*model)->forward(image.data(), 12, 16, nullptr);
  REQUIRE(out.is_ok());
  const double e = rel_err(out->cls, ref.cls);
  std::printf("vit bf16: cls rel L2 %.2e\n", e);
  CHECK(e < 3e-2);
  CHECK(e > 0);  // really ran in bf16
}

TEST_CASE("vit: pos-embed resampling matches hand-computed torch bicubic values", "[vit]") {
  // One row [0, 1] -> 4 columns (h 1 -> 1 is the identity).
  const float src[2] = {0.f, 1.f};
  float dst[4];
  // antialias=False: Keys a = -0.75, source x = (o + 0.5) / 2 - 0.5, clamped taps. By hand:
  // o=0: x=-0.25, t=0.75, only tap 3 (index 1) sees the 1: W(1.25) = -0.10546875;
  // o=1: x=0.25, t=0.25: W(0.75) + W(1.75) = 0.26171875 - 0.03515625 = 0.2265625; symmetric.
  resample_pos_grid(src, 1, 2, dst, 1, 4, 1, false);
  CHECK(dst[0] == Approx(-0.10546875).margin(1e-7));
  CHECK(dst[1] == Approx(0.2265625).margin(1e-7));
  CHECK(dst[2] == Approx(0.7734375).margin(1e-7));
  CHECK(dst[3] == Approx(1.10546875).margin(1e-7));
  // antialias=True (timm's default): Keys a = -0.5, centre (o + 0.5) / 2, taps [0, 2) with the
  // weights renormalised. o=0: w0 = W(0.25) = 0.8671875, w1 = W(1.25) = -0.0703125 -> w1 / sum =
  // -0.0882352941; o=1: w0 = W(0.25), w1 = W(0.75) = 0.2265625 -> 0.2071428571.
  resample_pos_grid(src, 1, 2, dst, 1, 4, 1, true);
  CHECK(dst[0] == Approx(-0.0703125 / 0.796875).margin(1e-7));
  CHECK(dst[1] == Approx(0.2265625 / 1.09375).margin(1e-7));
  CHECK(dst[2] == Approx(1.0 - 0.2265625 / 1.09375).margin(1e-7));
  CHECK(dst[3] == Approx(1.0 + 0.0703125 / 0.796875).margin(1e-7));
  // Downsampling with antialias: 4 -> 2, scale 2, support 4, weights W(|i - c + 0.5| / 2), centre
  // 1 for o=0: taps 0..3 at x = 0.25, 0.25, 0.75, 1.25 -> 0.8671875, 0.8671875, 0.2265625,
  // -0.0703125 (sum 1.890625).
  const float src4[4] = {1.f, 2.f, 4.f, 8.f};
  float dst2[2];
  resample_pos_grid(src4, 1, 4, dst2, 1, 2, 1, true);
  CHECK(dst2[0] ==
        Approx((0.8671875 * 1 + 0.8671875 * 2 + 0.2265625 * 4 - 0.0703125 * 8) / 1.890625)
            .margin(1e-6));
  // Same grid: the identity in both modes.
  float same[2];
  for (bool aa : {false, true}) {
    resample_pos_grid(src, 1, 2, same, 1, 2, 1, aa);
    CHECK(same[0] == 0.f);
    CHECK(same[1] == 1.f);
  }
  // 2-D layout [h, w, D]: the weights sum to 1, so a + b (a per row, b per column, per channel)
  // resamples to resample(a) + resample(b).
  const int64_t h0 = 3, w0 = 4, h1 = 5, w1 = 2, d = 2;
  std::vector<float> grid(size_t(h0 * w0 * d)), out(size_t(h1 * w1 * d));
  const float a[3] = {0.5f, -1.f, 2.f}, b[4] = {1.f, 0.f, -2.f, 3.f};
  for (int64_t y = 0; y < h0; ++y)
    for (int64_t x = 0; x < w0; ++x)
      for (int64_t c = 0; c < d; ++c) grid[size_t((y * w0 + x) * d + c)] = a[y] + (c + 1) * b[x];
  for (bool aa : {false, true}) {
    std::vector<float> ra(static_cast<size_t>(h1)), rb(static_cast<size_t>(w1));
    resample_pos_grid(a, h0, 1, ra.data(), h1, 1, 1, aa);
    resample_pos_grid(b, 1, w0, rb.data(), 1, w1, 1, aa);
    resample_pos_grid(grid.data(), h0, w0, out.data(), h1, w1, d, aa);
    for (int64_t y = 0; y < h1; ++y)
      for (int64_t x = 0; x < w1; ++x)
        for (int64_t c = 0; c < d; ++c)
          CHECK(out[size_t((y * w1 + x) * d + c)] ==
                Approx(ra[size_t(y)] + (c + 1) * rb[size_t(x)]).margin(1e-5));
  }
}

TEST_CASE("vit: another token grid resamples pos_embed or is refused", "[vit]") {
  VitConfig cfg = variants()[0].cfg;  // stored grid 3 x 4
  const Weights ws = vit_random_weights(cfg, 3);
  const int64_t h = 20, wd = 8;  // grid 5 x 2
  const std::vector<float> image = random_image(h, wd, 9);
  for (PosEmbedResample mode : {PosEmbedResample::kBicubic, PosEmbedResample::kBicubicAntialias}) {
    cfg.pos_resample = mode;
    const std::vector<float>& stored = stored_pos(ws, cfg);
    std::vector<float> pos(size_t((1 + 5 * 2) * cfg.width));
    std::copy(stored.begin(), stored.begin() + cfg.width, pos.begin());
    resample_pos_grid(stored.data() + cfg.width, 3, 4, pos.data() + cfg.width, 5, 2, cfg.width,
                      mode == PosEmbedResample::kBicubicAntialias);
    const test::VitRefOut ref = reference_forward(cfg, ws, image, h, wd, pos);
    auto model = VitModel::build(cfg);
    REQUIRE(model.is_ok());
    MapVisitor mv(ws);
    (*model)->visit(mv);
    (*model)->pack(Precision::kF32);
    auto out = (*model)->forward(image.data(), h, wd, nullptr, true);
    REQUIRE(out.is_ok());
    CHECK(out->grid_h == 5);
    CHECK(out->grid_w == 2);
    CHECK(max_rel(out->cls, ref.cls) < 1e-5);
    CHECK(rel_err(out->tokens, ref.tokens) < 1e-5);
  }
  cfg.pos_resample = PosEmbedResample::kRefuse;
  auto model = VitModel::build(cfg);
  REQUIRE(model.is_ok());
  MapVisitor mv(ws);
  (*model)->visit(mv);
  (*model)->pack(Precision::kF32);
  auto refused = (*model)->forward(image.data(), h, wd, nullptr);
  REQUIRE_FALSE(refused.is_ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("5x2") && Catch::Contains("3x4"));
  auto bad = (*model)->forward(image.data(), 13, 16, nullptr);  // not a multiple of p
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("13x16"));
  // Config errors name the field.
  VitConfig odd = cfg;
  odd.heads = 5;
  auto b = VitModel::build(odd);
  REQUIRE_FALSE(b.is_ok());
  CHECK_THAT(b.status().message(), Catch::Contains("heads"));
}

TEST_CASE("vit: loads a safetensors file by name with prefix and ignored names and overrides",
          "[vit]") {
  const VitConfig cfg = variants()[1].cfg;  // prefix "visual."
  const Weights ws = vit_random_weights(cfg, 21);
  const std::vector<float> image = random_image(12, 16, 4);
  test::TempDir dir("vit-load");
  auto write = [&](const std::string& path, const Weights& m) {
    std::vector<TensorToWrite> t;
    for (const auto& [name, ten] : m)
      t.push_back({name, DType::kF32, ten.shape, ten.values.data()});
    REQUIRE(write_safetensors(path, t).is_ok());
  };
  // Plus tensors the caller declares as not parameters.
  Weights with_extra = ws;
  with_extra["visual.head.weight"] = {{10, 24}, std::vector<float>(240, 1.f)};
  with_extra["visual.mask_token"] = {{1, 32}, std::vector<float>(32, 0.f)};
  const std::string good = dir.file("good.safetensors");
  write(good, with_extra);
  VitLoadOptions opt;
  opt.ignored_prefixes = {"visual.head.", "visual.mask_token"};
  auto model = VitModel::load(good, cfg, opt);
  INFO((model.is_ok() ? "" : model.status().message()));
  REQUIRE(model.is_ok());
  const test::VitRefOut ref = reference_forward(cfg, ws, image, 12, 16, stored_pos(ws, cfg));
  auto out = (*model)->forward(image.data(), 12, 16, nullptr);
  REQUIRE(out.is_ok());
  CHECK(max_rel(out->cls, ref.cls) < 1e-5);

  // Without the ignore list the extras are reported as unused, by name.
  auto strict = VitModel::load(good, cfg);
  REQUIRE_FALSE(strict.is_ok());
  CHECK_THAT(strict.status().message(), Catch::Contains("unused") &&
                                            Catch::Contains("visual.head.weight") &&
                                            Catch::Contains("visual.mask_token"));
  // Missing and mis-shaped tensors, by name.
  Weights broken = ws;
  broken.erase("visual.blocks.1.mlp.fc2.bias");
  broken["visual.blocks.0.attn.qkv.weight"].shape = {32, 96};
  const std::string bad = dir.file("bad.safetensors");
  write(bad, broken);
  auto b = VitModel::load(bad, cfg);
  REQUIRE_FALSE(b.is_ok());
  CHECK_THAT(b.status().message(),
             Catch::Contains("missing") && Catch::Contains("visual.blocks.1.mlp.fc2.bias") &&
                 Catch::Contains("mis-shaped") &&
                 Catch::Contains("visual.blocks.0.attn.qkv.weight: expected [96,32], found "
                                 "[32,96]"));

  // Overrides: a caller-modified qkv weight replaces the file's (e.g. a merged LoRA).
  Weights modified = ws;
  std::map<std::string, OverrideTensor> over;
  over["visual.blocks.0.attn.qkv.weight"] = ws.at("visual.blocks.0.attn.qkv.weight");
  for (float& v : over["visual.blocks.0.attn.qkv.weight"].values) v *= 1.5f;
  modified["visual.blocks.0.attn.qkv.weight"] = over["visual.blocks.0.attn.qkv.weight"];
  opt.overrides = &over;
  auto m2 = VitModel::load(good, cfg, opt);
  INFO((m2.is_ok() ? "" : m2.status().message()));
  REQUIRE(m2.is_ok());
  const test::VitRefOut ref2 = reference_forward(cfg, modified, image, 12, 16, stored_pos(ws, cfg));
  auto out2 = (*m2)->forward(image.data(), 12, 16, nullptr);
  REQUIRE(out2.is_ok());
  CHECK(max_rel(out2->cls, ref2.cls) < 1e-5);
  CHECK(max_rel(out2->cls, ref.cls) > 1e-3);  // the override really took effect
  // A mis-shaped or unknown override is reported by name.
  over["visual.blocks.0.attn.qkv.weight"].shape = {96, 16};
  over["visual.blocks.9.nothing"] = {{1}, {0.f}};
  auto m3 = VitModel::load(good, cfg, opt);
  REQUIRE_FALSE(m3.is_ok());
  CHECK_THAT(m3.status().message(), Catch::Contains("visual.blocks.0.attn.qkv.weight: expected "
                                                    "[96,32], found [96,16]") &&
                                        Catch::Contains("visual.blocks.9.nothing"));
}
