// The CLIP text encoder (attention/nets/clip_text.h) against shared/golden/clip/text-encoder-tiny
// (3 layers, 64 wide, 4 heads, exact GELU; OpenCLIP reference), its loader's reports, the prompt
// cache (attention/nets/prompt_cache.h) and `macro nn-run` on a CLIPTextModel folder.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "attention/nets/clip_text.h"
#include "attention/nets/clip_tokenizer.h"
#include "attention/nets/difix.h"
#include "attention/nets/prompt_cache.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "test_support.h"
#include "tiny_checkpoint_fixture.h"

using namespace macro;
using namespace macro::nets;
namespace fs = std::filesystem;

namespace {

std::string te_dir() {
  return test::golden_dir() + "/clip/text-encoder-tiny";
}
std::string case_path() {
  return te_dir() + "/case-prompts.safetensors";
}

std::vector<int32_t> read_ids(const SafeTensors& f, const std::string& name) {
  const TensorEntry* e = f.find(name);
  REQUIRE(e != nullptr);
  REQUIRE(e->dtype == DType::kI64);
  std::vector<int32_t> ids(size_t(e->numel()));
  for (size_t i = 0; i < ids.size(); ++i) {
    int64_t v;
    std::memcpy(&v, e->data + 8 * i, 8);
    ids[i] = int32_t(v);
  }
  return ids;
}

std::vector<float> read_f32(const SafeTensors& f, const std::string& name) {
  auto v = f.read_f32(name);
  REQUIRE(v.is_ok());
  return *v;
}

// rel L2 <= 1e-4 and max abs <= 1e-3 (golden README, fp32 network outputs).
void check_golden(const std::string& what, const float* got, const std::vector<float>& want) {
  const test::Diff d = test::compare(got, want.data(), want.size());
  std::printf("  %-28s rel L2 %.3e  max abs %.3e\n", what.c_str(), d.rel_l2, d.max_abs);
  INFO(what << ": rel L2 " << d.rel_l2 << ", max abs " << d.max_abs);
  CHECK(d.rel_l2 <= 1e-4);
  CHECK(d.max_abs <= 1e-3);
}

// A pipeline-shaped folder holding only tokenizer/ and text_encoder/ (symlinked goldens).
std::string make_text_folder(const test::TempDir& dir, bool copy_weights = false) {
  const std::string root = dir.path + "/pipe";
  fs::create_directories(root);
  fs::create_directory_symlink(test::golden_dir() + "/clip/tokenizer", root + "/tokenizer");
  if (copy_weights) {
    fs::create_directories(root + "/text_encoder");
    fs::copy_file(te_dir() + "/config.json", root + "/text_encoder/config.json");
    fs::copy_file(te_dir() + "/model.safetensors", root + "/text_encoder/model.safetensors");
  } else {
    fs::create_directory_symlink(te_dir(), root + "/text_encoder");
  }
  return root;
}

}  // namespace

TEST_CASE("clip text-encoder-tiny matches the golden last_hidden_state on every ISA path",
          "[nets][clip]") {
  auto g = SafeTensors::open(case_path());
  REQUIRE(g.is_ok());
  const Isa saved = active_isa();
  for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
    if (!isa_supported(isa)) {
      std::printf("clip text-encoder-tiny: %s not supported here, skipped\n", isa_name(isa));
      continue;
    }
    REQUIRE(set_isa(isa).is_ok());
    auto model = ClipTextModel::load(te_dir());  // packed for this path
    INFO((model.is_ok() ? "" : model.status().message()));
    REQUIRE(model.is_ok());
    std::printf("clip text-encoder-tiny [%s]\n", isa_name(isa));
    for (int k = 0; k < 2; ++k) {
      const std::vector<int32_t> ids = read_ids(*g, "input.ids" + std::to_string(k));
      auto out = (*model)->forward(ids, 1, &ThreadPool::global());
      REQUIRE(out.is_ok());
      REQUIRE(out->shape() == Shape{1, 77, 64});
      check_golden("output.hidden" + std::to_string(k), out->f32(),
                   read_f32(*g, "output.hidden" + std::to_string(k)));
    }
    // Both prompts as one batch give the same rows.
    std::vector<int32_t> both = read_ids(*g, "input.ids0");
    const std::vector<int32_t> ids1 = read_ids(*g, "input.ids1");
    both.insert(both.end(), ids1.begin(), ids1.end());
    auto out = (*model)->forward(both, 2, nullptr);
    REQUIRE(out.is_ok());
    check_golden("batch of 2, row 1", out->f32() + 77 * 64, read_f32(*g, "output.hidden1"));
  }
  REQUIRE(set_isa(saved).is_ok());
}

