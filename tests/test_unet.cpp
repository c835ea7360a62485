// U-Net (attention/nets/unet.h) against the diffusers goldens in shared/golden/unet-tiny: single
// view (with intermediates), odd latent, two joint views, MACRO masked/unmasked; bf16 deviation;
// checkpoint mismatches reported by name; the full-size SD-Turbo layout from the manifest loads.
#include <catch2/catch.hpp>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <tuple>

#include "attention/nets/nn_run.h"
#include "attention/nets/synthetic_checkpoint.h"
#include "attention/nets/unet.h"
#include "attention/nets/vae.h"
#include "attention/runtime/attention_mask.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "golden_tensors.h"
#include "test_support.h"

using namespace macro;
using namespace macro::nets;

namespace {

std::string unet_dir() {
  return test::golden_dir() + "/unet-tiny";
}

using test::Bound;
using test::check_close;
using test::kFp32;
using test::read_tensor;
// bf16 weights and matmul inputs through ~20 random-weight layers: measured 1.1-1.2e-2 rel L2,
// max abs <= 2.6e-2 on these cases (2026-11-22).
constexpr Bound kBf16{3e-2, 1e-1};

// Dense golden masks -> block-sparse masks for each level present.
void golden_masks(const SafeTensors& g, std::vector<BlockSparseMask>* store, UNetMasks* masks) {
  store->clear();
  store->reserve(8);
  masks->level.clear();
  for (int l = 0; l < 8; ++l) {
    const TensorEntry* e = g.find("mask.level" + std::to_string(l));
    if (!e) break;
    auto m = mask_from_dense(e->data, int(e->shape[0]), int(e->shape[1]), 0, true);
    REQUIRE(m.is_ok());
    store->push_back(std::move(*m));
    masks->level.push_back(&store->back());
  }
}

void run_case(const UNet2DConditionModel& unet, const std::string& name, Bound b,
              bool intermediates = false) {
  auto g = SafeTensors::open(unet_dir() + "/" + name + ".safetensors");
  REQUIRE(g.is_ok());
  Tensor z = read_tensor(*g, "input.z"), ctx = read_tensor(*g, "input.ctx");
  Tensor t = read_tensor(*g, "input.timestep");
  std::vector<BlockSparseMask> store;
  UNetMasks masks;
  golden_masks(*g, &store, &masks);
  std::map<std::string, Tensor> taps;
  UNetTap tap;
  if (intermediates)
    tap = [&](const std::string& n, const float* data, const Shape& s) {
      Tensor c = Tensor::f32(s);
      std::copy(data, data + c.numel(), c.f32());
      taps.emplace(n, std::move(c));
    };
  std::printf("unet-tiny %s (%s, %zu masked levels)\n", name.c_str(),
              precision_name(unet.precision()), masks.level.size());
  auto eps = unet.forward(z, t.f32()[0], ctx, masks, &ThreadPool::global(), tap);
  REQUIRE(eps.is_ok());
  check_close("output.eps", *eps, read_tensor(*g, "output.eps"), b);
  if (intermediates) {
    int seen = 0;
    for (const std::string& n : g->names()) {
      if (n.rfind("intermediate.", 0) != 0) continue;
      const std::string key = n.substr(13);
      REQUIRE(taps.count(key));
      check_close(n, taps.at(key), read_tensor(*g, n), b);
      ++seen;
    }
    CHECK(seen == 10);
  }
}

std::unique_ptr<UNet2DConditionModel> load_tiny(Precision p) {
  auto m = UNet2DConditionModel::load(unet_dir(), p);
  INFO((m.is_ok() ? "" : m.status().message()));
  REQUIRE(m.is_ok());
  return std::move(*m);
}

}  // namespace

TEST_CASE("unet-tiny fp32 matches the diffusers goldens", "[nets][unet]") {
  auto unet = load_tiny(Precision::kF32);
  run_case(*unet, "case-single", kFp32, /*intermediates=*/true);
  run_case(*unet, "case-odd", kFp32);
  run_case(*unet, "case-ref2", kFp32);
  run_case(*unet, "case-macro-masked", kFp32);
  run_case(*unet, "case-macro-unmasked", kFp32);
}

