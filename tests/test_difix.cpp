// The single-step Difix pipeline (attention/nets/difix.h) against shared/golden/difix-tiny (tiny
// U-Net + tiny Difix VAE; two views, and three views with the MACRO mask), in fp32 and bf16, and
// `macro nn-run` on a pipeline folder through the binary.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "attention/nets/difix.h"
#include "attention/runtime/attention_mask.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "golden_tensors.h"
#include "test_support.h"
#include "tiny_checkpoint_fixture.h"

using namespace macro;
using namespace macro::nets;

namespace {

using test::Bound;
using test::check_close;
using test::kFp32;
using test::read_tensor;
// bf16 through encoder, U-Net and decoder of random-weight tiny nets; measured values printed.
constexpr Bound kBf16{5e-2, 2e-1};

// A pipeline folder over the tiny goldens: model_index.json, unet/ and vae/ (symlinks),
// scheduler/scheduler_config.json.
std::string make_pipeline(const test::TempDir& dir) {
  const std::string root = dir.path + "/difix-tiny";
  test::write_tiny_pipeline(
      root,
      R"({"_class_name": "DifixPipeline", "unet": ["diffusers", "UNet2DConditionModel"], "vae": ["diffusers", "AutoencoderKL"]})");
  std::filesystem::create_directories(root + "/scheduler");
  REQUIRE(
      write_file_atomic(
          root + "/scheduler/scheduler_config.json",
          std::string(
              R"({"_class_name": "DDPMScheduler", "num_train_timesteps": 1000, "beta_schedule": "scaled_linear", "beta_start": 0.00085, "beta_end": 0.012, "prediction_type": "epsilon", "clip_sample": false})"))
          .is_ok());
  return root;
}

// The golden's dense mask.levelL tensors as block-sparse masks (kept alive in *store).
UNetMasks golden_masks(const SafeTensors& g, std::vector<BlockSparseMask>* store) {
  store->clear();
  store->reserve(8);
  UNetMasks masks;
  for (int l = 0; l < 8; ++l) {
    const TensorEntry* e = g.find("mask.level" + std::to_string(l));
    if (!e) break;
    auto m = mask_from_dense(e->data, int(e->shape[0]), int(e->shape[1]), 0, true);
    REQUIRE(m.is_ok());
    store->push_back(std::move(*m));
    masks.level.push_back(&store->back());
  }
  return masks;
}

void run_case(const DifixPipeline& pipe, const std::string& name, Precision p, Bound b) {
  auto g = SafeTensors::open(test::golden_dir() + "/difix-tiny/" + name + ".safetensors");
  REQUIRE(g.is_ok());
  Tensor images = read_tensor(*g, "input.images"), ctx = read_tensor(*g, "input.ctx");
  std::vector<BlockSparseMask> store;
  const UNetMasks masks = golden_masks(*g, &store);
  std::printf("difix-tiny %s (%s, %zu masked levels)\n", name.c_str(), precision_name(p),
              masks.level.size());
  auto o = pipe.step(images, ctx, masks, &ThreadPool::global());
  INFO((o.is_ok() ? "" : o.status().message()));
  REQUIRE(o.is_ok());
  check_close("output.z", o->z, read_tensor(*g, "output.z"), b);
  check_close("output.eps", o->eps, read_tensor(*g, "output.eps"), b);
  check_close("output.z0", o->z0, read_tensor(*g, "output.z0"), b);
  check_close("output.image", o->image, read_tensor(*g, "output.image"), b);
}

}  // namespace

TEST_CASE("difix-tiny fp32 matches the golden pipeline", "[nets][difix]") {
  test::TempDir dir("difix");
  auto pipe = DifixPipeline::load(make_pipeline(dir), Precision::kF32);
  INFO((pipe.is_ok() ? "" : pipe.status().message()));
  REQUIRE(pipe.is_ok());
  // The scheduler's abar_199 against the golden constant.
  auto g = SafeTensors::open(test::golden_dir() + "/difix-tiny/case-ref2.safetensors");
  REQUIRE(g.is_ok());
  const double abar_golden = read_tensor(*g, "const.alpha_bar_199").f32()[0];
  auto abar = alpha_bar((*pipe)->schedule(), 199);
  REQUIRE(abar.is_ok());
  std::printf("abar_199 %.9f (golden %.9f)\n", *abar, abar_golden);
  CHECK(std::abs(*abar - abar_golden) < 1e-6);
  run_case(**pipe, "case-ref2", Precision::kF32, kFp32);
  run_case(**pipe, "case-macro", Precision::kF32, kFp32);
}

