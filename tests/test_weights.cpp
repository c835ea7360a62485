// Checkpoint plumbing: diffusers configs, the weight store's name table and LoRA merge, the DDPM
// constants, and synthetic checkpoints written from the real manifests.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "attention/nets/diffusers_config.h"
#include "attention/nets/scheduler.h"
#include "attention/nets/unet.h"
#include "attention/nets/synthetic_checkpoint.h"
#include "attention/nets/weights.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/tensor.h"
#include "attention/runtime/thread_pool.h"
#include "test_support.h"

using namespace macro;
using namespace macro::nets;

TEST_CASE("diffusers configs: tiny goldens and manifests parse, bad fields are named", "[nets][config]") {
  const std::string g = test::golden_dir();
  auto unet = load_unet_config(g + "/unet-tiny/config.json");
  INFO(unet.status().message());
  REQUIRE(unet.is_ok());
  REQUIRE(unet->block_out_channels == std::vector<int>{32, 64, 64, 64});
  REQUIRE(unet->num_heads == std::vector<int>{2, 4, 4, 4});  // legacy attention_head_dim = head counts
  REQUIRE(unet->cross_attention_dim == 48);
  REQUIRE(unet->norm_num_groups == 8);
  auto vae = load_vae_config(g + "/vae-tiny/config.json");
  REQUIRE(vae.is_ok());
  REQUIRE(vae->lora_rank == 2);
  REQUIRE(vae->lora_scale == Approx(2.0));
  auto clip = load_clip_text_config(g + "/clip/text-encoder-tiny/config.json");
  REQUIRE(clip.is_ok());
  REQUIRE(clip->num_hidden_layers == 3);
  // Full-size configs embedded in the manifests; the release VAE has lora_rank 4 and no alpha:
  // PEFT's default alpha 8 gives the scale 2.0.
  auto manifest = read_text_file(g + "/manifests/vae.json");
  REQUIRE(manifest.is_ok());
  auto mj = nlohmann::json::parse(*manifest);
  auto cfg = mj["config"];
  cfg.erase("lora_alpha_over_rank");
  auto full_vae = parse_vae_config(cfg.dump(), "vae.json");
  REQUIRE(full_vae.is_ok());
  REQUIRE(full_vae->lora_rank == 4);
  REQUIRE(full_vae->lora_scale == Approx(2.0));
  // Errors name the field and what was found.
  auto bad = parse_unet_config(R"({"block_out_channels":[32],"down_block_types":["FooBlock"],
      "up_block_types":["UpBlock2D"],"attention_head_dim":2,"norm_num_groups":8})", "cfg");
  REQUIRE_FALSE(bad.is_ok());
  REQUIRE(bad.status().message().find("down_block_types[0]") != std::string::npos);
  REQUIRE(bad.status().message().find("FooBlock") != std::string::npos);
  auto bad_type = parse_unet_config(R"({"layers_per_block":"two"})", "cfg");
  REQUIRE_FALSE(bad_type.is_ok());
  REQUIRE(bad_type.status().message().find("layers_per_block") != std::string::npos);
}

TEST_CASE("DDPM: abar_199 matches the golden constant, x0 step", "[nets][scheduler]") {
  auto st = SafeTensors::open(test::golden_dir() + "/difix-tiny/case-ref2.safetensors");
  REQUIRE(st.is_ok());
  auto golden = st->read_f32("const.alpha_bar_199");
  REQUIRE(golden.is_ok());
  auto abar = alpha_bar(DdpmSchedule{}, 199);
  REQUIRE(abar.is_ok());
  REQUIRE(std::abs(*abar - (*golden)[0]) < 1e-6);
  REQUIRE(std::abs(*abar - 0.7552384) < 2e-6);  // the fp64 value in the spec, fp32 computed
  float z[2] = {1.0f, -0.5f}, eps[2] = {0.25f, 2.0f}, z0[2];
  REQUIRE(ddpm_x0(DdpmSchedule{}, 199, z, eps, z0, 2).is_ok());
  for (int i = 0; i < 2; ++i)
    REQUIRE(z0[i] == Approx((z[i] - std::sqrt(1 - *abar) * eps[i]) / std::sqrt(*abar)).epsilon(1e-6));
  REQUIRE_FALSE(alpha_bar(DdpmSchedule{}, 1000).is_ok());
  REQUIRE_FALSE(alpha_bar(DdpmSchedule{}, -1).is_ok());
}

