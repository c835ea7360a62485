// DreamSim ensemble (enhance/metrics/dreamsim.h): Pillow-exact bicubic preprocessing, the ensemble maths
// against a double-precision reference written here from the definitions (per-backbone
// normalisation, ViT features, LoRA merge, embedding centring/normalisation, concatenation, cosine
// distance), the full-size weight layout, and the weight-file errors.
#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>

#include "attention/runtime/cpu.h"
#include "attention/runtime/io/safetensors.h"
#include "enhance/metrics/dreamsim.h"
#include "enhance/metrics/feature_metrics.h"
#include "test_support.h"
#include "vit_reference.h"

using namespace macro;
using namespace macro::enhance;

namespace {

// ---- synthetic weights ---------------------------------------------------------------------------
struct T {
  std::vector<int64_t> shape;
  std::vector<float> v;
};
using Weights = std::map<std::string, T>;

int64_t numel(const std::vector<int64_t>& s) {
  int64_t n = 1;
  for (int64_t d : s) n *= d;
  return n;
}

bool ends_with(const std::string& s, const std::string& t) {
  return s.size() >= t.size() && s.compare(s.size() - t.size(), t.size(), t) == 0;
}

// Values that keep a random ViT's activations bounded: norm weights 1 + 0.1 u, biases 0.05 u,
// matrices n / sqrt(fan_in), cls/pos 0.5 n.
Weights random_weights(const DreamSimConfig& cfg, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  std::uniform_real_distribution<double> ud(-1.0, 1.0);
  Weights w;
  for (const DreamSimTensorSpec& s : dreamsim_tensor_specs(cfg)) {
    T t{s.shape, std::vector<float>(size_t(numel(s.shape)))};
    const bool norm = s.name.find("norm") != std::string::npos || s.name.find("pos_drop") != std::string::npos;
    const int64_t fan_in = s.shape.size() >= 2 ? numel(s.shape) / s.shape[0] : 1;
    for (float& v : t.v) {
      if (norm && ends_with(s.name, ".weight"))
        v = float(1.0 + 0.1 * ud(rng));
      else if (ends_with(s.name, ".bias"))
        v = float(0.05 * ud(rng));
      else if (ends_with(s.name, "cls_token") || ends_with(s.name, "pos_embed"))
        v = float(0.5 * nd(rng));
      else if (ends_with(s.name, ".proj") && s.shape.size() == 2)  // CLIP proj [D, P]
        v = float(nd(rng) / std::sqrt(double(s.shape[0])));
      else
        v = float(nd(rng) / std::sqrt(double(fan_in)));
    }
    w[s.name] = std::move(t);
  }
  return w;
}

Status write_weights(const std::string& path, const Weights& w,
                     const std::map<std::string, std::string>& meta = {}) {
  std::vector<TensorToWrite> out;
  for (const auto& [name, t] : w) out.push_back({name, DType::kF32, t.shape, t.v.data()});
  return write_safetensors(path, out, meta);
}

// PEFT form of every qkv: base_layer + lora_A/B (r, rows of A n/sqrt(D), B 0.2 n). Returns the
// merged weights the reference uses (W + alpha/r B A in double).
Weights to_unmerged(const Weights& merged, int r, double alpha, uint64_t seed, Weights* file,
                    const std::string& adapter = ".default") {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  Weights ref = merged;
  *file = {};
  for (const auto& [name, t] : merged) {
    if (!ends_with(name, ".attn.qkv.weight") && !ends_with(name, ".attn.qkv.bias")) {
      (*file)[name] = t;
      continue;
    }
    const std::string module = name.substr(0, name.rfind('.'));
    const std::string leaf = name.substr(name.rfind('.') + 1);
    (*file)[module + ".base_layer." + leaf] = t;
    if (leaf != "weight") continue;
    const int64_t out = t.shape[0], in = t.shape[1];
    T a{{r, in}, std::vector<float>(size_t(r * in))}, b{{out, r}, std::vector<float>(size_t(out * r))};
    for (float& v : a.v) v = float(nd(rng) / std::sqrt(double(in)));
    for (float& v : b.v) v = float(0.2 * nd(rng));
    T& m = ref[name];
    for (int64_t o = 0; o < out; ++o)
      for (int64_t i = 0; i < in; ++i) {
        double acc = 0;
        for (int k = 0; k < r; ++k) acc += double(b.v[size_t(o * r + k)]) * a.v[size_t(k * in + i)];
        m.v[size_t(o * in + i)] = float(double(t.v[size_t(o * in + i)]) + alpha / r * acc);
      }
    (*file)[module + ".lora_A" + adapter + ".weight"] = a;
    (*file)[module + ".lora_B" + adapter + ".weight"] = b;
  }
  return ref;
}

// ---- double-precision reference -----------------------------------------------------------------
using V = std::vector<double>;

// One backbone's feature from a [3, S, S] image in [0, 1] (normalised here), through
// vit_reference.h's double ViT; the file's `pos_drop` is the config's `norm_pre`.
V reference_feature(const Weights& w, const DreamSimBackbone& bb, const V& img01, int64_t s) {
  V img(img01.size());
  for (int64_t ch = 0; ch < 3; ++ch)
    for (int64_t i = 0; i < s * s; ++i)
      img[size_t(ch * s * s + i)] =
          (img01[size_t(ch * s * s + i)] - bb.mean[size_t(ch)]) / bb.std[size_t(ch)];
  const auto tensor = [&](const std::string& name) -> const std::vector<float>& {
    std::string file = name;
    const size_t at = file.find(".norm_pre.");
    if (at != std::string::npos) file.replace(at, 10, ".pos_drop.");
    auto it = w.find(file);
    if (it == w.end()) FAIL("reference: no tensor " << file);
    return it->second.v;
  };
  return test::vit_reference_forward(bb.vit, tensor, img, s, s, tensor(bb.vit.prefix + "pos_embed"))
      .cls;
}

V reference_embedding(const Weights& w, const DreamSimConfig& cfg, const V& img01) {
  V e;
  for (const DreamSimBackbone& b : cfg.backbones) {
    const V f = reference_feature(w, b, img01, cfg.image_size);
    e.insert(e.end(), f.begin(), f.end());
  }
  double m = 0, sq = 0;
  for (double v : e) m += v;
  m /= double(e.size());
  for (double& v : e) {
    v -= m;
    sq += v * v;
  }
  for (double& v : e) v /= std::sqrt(sq);
  return e;
}

double reference_distance(const V& a, const V& b) {
  double ab = 0, aa = 0, bb = 0;
  for (size_t i = 0; i < a.size(); ++i) ab += a[i] * b[i], aa += a[i] * a[i], bb += b[i] * b[i];
  return 1.0 - ab / (std::sqrt(aa) * std::sqrt(bb));
}

// A small ensemble with the real structure: D 32, 2 blocks, 2 heads, F 64, p 8, S 32, P 16.
DreamSimConfig small_config() {
  DreamSimConfig cfg = DreamSimConfig::ensemble();
  cfg.image_size = 32;
  for (DreamSimBackbone& b : cfg.backbones) {
    b.vit.width = 32;
    b.vit.depth = 2;
    b.vit.heads = 2;
    b.vit.mlp_hidden = 64;
    b.vit.patch = 8;
    b.vit.grid_h = b.vit.grid_w = 4;
    if (b.vit.proj_dim > 0) b.vit.proj_dim = 16;
  }
  return cfg;
}

// The deterministic pattern also used to make the Pillow numbers below.
gs::Image pattern(int w, int h) {
  gs::Image im(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        im.at(y, x, c) = float((x * x * 3 + y * 5 + c * 77 + ((x * y) % 13) * 17) % 256) / 255.0f;
  return im;
}

gs::Image noise_image(int w, int h, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> ud(0, 255);
  gs::Image im(w, h, 3);
  for (float& v : im.data) v = float(ud(rng)) / 255.0f;
  return im;
}

V to_double(const std::vector<float>& v) { return V(v.begin(), v.end()); }

}  // namespace

TEST_CASE("Pillow BICUBIC 8-bit resize to 224 matches Pillow 9.4", "[dreamsim]") {
  // Numbers from Pillow 9.4.0: Image.frombytes('RGB', (w, h), pattern).resize((224, 224),
  // Image.BICUBIC); sum of bytes, sum of byte * (index % 251 + 1), first 6 bytes, pixel (100, 50).
  struct Case {
    int w, h;
    uint64_t sum, wsum;
    int first[6], px[3];
  };
  const Case cases[] = {
      {37, 29, 19129227, 2407603314ull, {0, 77, 154, 0, 77, 154}, {36, 94, 212}},
      {300, 250, 19189752, 2416729027ull, {1, 78, 155, 9, 86, 163}, {220, 53, 143}},
      {224, 100, 19167808, 2414314039ull, {0, 77, 154, 1, 78, 155}, {71, 159, 255}},
      {500, 224, 19180652, 2415783477ull, {2, 79, 156, 24, 101, 187}, {109, 102, 83}},
      {224, 224, 19175659, 2416036301ull, {0, 77, 154, 3, 80, 157}, {200, 21, 98}},
  };
  for (const Case& c : cases) {
    INFO(c.w << "x" << c.h);
    const std::vector<uint8_t> src = quantize_u8(pattern(c.w, c.h));
    for (ThreadPool* pool : {static_cast<ThreadPool*>(nullptr), &ThreadPool::global()}) {
      const std::vector<uint8_t> out = resize_bicubic_u8(src.data(), c.w, c.h, 3, 224, 224, pool);
      REQUIRE(out.size() == size_t(224 * 224 * 3));
      uint64_t sum = 0, wsum = 0;
      for (size_t i = 0; i < out.size(); ++i) {
        sum += out[i];
        wsum += uint64_t(out[i]) * (i % 251 + 1);
      }
      CHECK(sum == c.sum);
      CHECK(wsum == c.wsum);
      for (int i = 0; i < 6; ++i) CHECK(int(out[size_t(i)]) == c.first[i]);
      for (int i = 0; i < 3; ++i) CHECK(int(out[size_t((100 * 224 + 50) * 3 + i)]) == c.px[i]);
    }
  }
}

TEST_CASE("DreamSim preprocessing quantises and scales to CHW in 0..1 and refuses bad images", "[dreamsim]") {
  gs::Image im = pattern(224, 224);
  im.data[0] = 0.5f / 255.0f + 1e-4f;  // rounds up to 1
  im.data[1] = 2.0f;                     // clamps to 255
  auto x = dreamsim_preprocess(im, 224);
  REQUIRE(x.is_ok());
  const std::vector<float>& v = *x;
  REQUIRE(v.size() == size_t(3 * 224 * 224));
  CHECK(v[0] == 1.0f / 255.0f);                              // R of pixel 0 (plane 0)
  CHECK(v[size_t(224 * 224)] == 1.0f);                        // G of pixel 0 (plane 1)
  CHECK(v[size_t(2 * 224 * 224 + 5)] == im.at(0, 5, 2));      // unchanged size: no resampling
  gs::Image gray(8, 8, 1);
  auto bad = dreamsim_preprocess(gray, 224);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("3 channels"));
  gs::Image nan = pattern(8, 8);
  nan.data[3] = NAN;
  CHECK_FALSE(dreamsim_preprocess(nan, 224).is_ok());
}

