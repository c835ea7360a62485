// TAESD on the real weights against the float32 PyTorch goldens (shared/golden/taesd).
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>

#include "attention/nets/taesd.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "test_support.h"

using namespace macro;
using namespace macro::nets;

namespace {

std::string weights_dir() {
  return test::source_dir() + "/data/weights/taesd";
}

struct Case {
  std::vector<float> image, latent, decoded;
};

Case load_case(const std::string& name) {
  const std::string path = test::golden_dir() + "/taesd/case-" + name + "-256.safetensors";
  auto f = SafeTensors::open(path);
  REQUIRE(f.is_ok());
  Case c;
  c.image = f->read_f32("input.image", {1, 3, 256, 256}).value();
  c.latent = f->read_f32("output.latent", {1, 4, 32, 32}).value();
  c.decoded = f->read_f32("output.decoded", {1, 3, 256, 256}).value();
  return c;
}

}  // namespace

TEST_CASE("taesd: shipped weights equal the shared copy", "[nets][taesd]") {
  for (const char* f :
       {"taesd_encoder.safetensors", "taesd_decoder.safetensors", "LICENSE.taesd.txt"}) {
    auto a = read_file(weights_dir() + "/" + f);
    auto b = read_file(test::shared_dir() + "/weights/taesd/" + f);
    REQUIRE(a.is_ok());
    REQUIRE(b.is_ok());
    REQUIRE(*a == *b);
  }
}

TEST_CASE("taesd: encoder and decoder match the PyTorch goldens (fp32)", "[nets][taesd]") {
  auto taesd = Taesd::load(weights_dir());
  REQUIRE(taesd.is_ok());
  ThreadPool pool(2);
  for (const char* name : {"coffee", "chelsea"}) {
    INFO(name);
    Case c = load_case(name);
    auto z = taesd->encode(TensorView::f32(c.image.data(), {1, 3, 256, 256}), &pool);
    REQUIRE(z.is_ok());
    REQUIRE(z->shape() == Shape{1, 4, 32, 32});
    const test::Diff dz = test::compare(z->f32(), c.latent.data(), c.latent.size());
    INFO("latent rel L2 " << dz.rel_l2 << " max abs " << dz.max_abs);
    CHECK(dz.rel_l2 <= 1e-4);
    CHECK(dz.max_abs <= 1e-3);
    // The decoder on the golden latent (so its error is measured alone).
    auto y = taesd->decode(TensorView::f32(c.latent.data(), {1, 4, 32, 32}), &pool);
    REQUIRE(y.is_ok());
    REQUIRE(y->shape() == Shape{1, 3, 256, 256});
    const test::Diff dy = test::compare(y->f32(), c.decoded.data(), c.decoded.size());
    INFO("decoded rel L2 " << dy.rel_l2 << " max abs " << dy.max_abs);
    CHECK(dy.rel_l2 <= 1e-4);
    CHECK(dy.max_abs <= 1e-3);
  }
}

TEST_CASE("taesd: scalar kernels, batches, odd sizes and bf16", "[nets][taesd]") {
  Case c = load_case("coffee");
  const Isa before = active_isa();
  {
    // Scalar kernels against the active path on a 10x12 crop of the golden latent (the full
    // 256x256 decode is too slow for the scalar loops in a unit test).
    std::vector<float> crop(size_t(4 * 10 * 12));
    for (int ch = 0; ch < 4; ++ch)
      for (int y = 0; y < 10; ++y)
        for (int x = 0; x < 12; ++x)
          crop[size_t((ch * 10 + y) * 12 + x)] = c.latent[size_t((ch * 32 + y + 5) * 32 + x + 3)];
    auto fast = Taesd::load(weights_dir());
    REQUIRE(fast.is_ok());
    auto yf = fast->decode(TensorView::f32(crop.data(), {1, 4, 10, 12}), nullptr);
    REQUIRE(set_isa(Isa::kScalar).is_ok());
    auto slow = Taesd::load(weights_dir());
    REQUIRE(slow.is_ok());
    auto ys = slow->decode(TensorView::f32(crop.data(), {1, 4, 10, 12}), nullptr);
    REQUIRE(set_isa(before).is_ok());
    REQUIRE(yf.is_ok());
    REQUIRE(ys.is_ok());
    const test::Diff d = test::compare(yf->f32(), ys->f32(), size_t(yf->numel()));
    INFO("scalar vs " << isa_name(before) << ": rel L2 " << d.rel_l2);
    CHECK(d.rel_l2 <= 1e-5);
  }
  auto taesd = Taesd::load(weights_dir());
  REQUIRE(taesd.is_ok());
  ThreadPool pool(2);
  // Batch of two = the two singles.
  std::vector<float> two(c.latent);
  for (float v : c.latent) two.push_back(-v);
  auto y2 = taesd->decode(TensorView::f32(two.data(), {2, 4, 32, 32}), &pool);
  REQUIRE(y2.is_ok());
  std::vector<float> neg(c.latent.size());
  for (size_t i = 0; i < neg.size(); ++i) neg[i] = -c.latent[i];
  auto y1 = taesd->decode(TensorView::f32(neg.data(), {1, 4, 32, 32}), &pool);
  REQUIRE(y1.is_ok());
  const size_t img = size_t(3 * 256 * 256);
  CHECK(test::compare(y2->f32() + img, y1->f32(), img).max_abs <= 1e-5);
  // Odd input: 37 x 50 -> ceil(/8) = 5 x 7, and a crop of the coffee image encodes like PyTorch's
  // padding-1 stride-2 convs (shape check; values covered by the goldens above).
  std::vector<float> odd(size_t(3 * 37 * 50));
  for (int ch = 0; ch < 3; ++ch)
    for (int y = 0; y < 37; ++y)
      for (int x = 0; x < 50; ++x)
        odd[size_t((ch * 37 + y) * 50 + x)] = c.image[size_t((ch * 256 + y) * 256 + x)];
  auto zo = taesd->encode(TensorView::f32(odd.data(), {1, 3, 37, 50}), &pool);
  REQUIRE(zo.is_ok());
  CHECK(zo->shape() == Shape{1, 4, 5, 7});
  // Shape errors name the tensor.
  auto bad = taesd->encode(TensorView::f32(odd.data(), {1, 1, 37, 150}), &pool, "input.image");
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("input.image") != std::string::npos);
  CHECK(bad.status().message().find("[N,3,H,W]") != std::string::npos);
  // bf16 (conv inputs rounded to bf16): looser, stated bound.
  auto tb = Taesd::load(weights_dir(), Precision::kBf16);
  REQUIRE(tb.is_ok());
  auto zb = tb->encode(TensorView::f32(c.image.data(), {1, 3, 256, 256}), &pool);
  REQUIRE(zb.is_ok());
  const double eb = test::compare(zb->f32(), c.latent.data(), c.latent.size()).rel_l2;
  INFO("bf16 latent rel L2 " << eb);
  CHECK(eb <= 2e-2);
  CHECK(eb > 0.0);
}