TEST_CASE("clip: the tokenizer's ids of the Difix prompt are the golden's input.ids0",
          "[nets][clip]") {
  auto g = SafeTensors::open(case_path());
  REQUIRE(g.is_ok());
  auto tok = ClipTokenizer::load(test::golden_dir() + "/clip/tokenizer");
  REQUIRE(tok.is_ok());
  CHECK(tok->encode(kDifixPrompt) == read_ids(*g, "input.ids0"));
  CHECK(tok->encode("A photo of a cat, sitting on the mat!") == read_ids(*g, "input.ids1"));
}

TEST_CASE("clip: bad ids are refused naming the token", "[nets][clip]") {
  auto model = ClipTextModel::load(te_dir());
  REQUIRE(model.is_ok());
  std::vector<int32_t> ids(77, 0);
  ids[5] = 49408;
  auto r = (*model)->forward(ids, 1, nullptr, "prompt");
  REQUIRE_FALSE(r.is_ok());
  CHECK_THAT(r.status().message(), Catch::Contains("token 5") && Catch::Contains("49408"));
  auto r2 = (*model)->forward(std::vector<int32_t>(78, 0), 1, nullptr, "prompt");
  REQUIRE_FALSE(r2.is_ok());
  CHECK_THAT(r2.status().message(), Catch::Contains("at most 77"));
}

TEST_CASE("clip loader reports missing, unused and mis-shaped tensors by name", "[nets][clip]") {
  auto src = SafeTensors::open(te_dir() + "/model.safetensors");
  REQUIRE(src.is_ok());
  test::TempDir dir("clip-loader");
  fs::copy_file(te_dir() + "/config.json", dir.file("config.json"));
  const std::string dropped = "text_model.encoder.layers.1.mlp.fc2.bias";
  const std::string reshaped = "text_model.encoder.layers.2.self_attn.q_proj.weight";
  const std::vector<float> extra(3, 0.5f);
  const std::vector<float> small(64 * 32, 0.0f);
  auto write_variant = [&](bool drop, bool add, bool reshape) {
    std::vector<TensorToWrite> ts;
    for (const std::string& n : src->names()) {
      if (drop && n == dropped) continue;
      const TensorEntry* e = src->find(n);
      if (reshape && n == reshaped) {
        ts.push_back({n, DType::kF32, {64, 32}, small.data()});
        continue;
      }
      ts.push_back({n, e->dtype, e->shape, e->data});
    }
    if (add)
      ts.push_back({"text_model.encoder.layers.9.extra.weight", DType::kF32, {3}, extra.data()});
    // The position_ids buffer of the real download is ignored, never reported.
    static const std::vector<int64_t> pos = [] {
      std::vector<int64_t> p(77);
      for (int i = 0; i < 77; ++i) p[size_t(i)] = i;
      return p;
    }();
    ts.push_back({"text_model.embeddings.position_ids", DType::kI64, {1, 77}, pos.data()});
    REQUIRE(write_safetensors(dir.file("model.safetensors"), ts).is_ok());
  };
  write_variant(false, false, false);
  {
    auto ok = ClipTextModel::load(dir.path);
    INFO((ok.is_ok() ? "" : ok.status().message()));
    CHECK(ok.is_ok());
  }
  write_variant(true, false, false);
  auto missing = ClipTextModel::load(dir.path);
  REQUIRE_FALSE(missing.is_ok());
  std::printf("missing:    %s\n", missing.status().message().c_str());
  CHECK_THAT(missing.status().message(), Catch::Contains(dropped) && Catch::Contains("missing"));
  write_variant(false, true, false);
  auto unused = ClipTextModel::load(dir.path);
  REQUIRE_FALSE(unused.is_ok());
  std::printf("unused:     %s\n", unused.status().message().c_str());
  CHECK_THAT(
      unused.status().message(),
      Catch::Contains("text_model.encoder.layers.9.extra.weight") && Catch::Contains("unused"));
  write_variant(false, false, true);
  auto bad = ClipTextModel::load(dir.path);
  REQUIRE_FALSE(bad.is_ok());
  std::printf("mis-shaped: %s\n", bad.status().message().c_str());
  CHECK_THAT(bad.status().message(), Catch::Contains(reshaped) && Catch::Contains("mis-shaped"));
  // No weights file at all names what was looked for.
  fs::remove(dir.file("model.safetensors"));
  auto none = ClipTextModel::load(dir.path);
  REQUIRE_FALSE(none.is_ok());
  CHECK_THAT(none.status().message(), Catch::Contains("model.safetensors"));
}