TEST_CASE("DreamSim embedding normalisation and distance (analytic)", "[dreamsim]") {
  std::vector<float> e = {1, 2, 3, 6};  // mean 3 -> {-2, -1, 0, 3} / sqrt(14)
  dreamsim_normalize_embedding(e);
  const double r = std::sqrt(14.0);
  CHECK(e[0] == Approx(-2 / r).epsilon(1e-7));
  CHECK(e[3] == Approx(3 / r).epsilon(1e-7));
  // Centring + scaling make d invariant to a constant offset and a positive scale; -e is at 2.
  std::vector<float> a = {0.3f, -1.2f, 2.5f, 0.1f, 0.7f}, b(a.size()), c(a.size());
  for (size_t i = 0; i < a.size(); ++i) b[i] = 3.0f * a[i] + 7.0f, c[i] = -a[i];
  dreamsim_normalize_embedding(a);
  dreamsim_normalize_embedding(b);
  dreamsim_normalize_embedding(c);
  CHECK(dreamsim_embedding_distance(a, b) == Approx(0.0).margin(1e-7));
  CHECK(dreamsim_embedding_distance(a, c) == Approx(2.0).margin(1e-7));
  CHECK(dreamsim_embedding_distance(a, a) == Approx(0.0).margin(1e-7));
  // Orthogonal (after centring): {1,-1,0,0} and {0,0,1,-1} -> 1.
  std::vector<float> p = {1, -1, 0, 0}, q = {0, 0, 1, -1};
  CHECK(dreamsim_embedding_distance(p, q) == Approx(1.0).margin(1e-12));
}

