// Memory-lean VAE paths (attention/nets/vae.h, layers.h, runtime/conv.h): the full-resolution
// level by row bands, bf16 convs by bands of pair planes, and bf16 skips must give exactly the
// bits of the whole-image path, in fp32 and bf16, on the vae-tiny golden model and image.
#include <catch2/catch.hpp>
#include <cstring>

#include "attention/nets/vae.h"
#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/io/safetensors.h"
#include "golden_tensors.h"
#include "test_support.h"

using namespace macro;
using namespace macro::nets;

namespace {

struct Outputs {
  Tensor moments, image;
  std::vector<Tensor> skips;
};

Outputs run(const DifixVae& vae, const Tensor& images, bool bf16_skips = false) {
  auto enc = vae.encode(images, 1, &ThreadPool::global(), nullptr, bf16_skips);
  INFO((enc.is_ok() ? "" : enc.status().message()));
  REQUIRE(enc.is_ok());
  std::vector<TensorView> skips;
  for (const Tensor& s : enc->skips) skips.push_back(s.view());
  auto dec = vae.decode(enc->z.view().slice(0, 0, 1), skips, &ThreadPool::global());
  INFO((dec.is_ok() ? "" : dec.status().message()));
  REQUIRE(dec.is_ok());
  Outputs o;
  o.moments = std::move(enc->moments);
  o.image = std::move(*dec);
  o.skips = std::move(enc->skips);
  return o;
}

bool same_bits(const Tensor& a, const Tensor& b) {
  return a.shape() == b.shape() && a.dtype() == b.dtype() &&
         std::memcmp(a.view().data, b.view().data, size_t(a.numel()) * dtype_size(a.dtype())) == 0;
}

}  // namespace

TEST_CASE("vae: banded full-resolution level is bit-identical to whole images", "[vae][mem]") {
  const std::string dir = test::golden_dir() + "/vae-tiny";
  auto g = SafeTensors::open(dir + "/case-roundtrip.safetensors");
  REQUIRE(g.is_ok());
  const Tensor images = test::read_tensor(*g, "input.image");  // [2, 3, 40, 56]
  const Isa saved = active_isa();
  for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16}) {
    if (!isa_supported(isa)) continue;
    REQUIRE(set_isa(isa).is_ok());
    for (Precision p : {Precision::kF32, Precision::kBf16}) {
      INFO(isa_name(isa));
      auto vae = DifixVae::load(dir, p);
      REQUIRE(vae.is_ok());
      (*vae)->set_band_rows(0);
      const Outputs whole = run(**vae, images);
      // Bands of 1, 3 (uneven last band) and 7 rows; 64 pair words per bf16 conv band.
      for (int64_t rows : {1, 3, 7}) {
        INFO(precision_name(p) << ", band rows " << rows);
        (*vae)->set_band_rows(rows);
        const size_t old = conv2d_set_pair_band(rows == 3 ? 64 : size_t(4) << 20);
        const Outputs banded = run(**vae, images);
        conv2d_set_pair_band(old);
        CHECK(same_bits(banded.moments, whole.moments));
        for (size_t i = 0; i < whole.skips.size(); ++i)
          CHECK(same_bits(banded.skips[i], whole.skips[i]));
        CHECK(same_bits(banded.image, whole.image));
      }
      // The planned scratch shrinks with bands (40 x 56 is one auto band; 4 rows is several).
      (*vae)->set_band_rows(4);
      const size_t lean_dec = (*vae)->decode_workspace_bytes(40, 56);
      const size_t lean_enc = (*vae)->encode_workspace_bytes(40, 56);
      (*vae)->set_band_rows(0);
      CHECK(lean_dec < (*vae)->decode_workspace_bytes(40, 56));
      CHECK(lean_enc < (*vae)->encode_workspace_bytes(40, 56));
      (*vae)->set_band_rows(DifixVae::kAutoBands);
    }
  }
  REQUIRE(set_isa(saved).is_ok());
}

TEST_CASE("vae: bf16 skips decode to the same bits, fp32 models refuse them", "[vae][mem]") {
  const std::string dir = test::golden_dir() + "/vae-tiny";
  auto g = SafeTensors::open(dir + "/case-roundtrip.safetensors");
  REQUIRE(g.is_ok());
  const Tensor images = test::read_tensor(*g, "input.image");
  auto vae = DifixVae::load(dir, Precision::kBf16);
  REQUIRE(vae.is_ok());
  (*vae)->set_band_rows(3);
  const Outputs f32_skips = run(**vae, images);
  const Outputs bf16_skips = run(**vae, images, /*bf16_skips=*/true);
  REQUIRE(bf16_skips.skips[0].dtype() == DType::kBF16);
  CHECK(bf16_skips.skips[0].numel() == f32_skips.skips[0].numel());
  CHECK(same_bits(bf16_skips.image, f32_skips.image));
  CHECK(same_bits(bf16_skips.moments, f32_skips.moments));

  auto vae32 = DifixVae::load(dir, Precision::kF32);
  REQUIRE(vae32.is_ok());
  auto enc = (*vae32)->encode(images, 1, nullptr, nullptr, /*bf16_skips=*/true);
  REQUIRE_FALSE(enc.is_ok());
  CHECK(enc.status().message().find("bf16 skips need a bf16 model") != std::string::npos);
  // ... and its decode refuses BF16 skip tensors by name.
  std::vector<TensorView> skips;
  for (const Tensor& s : bf16_skips.skips) skips.push_back(s.view());
  Tensor z = Tensor::f32({1, 4, 5, 7});
  auto dec = (*vae32)->decode(z, skips, nullptr);
  REQUIRE_FALSE(dec.is_ok());
  CHECK(dec.status().message().find("skip0: expected contiguous F32 [") != std::string::npos);
}