TEST_CASE("difix-tiny bf16 stays within its stated bound", "[nets][difix][bf16]") {
  test::TempDir dir("difix-bf16");
  auto pipe = DifixPipeline::load(make_pipeline(dir), Precision::kBf16);
  REQUIRE(pipe.is_ok());
  run_case(**pipe, "case-ref2", Precision::kBf16, kBf16);
  run_case(**pipe, "case-macro", Precision::kBf16, kBf16);
}

TEST_CASE("difix-tiny matches on every instruction-set path the machine supports",
          "[nets][difix][isa]") {
  const Isa saved = active_isa();
  test::TempDir dir("difix-isa");
  const std::string root = make_pipeline(dir);
  for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
    if (!isa_supported(isa)) {
      std::printf("difix-tiny: %s not supported here, skipped\n", isa_name(isa));
      continue;
    }
    REQUIRE(set_isa(isa).is_ok());
    for (Precision p : {Precision::kF32, Precision::kBf16}) {
      auto pipe = DifixPipeline::load(root, p);  // weights are packed for the path active now
      REQUIRE(pipe.is_ok());
      std::printf("[%s] ", isa_name(isa));
      run_case(**pipe, "case-macro", p, p == Precision::kF32 ? kFp32 : kBf16);
    }
  }
  REQUIRE(set_isa(saved).is_ok());
}

TEST_CASE("difix: consecutive steps on the reused arena are bit-identical",
          "[nets][difix][arena]") {
  test::TempDir dir("difix-arena");
  const std::string root = make_pipeline(dir);
  auto g = SafeTensors::open(test::golden_dir() + "/difix-tiny/case-ref2.safetensors");
  REQUIRE(g.is_ok());
  const Tensor images = read_tensor(*g, "input.images"), ctx = read_tensor(*g, "input.ctx");
  auto same = [](const Tensor& a, const Tensor& b) {
    return a.shape() == b.shape() &&
           std::memcmp(a.f32(), b.f32(), size_t(a.numel()) * sizeof(float)) == 0;
  };
  for (Precision p : {Precision::kF32, Precision::kBf16}) {
    auto pipe = DifixPipeline::load(root, p);
    REQUIRE(pipe.is_ok());
    const size_t ws =
        (*pipe)->step_workspace_bytes(images.dim(0), images.dim(2), images.dim(3), ctx.dim(1));
    auto first = (*pipe)->step(images, ctx, {}, &ThreadPool::global());
    REQUIRE(first.is_ok());
    const size_t capacity = (*pipe)->arena_capacity();
    // Reserved once, to the largest stage: the arena is as big as that stage and no bigger.
    CHECK(capacity >= ws);
    CHECK(capacity < ws + 4096);
    // Poison the arena's stale contents through a step of another shape (one view), then repeat.
    auto other = (*pipe)->step(images.view().slice(0, 0, 1), ctx.view().slice(0, 0, 1), {},
                               &ThreadPool::global());
    REQUIRE(other.is_ok());
    auto second = (*pipe)->step(images, ctx, {}, &ThreadPool::global());
    REQUIRE(second.is_ok());
    CHECK((*pipe)->arena_capacity() == capacity);  // no re-allocation for a shape seen before
    INFO(precision_name(p));
    CHECK(same(first->z, second->z));
    CHECK(same(first->eps, second->eps));
    CHECK(same(first->z0, second->z0));
    CHECK(same(first->image, second->image));
    // And the reused arena changes nothing against a fresh pipeline's first step.
    auto fresh = DifixPipeline::load(root, p);
    REQUIRE(fresh.is_ok());
    auto third = (*fresh)->step(images, ctx, {}, &ThreadPool::global());
    REQUIRE(third.is_ok());
    CHECK(same(first->image, third->image));
  }
}