TEST_CASE("weight store: LoRA merged as base + scale * B @ A, names reported", "[nets][weights]") {
  const std::string path = test::golden_dir() + "/vae-tiny/diffusion_pytorch_model.safetensors";
  auto raw = SafeTensors::open(path);
  REQUIRE(raw.is_ok());
  auto store = WeightStore::open(path, {2.0, {}});
  INFO((store ? std::string() : store.status().message()));
  REQUIRE(store.is_ok());
  const std::string m = "decoder.skip_conv_2";
  auto base = raw->read_f32(m + ".base_layer.weight");
  auto A = raw->read_f32(m + ".lora_A.vae_skip.weight");
  auto B = raw->read_f32(m + ".lora_B.vae_skip.weight");
  REQUIRE((base.is_ok() && A.is_ok() && B.is_ok()));
  const auto shape = raw->find(m + ".base_layer.weight")->shape;  // [out, in, 1, 1]
  const int64_t out = shape[0], in = shape[1], r = raw->find(m + ".lora_A.vae_skip.weight")->shape[0];
  Param p;
  (*store)->param(m + ".weight", p, shape);
  REQUIRE(p.loaded());
  double max_err = 0, max_delta = 0;
  for (int64_t o = 0; o < out; ++o)
    for (int64_t i = 0; i < in; ++i) {
      double acc = 0;
      for (int64_t q = 0; q < r; ++q) acc += double((*B)[o * r + q]) * (*A)[q * in + i];
      double expect = (*base)[o * in + i] + 2.0 * acc;
      max_err = std::max(max_err, std::abs(expect - p.data[o * in + i]));
      max_delta = std::max(max_delta, std::abs(2.0 * acc));
    }
  REQUIRE(max_err < 1e-6);
  REQUIRE(max_delta > 1e-4);  // the LoRA really changes the weight
  // A walk that asks for only one tensor: the rest are reported unused, a wrong name missing,
  // a wrong shape mis-shaped — each by name.
  Param q, wrong;
  (*store)->param("decoder.no_such.weight", q, {3});
  (*store)->param("encoder.conv_in.bias", wrong, {999});
  Status s = (*store)->finish();
  REQUIRE_FALSE(s.is_ok());
  REQUIRE(s.message().find("decoder.no_such.weight") != std::string::npos);
  REQUIRE(s.message().find("encoder.conv_in.bias: expected [999]") != std::string::npos);
  REQUIRE(s.message().find("unused") != std::string::npos);
  // Without a LoRA scale, unmerged adapters are an error naming a LoRA tensor.
  auto no_scale = WeightStore::open(path, {0.0, {}});
  REQUIRE_FALSE(no_scale.is_ok());
  REQUIRE(no_scale.status().message().find("lora_A") != std::string::npos);
}

TEST_CASE("weight store: legacy VAE attention names map to to_q/to_k/to_v/to_out.0", "[nets][weights]") {
  test::TempDir dir("legacy");
  std::vector<float> w(16, 0.5f), b(4, 0.25f);
  const std::string file = dir.file("vae.safetensors");
  REQUIRE(write_safetensors(file, {{"encoder.mid_block.attentions.0.query.weight", DType::kF32, {4, 4, 1, 1}, w.data()},
                                   {"encoder.mid_block.attentions.0.query.bias", DType::kF32, {4}, b.data()},
                                   {"encoder.mid_block.attentions.0.proj_attn.weight", DType::kF32, {4, 4}, w.data()}})
              .is_ok());
  auto store = WeightStore::open(file);
  REQUIRE(store.is_ok());
  Param q, qb, o;
  (*store)->param("encoder.mid_block.attentions.0.to_q.weight", q, {4, 4});
  (*store)->param("encoder.mid_block.attentions.0.to_q.bias", qb, {4});
  (*store)->param("encoder.mid_block.attentions.0.to_out.0.weight", o, {4, 4});
  REQUIRE((q.loaded() && qb.loaded() && o.loaded()));
  REQUIRE(q.data[5] == 0.5f);
  REQUIRE((*store)->finish().is_ok());
}