TEST_CASE("DreamSim small ensemble matches the double-precision reference (merged LoRA)", "[dreamsim]") {
  test::TempDir dir("dreamsim-small");
  const DreamSimConfig cfg = small_config();
  REQUIRE(cfg.embed_dim() == 64);
  const Weights w = random_weights(cfg, 11);
  const std::string path = dir.file("w.safetensors");
  REQUIRE(write_weights(path, w).is_ok());
  const gs::Image a = noise_image(32, 32, 1);                                  // not resized
  const gs::Image a2 = noise_image(40, 27, 1), b = noise_image(40, 27, 2);  // resized
  for (Isa isa : {Isa::kScalar, best_isa()}) {
    REQUIRE(set_isa(isa).is_ok());  // GEMM panels are packed for the path active at load
    INFO("isa " << int(isa));
    auto model = DreamSimModel::load(path, cfg);
    REQUIRE(model.is_ok());
    CHECK((*model)->lora_merged() == 0);
    // Features of each backbone before the ensemble normalisation.
    auto px = dreamsim_preprocess(a, 32);
    REQUIRE(px.is_ok());
    auto feats = (*model)->features(*px);
    REQUIRE(feats.is_ok());
    REQUIRE(feats->size() == 3);
    for (size_t i = 0; i < 3; ++i) {
      const V ref = reference_feature(w, cfg.backbones[i], to_double(*px), 32);
      REQUIRE((*feats)[i].size() == ref.size());
      double err = 0, mag = 0;
      for (size_t k = 0; k < ref.size(); ++k) {
        err = std::max(err, std::abs((*feats)[i][k] - ref[k]));
        mag = std::max(mag, std::abs(ref[k]));
      }
      INFO(cfg.backbones[i].name << " max err " << err << " max |f| " << mag);
      CHECK(err <= 2e-5 * std::max(1.0, mag));
    }
    auto ea = (*model)->embed(a);
    REQUIRE(ea.is_ok());
    const V ra = reference_embedding(w, cfg, to_double(*px));
    for (size_t k = 0; k < ra.size(); ++k) CHECK((*ea)[k] == Approx(ra[k]).margin(2e-6));
    auto pa2 = dreamsim_preprocess(a2, 32), pb = dreamsim_preprocess(b, 32);
    REQUIRE(pa2.is_ok());
    REQUIRE(pb.is_ok());
    const double ref_d = reference_distance(reference_embedding(w, cfg, to_double(*pa2)),
                                            reference_embedding(w, cfg, to_double(*pb)));
    auto d = (*model)->distance(a2, b);
    REQUIRE(d.is_ok());
    INFO("d " << *d << " reference " << ref_d);
    CHECK(ref_d > 0.05);  // a non-trivial pair
    CHECK(*d == Approx(ref_d).margin(2e-6));
  }
  REQUIRE(set_isa(best_isa()).is_ok());
}