TEST_CASE("unet-tiny bf16 stays within its stated bound", "[nets][unet][bf16]") {
  auto unet = load_tiny(Precision::kBf16);
  for (const char* c :
       {"case-single", "case-odd", "case-ref2", "case-macro-masked", "case-macro-unmasked"})
    run_case(*unet, c, kBf16);
}

TEST_CASE("unet: the MACRO mask changes the result and skips work", "[nets][unet]") {
  auto g = SafeTensors::open(unet_dir() + "/case-macro-masked.safetensors");
  REQUIRE(g.is_ok());
  std::vector<BlockSparseMask> store;
  UNetMasks masks;
  golden_masks(*g, &store, &masks);
  REQUIRE(masks.level.size() == 4);
  // Level 0: 5 views x 384 tokens; the mask allows far fewer pairs than the full square.
  const BlockSparseMask& m0 = *masks.level[0];
  CHECK(m0.nq == 5 * 16 * 24);
  CHECK(m0.computed_pairs() < int64_t(m0.nq) * m0.nq);
  auto masked = read_tensor(*g, "output.eps");
  auto u = SafeTensors::open(unet_dir() + "/case-macro-unmasked.safetensors");
  REQUIRE(u.is_ok());
  auto unmasked = read_tensor(*u, "output.eps");
  CHECK(test::compare(masked.f32(), unmasked.f32(), size_t(masked.numel())).rel_l2 > 1e-3);
}

TEST_CASE("unet: the close-up alone skips the other views' dead work, bit for bit",
          "[nets][unet]") {
  // output_views = 1 computes, after the last transformer's joint attention, view 0 only: its eps
  // must be the full forward's view 0 exactly, masked and unmasked, fp32 and bf16, any threads.
  for (Precision p : {Precision::kF32, Precision::kBf16}) {
    auto unet = load_tiny(p);
    for (const char* name : {"case-macro-masked", "case-macro-unmasked", "case-ref2"}) {
      INFO(name << " " << precision_name(p));
      auto g = SafeTensors::open(unet_dir() + "/" + name + ".safetensors");
      REQUIRE(g.is_ok());
      Tensor z = read_tensor(*g, "input.z"), ctx = read_tensor(*g, "input.ctx");
      const float t = read_tensor(*g, "input.timestep").f32()[0];
      std::vector<BlockSparseMask> store;
      UNetMasks masks;
      golden_masks(*g, &store, &masks);
      auto full = unet->forward(z, t, ctx, masks, &ThreadPool::global());
      REQUIRE(full.is_ok());
      const int64_t views = z.dim(0);
      REQUIRE(views >= 2);
      const size_t per_view = size_t(full->numel() / views);
      for (int threads : {1, 3}) {
        ThreadPool pool(threads);
        auto one = unet->forward(z, t, ctx, masks, &pool, {}, nullptr, 1);
        REQUIRE(one.is_ok());
        CHECK(one->dim(0) == 1);
        REQUIRE(size_t(one->numel()) == per_view);
        CHECK(std::memcmp(one->f32(), full->f32(), per_view * sizeof(float)) == 0);
      }
      auto two = unet->forward(z, t, ctx, masks, &ThreadPool::global(), {}, nullptr, 2);
      REQUIRE(two.is_ok());
      CHECK(std::memcmp(two->f32(), full->f32(), 2 * per_view * sizeof(float)) == 0);
      auto bad = unet->forward(z, t, ctx, masks, &ThreadPool::global(), {}, nullptr, views + 1);
      REQUIRE(!bad.is_ok());
      CHECK_THAT(bad.status().message(), Catch::Contains("output views"));
    }
  }
}