TEST_CASE("taesd: loader names missing, unused and mis-shaped tensors", "[nets][taesd]") {
  test::TempDir dir("taesd-bad");
  auto enc = SafeTensors::open(weights_dir() + "/taesd_encoder.safetensors");
  REQUIRE(enc.is_ok());
  // Rewrite the encoder without "14.bias", with an extra tensor, and "0.weight" transposed.
  std::vector<std::vector<float>> keep;
  std::vector<TensorToWrite> ts;
  for (const std::string& n : enc->names()) {
    if (n == "14.bias") continue;
    const TensorEntry* e = enc->find(n);
    TensorToWrite t{n, e->dtype, e->shape, e->data};
    if (n == "0.weight") t.shape = {3, 64, 3, 3};
    ts.push_back(t);
  }
  float extra = 1.0f;
  ts.push_back({"15.weight", DType::kF32, {1}, &extra});
  REQUIRE(write_safetensors(dir.file("taesd_encoder.safetensors"), ts).is_ok());
  auto t = Taesd::load(dir.path);
  REQUIRE_FALSE(t.is_ok());
  const std::string& m = t.status().message();
  INFO(m);
  CHECK(m.find("taesd_encoder.safetensors") != std::string::npos);
  CHECK(m.find("missing tensor '14.bias'") != std::string::npos);
  CHECK(m.find("unused tensor '15.weight'") != std::string::npos);
  CHECK(m.find("'0.weight': expected shape [64,3,3,3], found [3,64,3,3]") != std::string::npos);
  auto none = Taesd::load(dir.file("nowhere"));
  REQUIRE_FALSE(none.is_ok());
  CHECK(none.status().message().find("not a TAESD folder") != std::string::npos);
}

TEST_CASE("taesd: diffusers AutoencoderTiny names load through the conversion table",
          "[nets][taesd]") {
  // Re-key the published files into diffusers' layout: encoder.layers.{i}, decoder.layers.{i-1}.
  test::TempDir dir("taesd-diffusers");
  auto enc = SafeTensors::open(weights_dir() + "/taesd_encoder.safetensors");
  auto dec = SafeTensors::open(weights_dir() + "/taesd_decoder.safetensors");
  REQUIRE(enc.is_ok());
  REQUIRE(dec.is_ok());
  std::vector<TensorToWrite> ts;
  std::vector<std::string> keep;  // names must outlive ts
  keep.reserve(256);
  for (auto* f : {&*enc, &*dec}) {
    const bool is_dec = f == &*dec;
    for (const std::string& n : f->names()) {
      const size_t dot = n.find('.');
      const int idx = std::stoi(n.substr(0, dot)) - (is_dec ? 1 : 0);
      keep.push_back(std::string(is_dec ? "decoder" : "encoder") + ".layers." +
                     std::to_string(idx) + n.substr(dot));
      const TensorEntry* e = f->find(n);
      ts.push_back({keep.back(), e->dtype, e->shape, e->data});
    }
  }
  REQUIRE(write_safetensors(dir.file("diffusion_pytorch_model.safetensors"), ts).is_ok());
  auto t = Taesd::load(dir.path);
  REQUIRE(t.is_ok());
  Case c = load_case("chelsea");
  ThreadPool pool(2);
  auto y = t->decode(TensorView::f32(c.latent.data(), {1, 4, 32, 32}), &pool);
  REQUIRE(y.is_ok());
  CHECK(test::compare(y->f32(), c.decoded.data(), c.decoded.size()).rel_l2 <= 1e-4);
}
