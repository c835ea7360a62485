// Difix VAE (attention/nets/vae.h) against shared/golden/vae-tiny (released layout: unmerged
// PEFT LoRA, skip convs): moments, z, encoder skips, view-0 decode; bf16 deviation; checkpoint
// mismatches by name; the full-size layout from the manifest loads and runs.
#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>

#include "attention/nets/nn_run.h"
#include "attention/nets/synthetic_checkpoint.h"
#include "attention/nets/vae.h"
#include "attention/runtime/io/safetensors.h"
#include "golden_tensors.h"
#include "test_support.h"

using namespace macro;
using namespace macro::nets;

namespace {

std::string vae_dir() {
  return test::golden_dir() + "/vae-tiny";
}

using test::Bound;
using test::check_close;
using test::kFp32;
using test::read_tensor;
// bf16 weights and conv/matmul inputs; measured values are printed by the test.
constexpr Bound kBf16{3e-2, 1e-1};

void run_roundtrip(Precision p, Bound b) {
  auto vae = DifixVae::load(vae_dir(), p);
  INFO((vae.is_ok() ? "" : vae.status().message()));
  REQUIRE(vae.is_ok());
  auto g = SafeTensors::open(vae_dir() + "/case-roundtrip.safetensors");
  REQUIRE(g.is_ok());
  Tensor image = read_tensor(*g, "input.image");
  std::printf("vae-tiny case-roundtrip (%s)\n", precision_name(p));
  auto enc = (*vae)->encode(image, image.dim(0), &ThreadPool::global());
  REQUIRE(enc.is_ok());
  check_close("output.moments", enc->moments, read_tensor(*g, "output.moments"), b);
  check_close("output.z", enc->z, read_tensor(*g, "output.z"), b);
  REQUIRE(enc->skips.size() == 4);
  std::vector<TensorView> skips0;
  for (int i = 0; i < 4; ++i) {
    check_close("output.skip" + std::to_string(i), enc->skips[size_t(i)],
                read_tensor(*g, "output.skip" + std::to_string(i)), b);
    skips0.push_back(enc->skips[size_t(i)].view().slice(0, 0, 1));
  }
  auto dec = (*vae)->decode(enc->z.view().slice(0, 0, 1), skips0, &ThreadPool::global());
  REQUIRE(dec.is_ok());
  check_close("output.decoded_view0", *dec, read_tensor(*g, "output.decoded_view0"), b);
}

}  // namespace

TEST_CASE("vae-tiny fp32 matches the diffusers golden round trip", "[nets][vae]") {
  run_roundtrip(Precision::kF32, kFp32);
}

TEST_CASE("vae-tiny bf16 stays within its stated bound", "[nets][vae][bf16]") {
  run_roundtrip(Precision::kBf16, kBf16);
}

TEST_CASE("vae: bad image sizes and skips are refused", "[nets][vae]") {
  auto vae = DifixVae::load(vae_dir(), Precision::kF32);
  REQUIRE(vae.is_ok());
  auto r = (*vae)->encode(Tensor::f32({1, 3, 36, 40}), 1, nullptr);  // 36 % 8 != 0
  REQUIRE_FALSE(r.is_ok());
  CHECK_THAT(r.status().message(), Catch::Contains("multiples of 8"));
  auto enc = (*vae)->encode(Tensor::f32({1, 3, 16, 24}), 1, nullptr);
  REQUIRE(enc.is_ok());
  std::vector<TensorView> skips;
  for (const Tensor& s : enc->skips) skips.push_back(s.view());
  Tensor z_wrong = Tensor::f32({1, 4, 3, 3});  // skips are for 2x3
  auto d = (*vae)->decode(z_wrong, skips, nullptr);
  REQUIRE_FALSE(d.is_ok());
  CHECK_THAT(d.status().message(), Catch::Contains("skip0"));
}