TEST_CASE("unet: bad shapes and masks are refused", "[nets][unet]") {
  auto unet = load_tiny(Precision::kF32);
  Tensor z = Tensor::f32({2, 4, 8, 8}), ctx = Tensor::f32({2, 77, 48});
  Tensor bad_z = Tensor::f32({2, 3, 8, 8}), bad_ctx = Tensor::f32({2, 77, 40});
  auto r1 = unet->forward(bad_z, 199, ctx, {}, nullptr);
  REQUIRE_FALSE(r1.is_ok());
  CHECK_THAT(r1.status().message(), Catch::Contains("z"));
  auto r2 = unet->forward(z, 199, bad_ctx, {}, nullptr);
  REQUIRE_FALSE(r2.is_ok());
  CHECK_THAT(r2.status().message(), Catch::Contains("ctx"));
  std::vector<uint8_t> dense(100 * 100, 1);
  auto m = mask_from_dense(dense.data(), 100, 100);
  REQUIRE(m.is_ok());
  UNetMasks masks;
  masks.level = {&*m};
  auto r3 = unet->forward(z, 199, ctx, masks, nullptr);
  REQUIRE_FALSE(r3.is_ok());
  CHECK_THAT(r3.status().message(), Catch::Contains("mask level 0"));
  // A good call with one shared ctx row ([1, 77, 48]) works.
  Tensor ctx1 = Tensor::f32({1, 77, 48});
  CHECK(unet->forward(z, 199, ctx1, {}, nullptr).is_ok());
}

namespace {

// Copy the tiny checkpoint through `edit` (which may drop, rename or reshape tensors).
std::string edited_copy(const test::TempDir& dir, const std::string& src_dir,
                        const std::function<void(std::vector<TensorToWrite>&,
                                                 std::vector<std::vector<float>>&)>& edit) {
  auto f = SafeTensors::open(src_dir + "/diffusion_pytorch_model.safetensors");
  REQUIRE(f.is_ok());
  std::vector<TensorToWrite> ts;
  std::vector<std::vector<float>> data;
  data.reserve(f->names().size() + 4);
  for (const std::string& n : f->names()) {
    const TensorEntry* e = f->find(n);
    ts.push_back({n, e->dtype, e->shape, e->data});
  }
  edit(ts, data);
  const std::string out = dir.path + "/model";
  std::filesystem::create_directories(out);
  std::filesystem::copy_file(src_dir + "/config.json", out + "/config.json");
  REQUIRE(write_safetensors(out + "/diffusion_pytorch_model.safetensors", ts).is_ok());
  return out;
}

TensorToWrite* find_tw(std::vector<TensorToWrite>& ts, const std::string& name) {
  for (auto& t : ts)
    if (t.name == name) return &t;
  FAIL("no tensor " << name);
  return nullptr;
}

}  // namespace

TEST_CASE("unet: missing, extra and mis-shaped tensors are reported by name", "[nets][unet]") {
  const std::string victim = "up_blocks.2.attentions.1.transformer_blocks.0.attn2.to_k.weight";
  {
    test::TempDir dir("unet-missing");
    auto folder = edited_copy(dir, unet_dir(), [&](auto& ts, auto&) {
      ts.erase(std::remove_if(ts.begin(), ts.end(), [&](auto& t) { return t.name == victim; }),
               ts.end());
    });
    auto m = UNet2DConditionModel::load(folder, Precision::kF32);
    REQUIRE_FALSE(m.is_ok());
    CHECK_THAT(m.status().message(), Catch::Contains("missing") && Catch::Contains(victim));
  }
  {
    test::TempDir dir("unet-extra");
    auto folder = edited_copy(dir, unet_dir(), [&](auto& ts, auto&) {
      TensorToWrite extra = *find_tw(ts, victim);
      extra.name = "down_blocks.0.attentions.0.extra_thing.weight";
      ts.push_back(extra);
    });
    auto m = UNet2DConditionModel::load(folder, Precision::kF32);
    REQUIRE_FALSE(m.is_ok());
    CHECK_THAT(m.status().message(),
               Catch::Contains("unused") && Catch::Contains("extra_thing.weight"));
  }
  {
    test::TempDir dir("unet-shape");
    auto folder = edited_copy(dir, unet_dir(), [&](auto& ts, auto&) {
      TensorToWrite* t = find_tw(ts, victim);
      std::swap(t->shape[0], t->shape[1]);  // [64,48] -> [48,64]
    });
    auto m = UNet2DConditionModel::load(folder, Precision::kF32);
    REQUIRE_FALSE(m.is_ok());
    CHECK_THAT(m.status().message(), Catch::Contains("mis-shaped") && Catch::Contains(victim) &&
                                         Catch::Contains("[48,64]"));
  }
}