TEST_CASE("DreamSim unmerged PEFT LoRA is merged at load with lora_alpha / r", "[dreamsim]") {
  test::TempDir dir("dreamsim-lora");
  const DreamSimConfig cfg = small_config();
  const Weights base = random_weights(cfg, 21);
  const int r = 4;
  const double alpha = 8.0;  // scale 2: a large update, so a wrong scale cannot pass
  for (const std::string adapter : {".default", ""}) {
    INFO("adapter name '" << adapter << "'");
    Weights file;
    const Weights merged = to_unmerged(base, r, alpha, 5, &file, adapter);
    const std::string path = dir.file("lora" + adapter + ".safetensors");
    REQUIRE(write_weights(path, file, {{"lora_alpha", "8"}, {"lora_r", "4"}}).is_ok());
    auto model = DreamSimModel::load(path, cfg);
    REQUIRE(model.is_ok());
    CHECK((*model)->lora_merged() == 3 * 2);  // every qkv of 3 backbones x 2 blocks
    const gs::Image a = noise_image(32, 32, 3), b = noise_image(32, 32, 4);
    auto d = (*model)->distance(a, b);
    REQUIRE(d.is_ok());
    auto pa = dreamsim_preprocess(a, 32), pb = dreamsim_preprocess(b, 32);
    const double ref = reference_distance(reference_embedding(merged, cfg, to_double(*pa)),
                                          reference_embedding(merged, cfg, to_double(*pb)));
    const double ref_base = reference_distance(reference_embedding(base, cfg, to_double(*pa)),
                                               reference_embedding(base, cfg, to_double(*pb)));
    INFO("d " << *d << " merged reference " << ref << " base reference " << ref_base);
    CHECK(*d == Approx(ref).margin(2e-6));
    CHECK(std::abs(ref - ref_base) > 1e-3);  // the LoRA matters
  }
  // Without lora_alpha the scale is unknown: refused, naming the key.
  Weights file;
  to_unmerged(base, r, alpha, 5, &file);
  const std::string path = dir.file("noalpha.safetensors");
  REQUIRE(write_weights(path, file).is_ok());
  auto bad = DreamSimModel::load(path, cfg);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("lora_alpha"));
  CHECK_THAT(bad.status().message(), Catch::Contains("lora_A"));
  REQUIRE(write_weights(path, file, {{"lora_alpha", "8"}, {"lora_r", "16"}}).is_ok());
  bad = DreamSimModel::load(path, cfg);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("lora_r"));
}