TEST_CASE("synthetic checkpoint from the real VAE manifest has its exact names and shapes", "[nets][weights][synthetic]") {
  test::TempDir dir("synth-vae");
  const std::string manifest = test::golden_dir() + "/manifests/vae.json";
  REQUIRE(write_synthetic_component(manifest, dir.path + "/vae", "AutoencoderKL", {7, true}).is_ok());
  auto mtext = read_text_file(manifest);
  REQUIRE(mtext.is_ok());
  auto mj = nlohmann::json::parse(*mtext);
  auto st = SafeTensors::open(dir.path + "/vae/diffusion_pytorch_model.safetensors");
  INFO((st ? std::string() : st.status().message()));
  REQUIRE(st.is_ok());
  REQUIRE(st->names().size() == mj["tensors"].size());
  int64_t params = 0;
  for (auto it = mj["tensors"].begin(); it != mj["tensors"].end(); ++it) {
    const TensorEntry* e = st->find(it.key());
    REQUIRE(e != nullptr);
    REQUIRE(e->shape == it.value()["shape"].get<std::vector<int64_t>>());
    params += e->numel();
  }
  REQUIRE(params == mj["parameters"].get<int64_t>());
  auto cfg = load_vae_config(dir.path + "/vae/config.json");
  REQUIRE(cfg.is_ok());
  REQUIRE(cfg->block_out_channels == std::vector<int>{128, 256, 512, 512});
  // Values are spread as documented (weights ~ N(0, 1/fan_in), norm weights near 1).
  auto w = st->read_f32("encoder.down_blocks.1.resnets.0.conv1.weight");  // fan_in 128*9
  REQUIRE(w.is_ok());
  double ss = 0;
  for (float v : *w) ss += double(v) * v;
  REQUIRE(std::sqrt(ss / double(w->size())) == Approx(1.0 / std::sqrt(128.0 * 9)).epsilon(0.02));
}

TEST_CASE("synthetic checkpoints are deterministic in the seed, independent of threads", "[nets][weights][synthetic]") {
  test::TempDir dir("synth-small");
  const std::string manifest = dir.file("m.json");
  REQUIRE(write_file_atomic(manifest, R"({"config":{"block_out_channels":[8]},"tensors":{
      "a.weight":{"dtype":"F32","shape":[300,700]},"a.bias":{"dtype":"F32","shape":[300]},
      "n.weight":{"dtype":"F32","shape":[300]}}})").is_ok());
  REQUIRE(write_synthetic_component(manifest, dir.file("x"), "AutoencoderKL", {3, false}).is_ok());
  ThreadPool::set_global_threads(1);
  REQUIRE(write_synthetic_component(manifest, dir.file("y"), "AutoencoderKL", {3, false}).is_ok());
  ThreadPool::set_global_threads(0);
  REQUIRE(write_synthetic_component(manifest, dir.file("z"), "AutoencoderKL", {4, false}).is_ok());
  auto x = read_file(dir.file("x/diffusion_pytorch_model.safetensors"));
  auto y = read_file(dir.file("y/diffusion_pytorch_model.safetensors"));
  auto z = read_file(dir.file("z/diffusion_pytorch_model.safetensors"));
  REQUIRE((x.is_ok() && y.is_ok() && z.is_ok()));
  REQUIRE(*x == *y);
  REQUIRE(*x != *z);
  // A bad manifest is an error naming the file.
  REQUIRE(write_file_atomic(dir.file("bad.json"), R"({"tensors":{"a":{"shape":[-1]}},"config":{}})").is_ok());
  Status s = write_synthetic_component(dir.file("bad.json"), dir.file("w"), "X", {});
  REQUIRE_FALSE(s.is_ok());
  REQUIRE(s.message().find("bad.json") != std::string::npos);
}