TEST_CASE("prompt cache: computed once beside the weights, then read back", "[nets][clip]") {
  auto g = SafeTensors::open(case_path());
  REQUIRE(g.is_ok());
  const std::vector<float> want = read_f32(*g, "output.hidden0");
  test::TempDir dir("clip-cache");
  const std::string root = make_text_folder(dir, /*copy_weights=*/true);
  REQUIRE(has_text_encoder(root));
  PromptCacheInfo info;
  auto first = prompt_embedding(root, kDifixPrompt, nullptr, {}, &info);
  INFO((first.is_ok() ? "" : first.status().message()));
  REQUIRE(first.is_ok());
  CHECK_FALSE(info.hit);
  CHECK(info.note.empty());
  REQUIRE(fs::path(info.path).parent_path() == fs::path(prompt_cache_folder(root)));
  REQUIRE(file_exists(info.path));
  check_golden("computed", first->f32(), want);
  auto second = prompt_embedding(root, kDifixPrompt, nullptr, {}, &info);
  REQUIRE(second.is_ok());
  CHECK(info.hit);
  check_golden("from the cache", second->f32(), want);

  // Another prompt gets another key; the first file stays valid.
  auto key0 = prompt_cache_key(root, kDifixPrompt);
  auto key1 = prompt_cache_key(root, "a different prompt");
  REQUIRE(key0.is_ok());
  REQUIRE(key1.is_ok());
  CHECK(*key0 != *key1);

  // A corrupted cache file is ignored and rewritten.
  REQUIRE(write_file_atomic(info.path, std::string("not a safetensors file")).is_ok());
  auto third = prompt_embedding(root, kDifixPrompt, nullptr, {}, &info);
  REQUIRE(third.is_ok());
  CHECK_FALSE(info.hit);
  check_golden("after corruption", third->f32(), want);
  CHECK(SafeTensors::open(info.path).is_ok());

  // Touching the weights (new mtime) changes the key.
  const auto t = fs::last_write_time(root + "/text_encoder/model.safetensors");
  fs::last_write_time(root + "/text_encoder/model.safetensors", t + std::chrono::seconds(5));
  auto key2 = prompt_cache_key(root, kDifixPrompt);
  REQUIRE(key2.is_ok());
  CHECK(*key2 != *key0);
}

TEST_CASE("prompt cache: an unwritable pipeline folder falls back to the user cache folder",
          "[nets][clip]") {
  test::TempDir dir("clip-cache-ro");
  const std::string root = make_text_folder(dir, /*copy_weights=*/true);
  // A plain file where the cache folder should be: cannot be created, even by root.
  REQUIRE(write_file_atomic(prompt_cache_folder(root), std::string("x")).is_ok());
  const std::string xdg = dir.path + "/xdg";
  const char* old = std::getenv("XDG_CACHE_HOME");
  const std::string saved = old ? old : "";
  ::setenv("XDG_CACHE_HOME", xdg.c_str(), 1);
  PromptCacheInfo info;
  auto e = prompt_embedding(root, kDifixPrompt, nullptr, {}, &info);
  auto again = prompt_embedding(root, kDifixPrompt, nullptr, {}, &info);
  if (old)
    ::setenv("XDG_CACHE_HOME", saved.c_str(), 1);
  else
    ::unsetenv("XDG_CACHE_HOME");
  REQUIRE(e.is_ok());
  REQUIRE(again.is_ok());
  CHECK(info.hit);
  CHECK(fs::path(info.path).parent_path() == fs::path(xdg + "/macro/prompt_cache"));
  auto g = SafeTensors::open(case_path());
  REQUIRE(g.is_ok());
  check_golden("user cache", again->f32(), read_f32(*g, "output.hidden0"));

  // Nowhere writable: still returns the embedding and says why nothing was stored.
  PromptCacheOptions o;
  o.cache_dir = prompt_cache_folder(root) + "/sub";  // under the plain file
  auto none = prompt_embedding(root, kDifixPrompt, nullptr, o, &info);
  REQUIRE(none.is_ok());
  CHECK(info.path.empty());
  CHECK_THAT(info.note, Catch::Contains("cannot create the cache folder"));
}