TEST_CASE("DreamSim weight file errors name the tensor", "[dreamsim]") {
  test::TempDir dir("dreamsim-errors");
  const DreamSimConfig cfg = small_config();
  const Weights good = random_weights(cfg, 31);
  const std::string path = dir.file("w.safetensors");
  auto load_error = [&](const Weights& w) {
    REQUIRE(write_weights(path, w).is_ok());
    auto m = DreamSimModel::load(path, cfg);
    REQUIRE_FALSE(m.is_ok());
    return m.status().message();
  };
  {
    Weights w = good;
    w.erase("clip.blocks.1.mlp.fc2.bias");
    const std::string msg = load_error(w);
    CHECK_THAT(msg, Catch::Contains("clip.blocks.1.mlp.fc2.bias"));
    CHECK_THAT(msg, Catch::Contains("missing"));
  }
  {
    Weights w = good;
    w["open_clip.extra.weight"] = T{{2}, {1, 2}};
    const std::string msg = load_error(w);
    CHECK_THAT(msg, Catch::Contains("open_clip.extra.weight"));
  }
  {
    Weights w = good;
    w["dino.pos_embed"] = T{{1, 16, 32}, std::vector<float>(16 * 32)};
    const std::string msg = load_error(w);
    CHECK_THAT(msg, Catch::Contains("dino.pos_embed"));
    CHECK_THAT(msg, Catch::Contains("[1,17,32]"));
  }
  {
    Weights w = good;  // CLIP's ln_pre must be under DreamSim's name `pos_drop`
    w["clip.norm_pre.weight"] = w["clip.pos_drop.weight"];
    w.erase("clip.pos_drop.weight");
    const std::string msg = load_error(w);
    CHECK_THAT(msg, Catch::Contains("clip.pos_drop.weight"));
  }
  {
    // dino.norm.* (in DINO's state dict, unused by its 'cls' feature) is accepted.
    Weights w = good;
    w["dino.norm.weight"] = T{{32}, std::vector<float>(32, 1.0f)};
    w["dino.norm.bias"] = T{{32}, std::vector<float>(32, 0.0f)};
    REQUIRE(write_weights(path, w).is_ok());
    CHECK(DreamSimModel::load(path, cfg).is_ok());
  }
  auto missing = DreamSimModel::load(dir.file("nope.safetensors"), cfg);
  REQUIRE_FALSE(missing.is_ok());
  CHECK_THAT(missing.status().message(), Catch::Contains("nope.safetensors"));
  auto v = dreamsim_distance_value(noise_image(8, 8, 1), noise_image(8, 8, 2),
                                   dir.file("absent.safetensors"));
  REQUIRE_FALSE(v.is_ok());
  CHECK_THAT(v.status().message(), Catch::Contains("absent.safetensors"));
}