TEST_CASE("macro synth-weights writes a loadable VAE folder and refuses bad flags", "[nets][weights][synthetic]") {
  test::TempDir dir("synth-weights-cli");
  const std::string manifest = test::golden_dir() + "/manifests/vae.json";
  const std::string exe = test::macro_exe();
  REQUIRE(test::run_command(exe + " synth-weights --quiet --manifest " + manifest +
                            " --class AutoencoderKL --dtype bf16 --out " + dir.file("vae") +
                            " > /dev/null") == 0);
  auto cfg = load_vae_config(dir.file("vae/config.json"));
  REQUIRE(cfg.is_ok());
  auto store = WeightStore::open(dir.file("vae/diffusion_pytorch_model.safetensors"), {cfg->lora_scale, {}});
  INFO((store ? std::string() : store.status().message()));
  REQUIRE(store.is_ok());
  REQUIRE(test::run_command(exe + " synth-weights --manifest " + manifest + " --class Foo --out " +
                            dir.file("x") + " 2> /dev/null") == 1);
  REQUIRE(test::run_command(exe + " synth-weights --manifest " + dir.file("missing.json") +
                            " --class AutoencoderKL --out " + dir.file("y") + " 2> /dev/null") == 1);
  REQUIRE_FALSE(file_exists(dir.file("y/diffusion_pytorch_model.safetensors")));
}

namespace {

// unet-tiny rewritten twice with the same values: every tensor rounded to bf16 and stored as BF16
// (`<dir>/bf16`) and stored as F32 (`<dir>/f32`), each a loadable U-Net folder. Returns the largest
// tensor's fp32 bytes.
size_t write_bf16_unet_copies(const std::string& dir) {
  namespace fs = std::filesystem;
  const std::string src = test::golden_dir() + "/unet-tiny";
  auto f = SafeTensors::open(src + "/diffusion_pytorch_model.safetensors");
  REQUIRE(f.is_ok());
  std::vector<std::vector<float>> f32s;
  std::vector<std::vector<uint16_t>> bf16s;
  std::vector<TensorToWrite> as_f32, as_bf16;
  size_t largest = 0;
  for (const std::string& name : f->names()) {
    auto v = f->read_f32(name);
    REQUIRE(v.is_ok());
    largest = std::max(largest, v->size() * sizeof(float));
    std::vector<uint16_t> b(v->size());
    f32_to_bf16(v->data(), b.data(), int64_t(b.size()));
    bf16_to_f32(b.data(), v->data(), int64_t(b.size()));
    f32s.push_back(std::move(*v));
    bf16s.push_back(std::move(b));
    const auto& shape = f->find(name)->shape;
    as_f32.push_back({name, DType::kF32, shape, f32s.back().data()});
    as_bf16.push_back({name, DType::kBF16, shape, bf16s.back().data()});
  }
  for (const char* kind : {"f32", "bf16"}) {
    const std::string folder = dir + "/" + kind;
    fs::create_directories(folder);
    fs::copy_file(src + "/config.json", folder + "/config.json");
    REQUIRE(write_safetensors(folder + "/diffusion_pytorch_model.safetensors",
                              std::string(kind) == "f32" ? as_f32 : as_bf16)
                .is_ok());
  }
  return largest;
}

}  // namespace