TEST_CASE("unet: a config with other widths, heads and layers builds and runs", "[nets][unet]") {
  // Not the tiny or full sizes: 3 levels, 1 layer per block, 4 groups, heads 1/2/4.
  UNetConfig cfg;
  cfg.down_block_types = {"CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"};
  cfg.up_block_types = {"UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"};
  cfg.block_out_channels = {16, 24, 32};
  cfg.num_heads = {1, 2, 4};
  cfg.layers_per_block = 1;
  cfg.norm_num_groups = 4;
  cfg.cross_attention_dim = 12;
  auto m = UNet2DConditionModel::build(cfg);
  REQUIRE(m.is_ok());
  // Bind every parameter to a small deterministic value through the visitor.
  struct Filler : ParamVisitor {
    std::vector<std::unique_ptr<std::vector<float>>> store;
    size_t count = 0;
    void param(const std::string& name, Param& p, const std::vector<int64_t>& shape) override {
      int64_t n = 1;
      for (int64_t d : shape) n *= d;
      auto v = std::make_unique<std::vector<float>>(size_t(n));
      const bool norm =
          name.find("norm") != std::string::npos && name.find(".weight") != std::string::npos;
      for (int64_t i = 0; i < n; ++i)
        (*v)[size_t(i)] = norm ? 1.0f : 0.05f * float(std::sin(double(i) * 0.37 + double(count)));
      p.data = v->data();
      p.shape = shape;
      store.push_back(std::move(v));
      ++count;
    }
  } filler;
  (*m)->visit(filler);
  CHECK(filler.count > 50);
  (*m)->pack(Precision::kF32);
  Tensor z = Tensor::f32({2, 4, 7, 5}), ctx = Tensor::f32({2, 5, 12});
  for (int64_t i = 0; i < z.numel(); ++i) z.f32()[i] = float(std::cos(double(i)));
  for (int64_t i = 0; i < ctx.numel(); ++i) ctx.f32()[i] = float(std::sin(double(i)));
  auto eps = (*m)->forward(z, 199, ctx, {}, &ThreadPool::global());
  REQUIRE(eps.is_ok());
  CHECK(eps->shape() == Shape{2, 4, 7, 5});
  for (int64_t i = 0; i < eps->numel(); ++i) REQUIRE(std::isfinite(eps->f32()[i]));
}