TEST_CASE("DreamSim full-size layout: the exact file loads and d(x x) = 0 and is symmetric and finite",
          "[dreamsim]") {
  const DreamSimConfig cfg = DreamSimConfig::ensemble();
  CHECK(cfg.embed_dim() == 1792);
  const std::vector<DreamSimTensorSpec> specs = dreamsim_tensor_specs(cfg);
  // 3 towers x (cls, pos, patch w/b, 12 x 12 block tensors, final norm w/b), minus DINO's norm,
  // plus CLIP/OpenCLIP ln_pre (pos_drop) w/b and proj.
  CHECK(specs.size() == size_t(3 * (4 + 12 * 12 + 2) - 2 + 2 * 3));
  std::map<std::string, std::vector<int64_t>> by_name;
  int64_t params = 0;
  for (const auto& s : specs) by_name[s.name] = s.shape, params += numel(s.shape);
  CHECK(by_name["dino.pos_embed"] == std::vector<int64_t>{1, 197, 768});
  CHECK(by_name["clip.patch_embed.proj.weight"] == std::vector<int64_t>{768, 3, 16, 16});
  CHECK(by_name["open_clip.blocks.11.attn.qkv.weight"] == std::vector<int64_t>{2304, 768});
  CHECK(by_name["clip.pos_drop.weight"] == std::vector<int64_t>{768});
  CHECK(by_name["open_clip.proj"] == std::vector<int64_t>{768, 512});
  CHECK(by_name.count("dino.norm.weight") == 0);
  CHECK(by_name.count("dino.proj") == 0);

  // A BF16 file with every tensor (constant per tensor kind keeps writing cheap), LoRA unmerged
  // under PEFT names with r 16 as the released adapter.
  test::TempDir dir("dreamsim-full");
  const std::string path = dir.file("dreamsim_ensemble.safetensors");
  uint64_t state = 0x9E3779B97F4A7C15ull;
  auto uniform = [&state]() {  // xorshift64*: U(-1, 1), cheap for 260 M values
    state ^= state >> 12, state ^= state << 25, state ^= state >> 27;
    return float(double((state * 0x2545F4914F6CDD1Dull) >> 11) * 0x1.0p-52 - 1.0);
  };
  std::vector<std::vector<uint16_t>> data;
  std::vector<TensorToWrite> out;
  auto bf16 = [](float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    return uint16_t((u + 0x7fff + ((u >> 16) & 1)) >> 16);
  };
  // Norm weights 1, biases 0.02 u, matrices u * sqrt(3 / fan_in) (unit variance per output).
  auto add = [&](const std::string& name, const std::vector<int64_t>& shape, bool norm_w, bool bias) {
    std::vector<uint16_t> v(size_t(numel(shape)));
    const float amp = norm_w ? 0.f
                      : bias ? 0.02f
                             : float(std::sqrt(3.0 * shape[0] / double(numel(shape))));
    for (auto& x : v) x = bf16(norm_w ? 1.0f : amp * uniform());
    data.push_back(std::move(v));
    out.push_back({name, DType::kBF16, shape, data.back().data()});
  };
  data.reserve(specs.size() + 200);
  for (const auto& s : specs) {
    const bool norm_w = (s.name.find("norm") != std::string::npos ||
                         s.name.find("pos_drop") != std::string::npos) && ends_with(s.name, ".weight");
    std::string name = s.name;
    if (ends_with(name, ".attn.qkv.weight") || ends_with(name, ".attn.qkv.bias")) {
      const std::string module = name.substr(0, name.rfind('.'));
      name = module + ".base_layer" + name.substr(name.rfind('.'));
      if (ends_with(s.name, ".weight")) {
        add(module + ".lora_A.default.weight", {16, 768}, false, false);
        add(module + ".lora_B.default.weight", {2304, 16}, false, true);
      }
    }
    add(name, s.shape, norm_w, ends_with(s.name, ".bias"));
  }
  REQUIRE(write_safetensors(path, out, {{"lora_alpha", "8"}}).is_ok());
  data.clear();
  const auto t0 = std::chrono::steady_clock::now();
  auto model = dreamsim_cached_model(path);  // the metric entry's loader and cache
  REQUIRE(model.is_ok());
  const auto t1 = std::chrono::steady_clock::now();
  CHECK((*model)->lora_merged() == 36);
  const MetricValue entry = dreamsim_distance(noise_image(96, 64, 9), noise_image(96, 64, 10), path);
  std::filesystem::remove(path);  // from here on only the cached model can answer
  auto again = dreamsim_cached_model(path);
  REQUIRE(again.is_ok());
  CHECK(again->get() == model->get());
  const gs::Image a = noise_image(96, 64, 9), b = noise_image(96, 64, 10);
  auto ea = (*model)->embed(a);
  const auto t2 = std::chrono::steady_clock::now();
  auto eb = (*model)->embed(b);
  REQUIRE(ea.is_ok());
  REQUIRE(eb.is_ok());
  REQUIRE(ea->size() == 1792);
  WARN("full-size DreamSim: load " << std::chrono::duration<double>(t1 - t0).count()
                                   << " s, one embedding (3 ViT-B/16) "
                                   << std::chrono::duration<double>(t2 - t1).count() << " s");
  double norm = 0;
  for (float v : *ea) {
    REQUIRE(std::isfinite(v));
    norm += double(v) * v;
  }
  CHECK(norm == Approx(1.0).margin(1e-5));
  const double dab = dreamsim_embedding_distance(*ea, *eb);
  CHECK(std::isfinite(dab));
  CHECK(dab > 0.0);
  CHECK(dab <= 2.0);
  // The entry point, pair reversed, recomputes both embeddings: bit-identical to d(a, b) means
  // the pipeline is deterministic and symmetric, so d(x, x) is exactly 0.
  auto dba = dreamsim_distance_value(b, a, path);
  REQUIRE(dba.is_ok());
  CHECK(*dba == dab);
  CHECK(dreamsim_embedding_distance(*ea, *ea) == Approx(0.0).margin(1e-12));
  // The metric-suite entry (called while the file existed) gave the same number.
  CHECK(entry.computed);
  CHECK(entry.value == dab);
  // A file written again at the path (another size and time) is loaded again, never answered
  // by the stale model: here a broken one, so the reload fails naming it.
  {
    std::ofstream junk(path, std::ios::binary);
    junk << std::string(64, 'x');
  }
  auto replaced = dreamsim_cached_model(path);
  REQUIRE_FALSE(replaced.is_ok());
  CHECK_THAT(replaced.status().message(), Catch::Contains(path));
  std::filesystem::remove(path);
  dreamsim_release_cached_model();
  auto gone = dreamsim_distance_value(b, a, path);  // the file was deleted: reload fails
  REQUIRE_FALSE(gone.is_ok());
  CHECK_THAT(gone.status().message(), Catch::Contains(path));
  const MetricValue absent = dreamsim_distance(a, b, path);
  CHECK_FALSE(absent.computed);
  CHECK_THAT(absent.reason, Catch::Contains("weights not supplied") && Catch::Contains(path));
}

