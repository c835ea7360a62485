// `macro nn-run` end to end: the binary on a golden input, and refusals of bad inputs.
#include <catch2/catch.hpp>
#include <cmath>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "test_support.h"

using namespace macro;

namespace {

std::string model_dir() {
  return test::source_dir() + "/data/weights/taesd";
}

int run_nn(const std::string& inputs, const std::string& out, const std::string& extra,
           const std::string& log) {
  return test::run_command(test::macro_exe() + " nn-run --model " + model_dir() + " --inputs " +
                           inputs + " --out " + out + " --threads 2 " + extra + " > " + log +
                           " 2>&1");
}

}  // namespace

TEST_CASE("nn-run taesd: the binary reproduces the golden case", "[nets][taesd][nn-run]") {
  test::TempDir dir("nn-run");
  const std::string golden = test::golden_dir() + "/taesd/case-chelsea-256.safetensors";
  auto g = SafeTensors::open(golden);
  REQUIRE(g.is_ok());
  // The golden file also holds outputs: pass only input.image.
  auto image = g->read_f32("input.image", {1, 3, 256, 256});
  REQUIRE(image.is_ok());
  const std::string in = dir.file("in.safetensors"), out = dir.file("out.safetensors");
  REQUIRE(write_safetensors(in, {{"input.image", DType::kF32, {1, 3, 256, 256}, image->data()}})
              .is_ok());
  REQUIRE(run_nn(in, out, "", dir.file("log.txt")) == 0);
  auto o = SafeTensors::open(out);
  REQUIRE(o.is_ok());
  CHECK(o->metadata().at("model") == "taesd");
  auto z = o->read_f32("output.latent", {1, 4, 32, 32});
  auto y = o->read_f32("output.decoded", {1, 3, 256, 256});
  REQUIRE(z.is_ok());
  REQUIRE(y.is_ok());
  auto gz = g->read_f32("output.latent").value();
  auto gy = g->read_f32("output.decoded").value();
  CHECK(test::compare(*z, gz).rel_l2 <= 1e-4);
  // output.decoded decodes OUR latent, the golden decodes the golden latent: the latent's 1e-5
  // level difference propagates, so the bound is the golden one plus that.
  const test::Diff dy = test::compare(*y, gy);
  INFO("decoded rel L2 " << dy.rel_l2);
  CHECK(dy.rel_l2 <= 2e-4);
}

TEST_CASE("nn-run taesd: bad inputs are refused naming the tensor", "[nets][taesd][nn-run]") {
  test::TempDir dir("nn-run-bad");
  const std::string out = dir.file("out.safetensors"), log = dir.file("log.txt");
  auto expect_refusal = [&](const std::vector<TensorToWrite>& ts, const std::string& needle) {
    const std::string in = dir.file("in.safetensors");
    REQUIRE(write_safetensors(in, ts).is_ok());
    CHECK(run_nn(in, out, "", log) == 1);
    auto text = read_text_file(log);
    REQUIRE(text.is_ok());
    INFO(*text);
    CHECK(text->find(needle) != std::string::npos);
    CHECK_FALSE(file_exists(out));
  };
  std::vector<float> img(size_t(2 * 3 * 16 * 16), 0.5f);
  expect_refusal({{"input.image", DType::kF32, {2, 1, 48, 16}, img.data()}},
                 "'input.image': expected [N,3,H,W], found [2,1,48,16]");
  expect_refusal({{"input.image", DType::kF32, {6, 16, 16}, img.data()}}, "expected rank 4");
  expect_refusal({{"input.picture", DType::kF32, {2, 3, 16, 16}, img.data()}},
                 "unexpected tensor 'input.picture'");
  std::vector<float> nan_img = img;
  nan_img[777] = NAN;
  expect_refusal({{"input.image", DType::kF32, {2, 3, 16, 16}, nan_img.data()}},
                 "'input.image': element 777 is NaN");
  std::vector<int32_t> ints(img.size());
  expect_refusal({{"input.image", DType::kI32, {2, 3, 16, 16}, ints.data()}},
                 "expected a float dtype");
  // Unknown precision and missing flags are usage errors with the flag named.
  const std::string in = dir.file("ok.safetensors");
  REQUIRE(
      write_safetensors(in, {{"input.image", DType::kF32, {2, 3, 16, 16}, img.data()}}).is_ok());
  CHECK(run_nn(in, out, "--precision fp8", log) == 1);
  CHECK(read_text_file(log)->find("--precision") != std::string::npos);
  // Batch of two small images in bf16 runs and has the right shapes.
  REQUIRE(run_nn(in, out, "--precision bf16", log) == 0);
  auto o = SafeTensors::open(out);
  REQUIRE(o.is_ok());
  CHECK(o->find("output.latent")->shape == std::vector<int64_t>{2, 4, 2, 2});
  CHECK(o->find("output.decoded")->shape == std::vector<int64_t>{2, 3, 16, 16});
  CHECK(o->metadata().at("precision") == "bf16");
}