namespace {

// A full-size checkpoint written straight from the manifest's names and shapes, in BF16, with a
// cheap deterministic fill (a repeated pseudo-random block scaled by 1/sqrt(fan_in); norm weights
// 1, biases small). write_synthetic_component() draws every value independently, which for the
// 866M-parameter U-Net takes over a minute on a shared 2-core machine; the VAE test uses it.
Status write_fast_full_checkpoint(const std::string& manifest, const std::string& dir,
                                  const std::string& class_name) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(manifest));
  const nlohmann::json m = nlohmann::json::parse(text);
  nlohmann::json config = m["config"];
  config["_class_name"] = class_name;
  std::filesystem::create_directories(dir);
  MACRO_TRY(write_file_atomic(dir + "/config.json", config.dump(1)));
  std::map<int64_t, std::vector<uint16_t>> by_fan_in;  // fan_in -> pattern of the largest size
  std::vector<std::pair<std::string, std::vector<int64_t>>> tensors;
  std::map<int64_t, int64_t> max_numel;
  for (auto it = m["tensors"].begin(); it != m["tensors"].end(); ++it) {
    std::vector<int64_t> shape = it.value()["shape"].get<std::vector<int64_t>>();
    int64_t n = 1, fan_in = 1;
    for (size_t i = 0; i < shape.size(); ++i) n *= shape[i], fan_in *= i ? shape[i] : 1;
    const bool norm_w = it.key().find("norm") != std::string::npos && it.key().size() > 7 &&
                        it.key().compare(it.key().size() - 7, 7, ".weight") == 0;
    const int64_t key = shape.size() == 1 ? (norm_w ? -1 : 0) : fan_in;
    max_numel[key] = std::max(max_numel[key], n);
    tensors.emplace_back(it.key(), shape);
  }
  for (auto [key, n] : max_numel) {
    std::vector<uint16_t>& buf = by_fan_in[key];
    buf.resize(size_t(n));
    const float s = key == -1 ? 0.0f : key == 0 ? 0.02f : float(1.0 / std::sqrt(double(key)));
    uint32_t x = 12345u + uint32_t(key);
    constexpr size_t kBlock = 4099;  // prime: the pattern does not align with rows
    for (size_t i = 0; i < std::min(buf.size(), kBlock); ++i) {
      x = x * 1664525u + 1013904223u;
      const float u = float(x >> 8) / float(1u << 24) * 2.0f - 1.0f;  // U(-1, 1)
      buf[i] = f32_to_bf16(key == -1 ? 1.0f + 0.05f * u : s * 1.7f * u);
    }
    for (size_t i = kBlock; i < buf.size(); ++i) buf[i] = buf[i - kBlock];
  }
  std::vector<TensorToWrite> ts;
  for (const auto& [name, shape] : tensors) {
    int64_t fan_in = 1;
    for (size_t i = 1; i < shape.size(); ++i) fan_in *= shape[i];
    const bool norm_w = name.find("norm") != std::string::npos && name.size() > 7 &&
                        name.compare(name.size() - 7, 7, ".weight") == 0;
    const int64_t key = shape.size() == 1 ? (norm_w ? -1 : 0) : fan_in;
    ts.push_back({name, DType::kBF16, shape, by_fan_in.at(key).data()});
  }
  return write_safetensors(dir + "/diffusion_pytorch_model.safetensors", ts);
}

}  // namespace