TEST_CASE("DreamSim ensemble config is the released model", "[dreamsim]") {
  const DreamSimConfig cfg = DreamSimConfig::ensemble();
  REQUIRE(cfg.backbones.size() == 3);
  CHECK(cfg.image_size == 224);
  const char* names[] = {"dino", "clip", "open_clip"};
  for (size_t i = 0; i < 3; ++i) {
    const DreamSimBackbone& b = cfg.backbones[i];
    INFO(b.name);
    CHECK(b.name == names[i]);
    CHECK(b.vit.prefix == b.name + ".");
    CHECK(b.vit.width == 768);
    CHECK(b.vit.depth == 12);
    CHECK(b.vit.heads == 12);
    CHECK(b.vit.mlp_hidden == 3072);
    CHECK(b.vit.patch == 16);
    CHECK(b.vit.grid_h == 14);
    CHECK(b.vit.grid_w == 14);
    CHECK_FALSE(b.vit.layer_scale);
    CHECK(b.vit.qkv_bias);
    CHECK(b.vit.patch_bias);
  }
  const DreamSimBackbone &dino = cfg.backbones[0], &clip = cfg.backbones[1],
                         &oclip = cfg.backbones[2];
  // DINO 'cls': the last block's output before `norm`; eps 1e-6; exact GELU; ImageNet stats.
  CHECK_FALSE(dino.vit.final_norm);
  CHECK_FALSE(dino.vit.norm_pre);
  CHECK(dino.vit.proj_dim == 0);
  CHECK(dino.vit.ln_eps == 1e-6f);
  CHECK(dino.vit.act == nets::VitAct::kGelu);
  CHECK(dino.mean == kImagenetMean);
  CHECK(dino.std == kImagenetStd);
  // CLIP / OpenCLIP 'embedding': ln_pre, ln_post, proj 512, eps 1e-5; QuickGELU only for CLIP.
  for (const DreamSimBackbone* b : {&clip, &oclip}) {
    CHECK(b->vit.norm_pre);
    CHECK(b->vit.final_norm);
    CHECK(b->vit.proj_dim == 512);
    CHECK(b->vit.ln_eps == 1e-5f);
    CHECK(b->mean == kOpenAiClipMean);
    CHECK(b->std == kOpenAiClipStd);
  }
  CHECK(clip.vit.act == nets::VitAct::kQuickGelu);
  CHECK(oclip.vit.act == nets::VitAct::kGelu);
  CHECK(kImagenetMean[0] == 0.485f);
  CHECK(kOpenAiClipStd[2] == 0.27577711f);
}

TEST_CASE("DreamSim model calls from several threads agree with a serial call", "[dreamsim]") {
  test::TempDir dir("dreamsim-cache");
  const DreamSimConfig cfg = small_config();
  const Weights w = random_weights(cfg, 41);
  const std::string path = dir.file("w.safetensors");
  REQUIRE(write_weights(path, w).is_ok());
  auto model = DreamSimModel::load(path, cfg);
  REQUIRE(model.is_ok());
  const gs::Image a = noise_image(33, 31, 5), b = noise_image(33, 31, 6);
  auto serial = (*model)->distance(a, b);
  REQUIRE(serial.is_ok());
  ThreadPool callers(4);
  std::vector<double> got(8, -1.0);
  callers.parallel_for(got.size(), [&](size_t i0, size_t i1, int) {
    for (size_t i = i0; i < i1; ++i) {
      auto d = (*model)->distance(a, b);  // every caller on the global pool, serialised
      got[i] = d.is_ok() ? *d : -1.0;
    }
  }, 1);
  for (double g : got) CHECK(g == *serial);
}