TEST_CASE("loading keeps no widened copies: packed straight from the file, bytes accounted",
          "[nets][weights][memory]") {
  test::TempDir dir("lazy-load");
  const size_t largest = write_bf16_unet_copies(dir.path);
  auto g = SafeTensors::open(test::golden_dir() + "/unet-tiny/case-ref2.safetensors");
  REQUIRE(g.is_ok());
  auto zv = g->read_f32("input.z");
  auto cv = g->read_f32("input.ctx");
  REQUIRE((zv.is_ok() && cv.is_ok()));
  const Tensor z = Tensor::from_f32(g->find("input.z")->shape, *zv);
  const Tensor ctx = Tensor::from_f32(g->find("input.ctx")->shape, *cv);
  for (Precision p : {Precision::kF32, Precision::kBf16}) {
    reset_widen_peak();
    REQUIRE(widen_stats().live_bytes == 0);
    auto from_bf16 = UNet2DConditionModel::load(dir.path + "/bf16", p);
    INFO((from_bf16.is_ok() ? "" : from_bf16.status().message()));
    REQUIRE(from_bf16.is_ok());
    const WidenStats s = widen_stats();
    auto from_f32 = UNet2DConditionModel::load(dir.path + "/f32", p);
    REQUIRE(from_f32.is_ok());
    const size_t wb = (*from_bf16)->weight_bytes();
    std::printf(
        "unet-tiny %s from a BF16 file: packed %zu bytes (from F32 %zu), transient "
        "fp32 peak %zu bytes (largest tensor %zu)\n",
        precision_name(p), wb, (*from_f32)->weight_bytes(), s.peak_bytes, largest);
    // Nothing widened survives the load, and at most one fused q|k|v (three tensors) was ever
    // widened at once; a bf16 run widens only conv weights (the bf16 conv packing takes fp32).
    CHECK(widen_stats().live_bytes == 0);
    CHECK(s.peak_bytes <= 3 * largest);
    CHECK(s.peak_bytes > 0);
    // The loaded model holds exactly its packed form, the same whatever the file's dtype.
    CHECK(wb == (*from_f32)->weight_bytes());
    // Packing from the BF16 bytes gives bit-identical results to packing the same values from F32.
    auto a = (*from_bf16)->forward(z, 199, ctx, {}, &ThreadPool::global());
    auto b = (*from_f32)->forward(z, 199, ctx, {}, &ThreadPool::global());
    REQUIRE((a.is_ok() && b.is_ok()));
    REQUIRE(a->numel() == b->numel());
    CHECK(std::memcmp(a->f32(), b->f32(), size_t(a->numel()) * sizeof(float)) == 0);
  }
  // The packed size tracks the precision: bf16 GEMM/conv panels are half the fp32 ones (the fp32
  // norm/bias vectors and panel padding keep it a little above half) with the direct convs; the
  // Winograd packs of the convs that get them are 16/9 of a direct pack, and are counted too.
  auto m32 = UNet2DConditionModel::load(dir.path + "/bf16", Precision::kF32);
  const ConvWinograd mode = conv2d_set_winograd(ConvWinograd::kOff);
  auto m16 = UNet2DConditionModel::load(dir.path + "/bf16", Precision::kBf16);
  conv2d_set_winograd(ConvWinograd::kAlways);
  auto m16w = UNet2DConditionModel::load(dir.path + "/bf16", Precision::kBf16);
  conv2d_set_winograd(mode);
  REQUIRE((m32.is_ok() && m16.is_ok() && m16w.is_ok()));
  CHECK(double((*m16)->weight_bytes()) < 0.6 * double((*m32)->weight_bytes()));
  CHECK((*m16w)->weight_bytes() > (*m16)->weight_bytes());
  CHECK((*m16w)->weight_bytes() < (*m32)->weight_bytes());
  // An eager store (the default, for small loaders) owns converted copies; a lazy one owns none.
  WeightStoreOptions lazy;
  lazy.lazy = true;
  auto eager_store = WeightStore::open(dir.path + "/bf16/diffusion_pytorch_model.safetensors");
  auto lazy_store = WeightStore::open(dir.path + "/bf16/diffusion_pytorch_model.safetensors", lazy);
  REQUIRE((eager_store.is_ok() && lazy_store.is_ok()));
  auto u1 = UNet2DConditionModel::build(*load_unet_config(dir.path + "/bf16/config.json"));
  auto u2 = UNet2DConditionModel::build(*load_unet_config(dir.path + "/bf16/config.json"));
  REQUIRE((u1.is_ok() && u2.is_ok()));
  (*u1)->visit(**eager_store);
  (*u2)->visit(**lazy_store);
  REQUIRE(((*eager_store)->finish().is_ok() && (*lazy_store)->finish().is_ok()));
  CHECK((*eager_store)->owned_bytes() >= size_t(largest));
  CHECK((*lazy_store)->owned_bytes() == 0);
}