TEST_CASE("unet: the full-size SD-Turbo layout from the manifest loads (bf16 storage)",
          "[nets][unet][full]") {
  test::TempDir dir("unet-full");
  auto tw = std::chrono::steady_clock::now();
  const Status w = write_fast_full_checkpoint(test::golden_dir() + "/manifests/unet.json", dir.path,
                                              "UNet2DConditionModel");
  INFO(w.message());
  REQUIRE(w.is_ok());
  auto t0 = std::chrono::steady_clock::now();
  std::printf("full unet write %.1f s\n", std::chrono::duration<double>(t0 - tw).count());
  auto m = UNet2DConditionModel::load(dir.path, Precision::kBf16);
  std::printf("full unet load %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  INFO((m.is_ok() ? "" : m.status().message()));
  REQUIRE(m.is_ok());
  CHECK((*m)->config().block_out_channels == std::vector<int>{320, 640, 1280, 1280});
  CHECK((*m)->config().num_heads == std::vector<int>{5, 10, 20, 20});
  // One small forward (latent 8x8, one view) proves the packed tree is complete.
  Tensor z = Tensor::f32({1, 4, 8, 8}), ctx = Tensor::f32({1, 77, 1024});
  for (int64_t i = 0; i < z.numel(); ++i) z.f32()[i] = float(std::sin(double(i)));
  for (int64_t i = 0; i < ctx.numel(); ++i) ctx.f32()[i] = float(std::cos(double(i) * 0.01));
  auto t1 = std::chrono::steady_clock::now();
  auto eps = (*m)->forward(z, 199, ctx, {}, &ThreadPool::global());
  std::printf("full unet forward 8x8 %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count());
  REQUIRE(eps.is_ok());
  for (int64_t i = 0; i < eps->numel(); ++i) REQUIRE(std::isfinite(eps->f32()[i]));
}

TEST_CASE("unet/vae: planned scratch at the full SD-Turbo / Difix sizes", "[nets][unet][vae]") {
  auto text = read_text_file(test::golden_dir() + "/manifests/unet.json");
  REQUIRE(text.is_ok());
  const nlohmann::json m = nlohmann::json::parse(*text);
  auto cfg = parse_unet_config(m["config"].dump(), "unet.json");
  REQUIRE(cfg.is_ok());
  auto unet = UNet2DConditionModel::build(*cfg);  // structure only: planning reads no weights
  REQUIRE(unet.is_ok());
  auto vtext = read_text_file(test::golden_dir() + "/manifests/vae.json");
  REQUIRE(vtext.is_ok());
  auto vcfg = parse_vae_config(nlohmann::json::parse(*vtext)["config"].dump(), "vae.json");
  REQUIRE(vcfg.is_ok());
  auto vae = DifixVae::build(*vcfg);
  REQUIRE(vae.is_ok());
  const double gib = 1024.0 * 1024.0 * 1024.0;
  for (auto [views, h, w] :
       {std::tuple{1, 64, 64}, std::tuple{2, 72, 128}, std::tuple{5, 72, 128}}) {
    const double u = double((*unet)->workspace_bytes(views, h, w)) / gib;
    std::printf("unet scratch: %d view(s) latent %dx%d: %.2f GiB\n", views, h, w, u);
    CHECK(u < 1.5 * views);  // activations only: no N x N attention matrix anywhere
  }
  for (auto [h, w] : {std::pair{512, 512}, std::pair{576, 1024}}) {
    const double e = double((*vae)->encode_workspace_bytes(h, w)) / gib;
    const double d = double((*vae)->decode_workspace_bytes(h, w)) / gib;
    std::printf("vae scratch %dx%d: encode %.2f GiB, decode %.2f GiB\n", h, w, e, d);
    CHECK(d < 3.0);
  }
}

TEST_CASE("nn-run unet folder: golden case through the library entry point",
          "[nets][unet][nn-run]") {
  test::TempDir dir("nn-run-unet");
  auto g = SafeTensors::open(unet_dir() + "/case-odd.safetensors");
  REQUIRE(g.is_ok());
  Tensor z = read_tensor(*g, "input.z"), ctx = read_tensor(*g, "input.ctx");
  const int64_t t = 199;
  const std::string in = dir.file("in.safetensors"), out = dir.file("out.safetensors");
  REQUIRE(write_safetensors(in, {{"input.z", DType::kF32, z.shape(), z.f32()},
                                 {"input.ctx", DType::kF32, ctx.shape(), ctx.f32()},
                                 {"input.timestep", DType::kI64, {1}, &t}})
              .is_ok());
  NnRunOptions opt;
  opt.model = unet_dir();
  opt.inputs = in;
  opt.out = out;
  opt.pool = &ThreadPool::global();
  Status s = nn_run(opt);
  INFO(s.message());
  REQUIRE(s.is_ok());
  auto o = SafeTensors::open(out);
  REQUIRE(o.is_ok());
  CHECK(o->metadata().at("model") == "unet");
  check_close("nn-run output.eps", read_tensor(*o, "output.eps"), read_tensor(*g, "output.eps"),
              kFp32);
  // A NaN in the input is refused naming the tensor.
  z.f32()[5] = NAN;
  REQUIRE(write_safetensors(in, {{"input.z", DType::kF32, z.shape(), z.f32()},
                                 {"input.ctx", DType::kF32, ctx.shape(), ctx.f32()}})
              .is_ok());
  Status bad = nn_run(opt);
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.message(), Catch::Contains("input.z") && Catch::Contains("NaN"));
  // A context of the wrong width is refused naming the tensor and the expected layout.
  z.f32()[5] = 0.0f;
  Tensor ctx40 = Tensor::f32({1, 77, 40});
  REQUIRE(write_safetensors(in, {{"input.z", DType::kF32, z.shape(), z.f32()},
                                 {"input.ctx", DType::kF32, ctx40.shape(), ctx40.f32()}})
              .is_ok());
  Status bad_ctx = nn_run(opt);
  REQUIRE_FALSE(bad_ctx.is_ok());
  CHECK_THAT(bad_ctx.message(), Catch::Contains("input.ctx") && Catch::Contains("48"));
}