TEST_CASE("difix: the close-up-only step gives the same image bit for bit", "[nets][difix]") {
  // step(all_views = false) computes eps and z0 of view 0 only (what the decode needs) and skips
  // the other views' dead work in the U-Net: the decoded image must not change by one bit.
  test::TempDir dir("difix-live");
  const std::string root = make_pipeline(dir);
  for (Precision p : {Precision::kF32, Precision::kBf16}) {
    auto pipe = DifixPipeline::load(root, p);
    REQUIRE(pipe.is_ok());
    for (const char* name : {"case-ref2", "case-macro"}) {
      INFO(name << " " << precision_name(p));
      auto g = SafeTensors::open(test::golden_dir() + "/difix-tiny/" + name + ".safetensors");
      REQUIRE(g.is_ok());
      Tensor images = read_tensor(*g, "input.images"), ctx = read_tensor(*g, "input.ctx");
      std::vector<BlockSparseMask> store;
      const UNetMasks masks = golden_masks(*g, &store);
      auto all = (*pipe)->step(images, ctx, masks, &ThreadPool::global());
      REQUIRE(all.is_ok());
      auto one = (*pipe)->step(images, ctx, masks, &ThreadPool::global(),
                               DifixPipeline::kDefaultTimestep, {},
                               /*all_views=*/false);
      REQUIRE(one.is_ok());
      CHECK(one->eps.dim(0) == 1);
      CHECK(one->z0.dim(0) == 1);
      const size_t per_view = size_t(all->eps.numel() / all->eps.dim(0));
      CHECK(std::memcmp(one->eps.f32(), all->eps.f32(), per_view * sizeof(float)) == 0);
      CHECK(std::memcmp(one->z0.f32(), all->z0.f32(), per_view * sizeof(float)) == 0);
      REQUIRE(one->image.numel() == all->image.numel());
      CHECK(std::memcmp(one->image.f32(), all->image.f32(),
                        size_t(all->image.numel()) * sizeof(float)) == 0);
    }
  }
}

TEST_CASE("difix: bad scheduler configs and inputs are refused by name", "[nets][difix]") {
  test::TempDir dir("difix-bad");
  const std::string root = make_pipeline(dir);
  REQUIRE(write_file_atomic(root + "/scheduler/scheduler_config.json",
                            std::string(R"({"beta_schedule": "linear"})"))
              .is_ok());
  auto p = DifixPipeline::load(root, Precision::kF32);
  REQUIRE_FALSE(p.is_ok());
  CHECK_THAT(p.status().message(), Catch::Contains("beta_schedule"));
  REQUIRE(write_file_atomic(root + "/scheduler/scheduler_config.json", std::string("{}")).is_ok());
  auto pipe = DifixPipeline::load(root, Precision::kF32);
  REQUIRE(pipe.is_ok());
  auto r = (*pipe)->step(Tensor::f32({2, 3, 60, 88}), Tensor::f32({2, 77, 48}), {}, nullptr);
  REQUIRE_FALSE(r.is_ok());
  CHECK_THAT(r.status().message(), Catch::Contains("images"));
  auto r2 = (*pipe)->step(Tensor::f32({2, 3, 64, 88}), Tensor::f32({3, 77, 48}), {}, nullptr);
  REQUIRE_FALSE(r2.is_ok());
  CHECK_THAT(r2.status().message(), Catch::Contains("ctx"));
}

TEST_CASE("nn-run difix pipeline folder: the binary reproduces the golden",
          "[nets][difix][nn-run]") {
  test::TempDir dir("nn-run-difix");
  const std::string model = make_pipeline(dir);
  auto g = SafeTensors::open(test::golden_dir() + "/difix-tiny/case-macro.safetensors");
  REQUIRE(g.is_ok());
  // Pass only the pipeline's inputs (the golden also holds outputs and the maps masks came from).
  std::vector<TensorToWrite> ins;
  for (const std::string& n : g->names()) {
    if (n != "input.images" && n != "input.ctx" && n.rfind("mask.level", 0) != 0) continue;
    const TensorEntry* e = g->find(n);
    ins.push_back({n, e->dtype, e->shape, e->data});
  }
  REQUIRE(ins.size() == 6);
  const std::string in = dir.file("in.safetensors"), out = dir.file("out.safetensors");
  REQUIRE(write_safetensors(in, ins).is_ok());
  const std::string cmd = test::nn_run_command(model, in, out, dir.file("log.txt"));
  auto o = test::run_nn_run(cmd, dir.file("log.txt"), out);
  REQUIRE(o.is_ok());
  CHECK(o->metadata().at("model") == "difix");
  for (const char* n : {"output.z", "output.eps", "output.z0", "output.image"})
    check_close(std::string("nn-run ") + n, read_tensor(*o, n), read_tensor(*g, n), kFp32);
  // An unexpected tensor is refused naming it.
  ins.push_back({"input.plane_level0", g->find("input.plane_level0")->dtype,
                 g->find("input.plane_level0")->shape, g->find("input.plane_level0")->data});
  REQUIRE(write_safetensors(in, ins).is_ok());
  CHECK(test::run_command(cmd) == 1);
  auto log2 = read_text_file(dir.file("log.txt"));
  REQUIRE(log2.is_ok());
  CHECK_THAT(*log2, Catch::Contains("input.plane_level0"));
}
