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

TEST_CASE("upsample x2 + 3x3 conv by 2x2 phases equals the conv of the resized image",
          "[vae][mem][conv]") {
  // Upsample2D (layers.h): exact 2x outputs take the four phase convs; every entry point gives
  // the same bits, and they match the conv of the nearest-resized image in double (fp32 to
  // summation order, bf16 within the bf16 conv's rounding). A non-2x size takes the plain conv.
  const int64_t c = 6, n = 2;
  const std::vector<float> w = test::random_vec(size_t(c * c * 9), 41);
  const std::vector<float> b = test::random_vec(size_t(c), 42);
  for (Precision p : {Precision::kF32, Precision::kBf16}) {
    Upsample2D up;
    up.init(c);
    up.conv.weight.data = w.data();
    up.conv.weight.shape = {c, c, 3, 3};
    up.conv.bias.data = b.data();
    up.conv.bias.shape = {c};
    up.pack(p);
    for (auto [h, wd, oh, ow] : {std::array<int64_t, 4>{5, 7, 10, 14}, {4, 3, 8, 6},
                                 {5, 7, 9, 13}}) {  // the last: nearest to 2h - 1 x 2w - 1
      INFO(precision_name(p) << " " << h << "x" << wd << " -> " << oh << "x" << ow);
      std::vector<float> x = test::random_vec(size_t(n * c * h * wd), 43);
      // The reference: nearest source floor(y h / oh), then the conv, in double.
      std::vector<double> ref(size_t(n * c * oh * ow));
      for (int64_t i = 0; i < n; ++i)
        for (int64_t co = 0; co < c; ++co)
          for (int64_t y = 0; y < oh; ++y)
            for (int64_t xx = 0; xx < ow; ++xx) {
              double s = b[size_t(co)];
              for (int64_t ci = 0; ci < c; ++ci)
                for (int dy = 0; dy < 3; ++dy)
                  for (int dx = 0; dx < 3; ++dx) {
                    const int64_t uy = y + dy - 1, ux = xx + dx - 1;
                    if (uy < 0 || uy >= oh || ux < 0 || ux >= ow) continue;
                    s += double(w[size_t((co * c + ci) * 9 + dy * 3 + dx)]) *
                         double(x[size_t(((i * c + ci) * h + uy * h / oh) * wd + ux * wd / ow)]);
                  }
              ref[size_t(((i * c + co) * oh + y) * ow + xx)] = s;
            }
      Arena arena(size_t(64) << 20);
      Workspace ws(&arena);
      const Run r{&ws, &ThreadPool::global(), p};
      std::vector<float> y0(ref.size()), y1(ref.size()), tmp(ref.size());
      up.forward(r, x.data(), n, c, h, wd, oh, ow, y0.data());
      std::copy(x.begin(), x.end(), y1.begin());  // in place: x in a buffer the output's size
      up.forward_in_place(r, y1.data(), n, c, h, wd, oh, ow, tmp.data());
      CHECK(std::memcmp(y0.data(), y1.data(), y0.size() * sizeof(float)) == 0);
      for (int64_t rows : {1, 2, 5, 64}) {  // one image by output bands
        std::vector<float> y2(size_t(c * oh * ow));
        up.forward_lean(r, x.data(), c, h, wd, oh, ow, y2.data(), rows);
        INFO("band rows " << rows);
        CHECK(std::memcmp(y0.data(), y2.data(), y2.size() * sizeof(float)) == 0);
      }
      double err = 0.0, mag = 0.0;
      for (size_t k = 0; k < ref.size(); ++k) {
        err = std::max(err, std::abs(double(y0[k]) - ref[k]));
        mag = std::max(mag, std::abs(ref[k]));
      }
      CHECK(err <= (p == Precision::kF32 ? 1e-6 : 2e-2) * mag);
    }
  }
}