TEST_CASE("difix pipeline: the text encoder's width must match the unet", "[nets][clip]") {
  // Tiny U-Net (cross dim 48) + tiny VAE + tiny text encoder (64 wide): refused by name.
  test::TempDir dir("clip-pipe");
  const std::string root = make_text_folder(dir);
  test::write_tiny_pipeline(root);
  auto pipe = DifixPipeline::load(root, Precision::kF32);
  REQUIRE(pipe.is_ok());
  PromptCacheInfo info;
  auto ctx = (*pipe)->prompt_context(kDifixPrompt, nullptr, &info);
  REQUIRE_FALSE(ctx.is_ok());
  CHECK_THAT(ctx.status().message(),
             Catch::Contains("hidden_size") && Catch::Contains("48") && Catch::Contains("64"));
}

TEST_CASE("nn-run on a CLIPTextModel folder reproduces the golden (I64 and I32 ids)",
          "[nets][clip][nn-run]") {
  auto g = SafeTensors::open(case_path());
  REQUIRE(g.is_ok());
  test::TempDir dir("clip-nn-run");
  const TensorEntry* e = g->find("input.ids1");
  REQUIRE(e != nullptr);
  const std::vector<int32_t> ids32 = read_ids(*g, "input.ids1");
  const std::string out = dir.file("out.safetensors");
  for (DType dt : {DType::kI64, DType::kI32}) {
    const std::string in = dir.file("in.safetensors");
    TensorToWrite t{"input.ids", dt, e->shape,
                    dt == DType::kI64 ? static_cast<const void*>(e->data) : ids32.data()};
    REQUIRE(write_safetensors(in, {t}).is_ok());
    const std::string cmd = test::nn_run_command(te_dir(), in, out, dir.file("log.txt"));
    auto o = test::run_nn_run(cmd, dir.file("log.txt"), out);
    REQUIRE(o.is_ok());
    CHECK(o->metadata().at("model") == "clip_text");
    check_golden(std::string("nn-run ") + dtype_name(dt), read_f32(*o, "output.hidden").data(),
                 read_f32(*g, "output.hidden1"));
  }
  // Float ids are refused naming the tensor and the dtype.
  const std::vector<float> f(77, 0.0f);
  REQUIRE(write_safetensors(dir.file("bad.safetensors"),
                            {{"input.ids", DType::kF32, {1, 77}, f.data()}})
              .is_ok());
  const std::string cmd = test::macro_exe() + " nn-run --model " + te_dir() + " --inputs " +
                          dir.file("bad.safetensors") + " --out " + out + " > " +
                          dir.file("log.txt") + " 2>&1";
  CHECK(test::run_command(cmd) == 1);
  auto log = read_text_file(dir.file("log.txt"));
  REQUIRE(log.is_ok());
  CHECK_THAT(*log, Catch::Contains("input.ids") && Catch::Contains("F32"));
}

namespace {

// Lists the (name, shape) pairs of a module walk.
struct ShapeLister : ParamVisitor {
  std::vector<std::pair<std::string, std::vector<int64_t>>> items;
  void param(const std::string& name, Param&, const std::vector<int64_t>& shape) override {
    items.emplace_back(name, shape);
  }
};

// A random CLIP text encoder of the given width in <dir>/text_encoder (config.json +
// model.safetensors), small values so that activations stay bounded.
void write_random_text_encoder(const std::string& dir, int width) {
  ClipTextConfig cfg;
  cfg.hidden_size = width;
  cfg.intermediate_size = 4 * width;
  cfg.num_attention_heads = 3;
  cfg.num_hidden_layers = 2;
  auto m = ClipTextModel::build(cfg);
  REQUIRE(m.is_ok());
  ShapeLister lister;
  (*m)->visit(lister);
  std::vector<std::vector<float>> data;
  std::vector<TensorToWrite> ts;
  uint32_t state = 12345;
  auto rnd = [&] {
    state = state * 1664525u + 1013904223u;
    return float(state >> 8) / float(1 << 24) * 2.0f - 1.0f;
  };
  data.reserve(lister.items.size());
  for (const auto& [name, shape] : lister.items) {
    int64_t n = 1;
    for (int64_t d : shape) n *= d;
    const bool norm_w =
        name.find("layer_norm") != std::string::npos && name.find(".weight") != std::string::npos;
    const float s = norm_w ? 0.05f : 0.1f;
    std::vector<float> v(static_cast<size_t>(n));
    for (float& x : v) x = (norm_w ? 1.0f : 0.0f) + s * rnd();
    data.push_back(std::move(v));
    ts.push_back({name, DType::kF32, shape, data.back().data()});
  }
  fs::create_directories(dir + "/text_encoder");
  REQUIRE(write_safetensors(dir + "/text_encoder/model.safetensors", ts).is_ok());
  const std::string config =
      R"({"architectures": ["CLIPTextModel"], "hidden_size": )" + std::to_string(width) +
      R"(, "intermediate_size": )" + std::to_string(4 * width) +
      R"(, "num_attention_heads": 3, "num_hidden_layers": 2, "max_position_embeddings": 77,
          "vocab_size": 49408, "hidden_act": "quick_gelu", "layer_norm_eps": 1e-05})";
  REQUIRE(write_file_atomic(dir + "/text_encoder/config.json", config).is_ok());
}

}  // namespace