TEST_CASE("vae: missing LoRA half, extra and mis-shaped tensors are reported by name",
          "[nets][vae]") {
  auto copy_with = [](const test::TempDir& dir,
                      const std::function<void(std::vector<TensorToWrite>&)>& edit) {
    auto f = SafeTensors::open(vae_dir() + "/diffusion_pytorch_model.safetensors");
    REQUIRE(f.is_ok());
    std::vector<TensorToWrite> ts;
    for (const std::string& n : f->names()) {
      const TensorEntry* e = f->find(n);
      ts.push_back({n, e->dtype, e->shape, e->data});
    }
    edit(ts);
    std::filesystem::copy_file(vae_dir() + "/config.json", dir.file("config.json"));
    REQUIRE(write_safetensors(dir.file("diffusion_pytorch_model.safetensors"), ts).is_ok());
    return DifixVae::load(dir.path, Precision::kF32);
  };
  {
    test::TempDir dir("vae-missing");
    const std::string victim = "encoder.down_blocks.1.resnets.0.conv_shortcut.weight";
    auto m = copy_with(dir, [&](auto& ts) {
      ts.erase(std::remove_if(ts.begin(), ts.end(), [&](auto& t) { return t.name == victim; }),
               ts.end());
    });
    REQUIRE_FALSE(m.is_ok());
    CHECK_THAT(m.status().message(), Catch::Contains("missing") && Catch::Contains(victim));
  }
  {
    test::TempDir dir("vae-lora-half");
    auto m = copy_with(dir, [&](auto& ts) {
      ts.erase(std::remove_if(
                   ts.begin(), ts.end(),
                   [&](auto& t) { return t.name == "decoder.skip_conv_3.lora_B.vae_skip.weight"; }),
               ts.end());
    });
    REQUIRE_FALSE(m.is_ok());
    CHECK_THAT(m.status().message(), Catch::Contains("decoder.skip_conv_3"));
  }
  {
    test::TempDir dir("vae-extra");
    auto m = copy_with(dir, [&](auto& ts) {
      TensorToWrite t = ts[0];
      t.name = "decoder.skip_conv_5.weight";
      ts.push_back(t);
    });
    REQUIRE_FALSE(m.is_ok());
    CHECK_THAT(m.status().message(),
               Catch::Contains("unused") && Catch::Contains("decoder.skip_conv_5.weight"));
  }
  {
    test::TempDir dir("vae-shape");
    const std::string victim = "encoder.conv_out.weight";  // [8,64,3,3]
    auto m = copy_with(dir, [&](auto& ts) {
      for (auto& t : ts)
        if (t.name == victim) t.shape = {8, 64, 9, 1};
    });
    REQUIRE_FALSE(m.is_ok());
    CHECK_THAT(m.status().message(), Catch::Contains("mis-shaped") && Catch::Contains(victim));
  }
}

TEST_CASE("vae: the full-size Difix layout from the manifest loads and runs (bf16 storage)",
          "[nets][vae][full]") {
  test::TempDir dir("vae-full");
  SyntheticCheckpointOptions o;
  o.bf16 = true;
  REQUIRE(write_synthetic_component(test::golden_dir() + "/manifests/vae.json", dir.path,
                                    "AutoencoderKL", o)
              .is_ok());
  auto vae = DifixVae::load(dir.path, Precision::kF32);
  INFO((vae.is_ok() ? "" : vae.status().message()));
  REQUIRE(vae.is_ok());
  CHECK((*vae)->config().lora_rank == 4);
  Tensor image = Tensor::f32({1, 3, 32, 48});
  for (int64_t i = 0; i < image.numel(); ++i) image.f32()[i] = float(std::sin(double(i) * 0.1));
  auto enc = (*vae)->encode(image, 1, &ThreadPool::global());
  REQUIRE(enc.is_ok());
  CHECK(enc->z.shape() == Shape{1, 4, 4, 6});
  std::vector<TensorView> skips;
  for (const Tensor& s : enc->skips) skips.push_back(s.view());
  auto dec = (*vae)->decode(enc->z, skips, &ThreadPool::global());
  REQUIRE(dec.is_ok());
  CHECK(dec->shape() == Shape{1, 3, 32, 48});
  for (int64_t i = 0; i < dec->numel(); ++i) REQUIRE(std::isfinite(dec->f32()[i]));
}

TEST_CASE("nn-run vae folder: golden round trip through the library entry point",
          "[nets][vae][nn-run]") {
  test::TempDir dir("nn-run-vae");
  auto g = SafeTensors::open(vae_dir() + "/case-roundtrip.safetensors");
  REQUIRE(g.is_ok());
  Tensor image = read_tensor(*g, "input.image");
  const std::string in = dir.file("in.safetensors"), out = dir.file("out.safetensors");
  REQUIRE(
      write_safetensors(in, {{"input.image", DType::kF32, image.shape(), image.f32()}}).is_ok());
  NnRunOptions opt;
  opt.model = vae_dir();
  opt.inputs = in;
  opt.out = out;
  opt.pool = &ThreadPool::global();
  Status s = nn_run(opt);
  INFO(s.message());
  REQUIRE(s.is_ok());
  auto o = SafeTensors::open(out);
  REQUIRE(o.is_ok());
  for (const char* n : {"output.moments", "output.z", "output.skip0", "output.skip1",
                        "output.skip2", "output.skip3", "output.decoded_view0"})
    check_close(std::string("nn-run ") + n, read_tensor(*o, n), read_tensor(*g, n), kFp32);
}