TEST_CASE("difix pipeline without input.ctx uses the folder's cached prompt embedding",
          "[nets][clip][nn-run]") {
  // Tiny U-Net (cross dim 48) + tiny VAE + a random 48-wide text encoder + the real tokenizer.
  test::TempDir dir("clip-pipe-ctx");
  const std::string root = dir.path + "/pipe";
  fs::create_directories(root);
  fs::create_directory_symlink(test::golden_dir() + "/clip/tokenizer", root + "/tokenizer");
  test::write_tiny_pipeline(root);
  write_random_text_encoder(root, 48);
  auto pipe = DifixPipeline::load(root, Precision::kF32);
  REQUIRE(pipe.is_ok());
  PromptCacheInfo info;
  auto ctx = (*pipe)->prompt_context(kDifixPrompt, nullptr, &info);
  INFO((ctx.is_ok() ? "" : ctx.status().message()));
  REQUIRE(ctx.is_ok());
  REQUIRE(ctx->shape() == Shape{1, 77, 48});
  CHECK_FALSE(info.hit);
  // The pad rows attend causally to the prompt: they differ from each other and are not zero.
  double row76 = 0, diff = 0;
  for (int c = 0; c < 48; ++c) {
    row76 += std::abs(ctx->f32()[76 * 48 + c]);
    diff += std::abs(ctx->f32()[76 * 48 + c] - ctx->f32()[2 * 48 + c]);
  }
  CHECK(row76 > 0);
  CHECK(diff > 0);

  auto g = SafeTensors::open(test::golden_dir() + "/difix-tiny/case-ref2.safetensors");
  REQUIRE(g.is_ok());
  const TensorEntry* ie = g->find("input.images");
  REQUIRE(ie != nullptr);
  auto iv = g->read_f32("input.images");
  REQUIRE(iv.is_ok());
  Tensor images = Tensor::from_f32(ie->shape, *iv);
  auto want = (*pipe)->step(images, *ctx, UNetMasks{}, nullptr);
  REQUIRE(want.is_ok());
  auto got = (*pipe)->step_with_prompt(images, UNetMasks{}, nullptr);
  REQUIRE(got.is_ok());
  const test::Diff d0 =
      test::compare(got->image.f32(), want->image.f32(), size_t(want->image.numel()));
  CHECK(d0.max_abs == 0.0);

  // nn-run on the folder without input.ctx: same image as the explicit context.
  const std::string in = dir.file("in.safetensors"), out = dir.file("out.safetensors");
  REQUIRE(write_safetensors(in, {{"input.images", ie->dtype, ie->shape, ie->data}}).is_ok());
  const std::string cmd = test::nn_run_command(root, in, out, dir.file("log.txt"));
  auto o = test::run_nn_run(cmd, dir.file("log.txt"), out);
  REQUIRE(o.is_ok());
  const std::vector<float> img = read_f32(*o, "output.image");
  const test::Diff d = test::compare(img.data(), want->image.f32(), img.size());
  std::printf("  nn-run without input.ctx vs explicit ctx: rel L2 %.3e max abs %.3e\n", d.rel_l2,
              d.max_abs);
  CHECK(d.rel_l2 <= 1e-6);
  // A different prompt changes the result (the context is really used).
  auto other = (*pipe)->step_with_prompt(images, UNetMasks{}, nullptr, 199, "a cat");
  REQUIRE(other.is_ok());
  const test::Diff d2 =
      test::compare(other->image.f32(), want->image.f32(), size_t(want->image.numel()));
  CHECK(d2.rel_l2 > 1e-6);
}
