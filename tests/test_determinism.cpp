// Determinism policy (docs/reliability.md): `macro render`, `macro nn-run` and `macro enhance`
// write byte-identical files for the same inputs, run after run and for any --threads. Each test
// runs the real binary five times (--threads 1, 2, 2 again, 4 and 8: more threads than this machine
// has cores still splits the work as a many-core machine would) and compares every output file
// byte for byte. Inputs: the committed default scene, the real TAESD weights
// (data/weights/taesd), the tiny random U-Net/VAE goldens (unet-tiny, vae-tiny) alone and as a
// Difix pipeline, and a small synthetic DL3DV-Closeup folder for enhance (as in test_enhance.cpp).
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "enhance_fixture.h"
#include "test_support.h"

using namespace macro;
namespace fs = std::filesystem;

namespace {

std::string slurp_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Runs `macro <args>` (with {out} replaced by `out_dir`) once per thread setting and returns, per
// run, the bytes of each file named in `outputs` (relative to out_dir).
struct Runs {
  std::vector<std::vector<std::string>> bytes;  // [run][output]
};

Runs run_each_thread_count(const test::TempDir& tmp, const std::string& args,
                           const std::vector<std::string>& outputs) {
  Runs r;
  int k = 0;
  for (const char* threads : {"1", "2", "2", "4", "8"}) {
    const std::string out_dir = tmp.file("run" + std::to_string(k++));
    fs::create_directories(out_dir);
    std::string a = args;
    for (size_t at = a.find("{out}"); at != std::string::npos; at = a.find("{out}", at))
      a.replace(at, 5, out_dir);
    const std::string cmd = test::macro_exe() + " " + a + " --quiet --threads " + threads + " >" +
                            out_dir + "/log.txt 2>&1";
    const int rc = test::run_command(cmd);
    INFO(cmd << "\n" << slurp_bytes(out_dir + "/log.txt"));
    REQUIRE(rc == 0);
    std::vector<std::string> files;
    for (const auto& o : outputs) {
      REQUIRE(fs::exists(out_dir + "/" + o));
      files.push_back(slurp_bytes(out_dir + "/" + o));
      CHECK(files.back().size() > 0);
    }
    r.bytes.push_back(std::move(files));
  }
  return r;
}

void check_identical(const Runs& r, const std::vector<std::string>& outputs) {
  for (size_t o = 0; o < outputs.size(); ++o) {
    INFO("output " << outputs[o]);
    CHECK(r.bytes[0][o] == r.bytes[1][o]);  // --threads 1 vs 2
    CHECK(r.bytes[1][o] == r.bytes[2][o]);  // repeated run
    CHECK(r.bytes[0][o] == r.bytes[3][o]);  // --threads 4
    CHECK(r.bytes[0][o] == r.bytes[4][o]);  // --threads 8
  }
}

std::vector<float> wave(size_t n, float scale, float offset) {
  std::vector<float> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = offset + scale * std::sin(0.113f * float(i) + 0.7f);
  return v;
}

}  // namespace

TEST_CASE(
    "determinism: macro render writes identical PNG, EXR, safetensors and depth PNG for 1, 2, 4 "
    "and 8 threads",
    "[reliability][determinism]") {
  test::TempDir tmp("det-render");
  const std::string scene = test::source_dir() + "/data/scenes/default";
  const std::vector<std::string> outputs = {"a.png", "a.exr", "a.safetensors", "d.png"};
  for (const char* mode : {"classic", "antialiased"}) {
    INFO("mode " << mode);
    const Runs r = run_each_thread_count(
        tmp,
        "render --scene " + scene + " --camera closeup --mode " + mode +
            " --out-png {out}/a.png --out-exr {out}/a.exr --out-tensors {out}/a.safetensors "
            "--out-depth-png {out}/d.png",
        outputs);
    check_identical(r, outputs);
    fs::remove_all(tmp.file("run0")), fs::remove_all(tmp.file("run1")),
        fs::remove_all(tmp.file("run2"));
  }
}

TEST_CASE("determinism: macro nn-run TAESD (real weights) fp32 and bf16 for 1, 2, 4 and 8 threads",
          "[reliability][determinism]") {
  test::TempDir tmp("det-taesd");
  const std::vector<float> img = wave(size_t(1) * 3 * 64 * 96, 0.4f, 0.5f);
  const std::string in = tmp.file("in.safetensors");
  REQUIRE(
      write_safetensors(in, {{"input.image", DType::kF32, {1, 3, 64, 96}, img.data()}}).is_ok());
  for (const char* precision : {"fp32", "bf16"}) {
    INFO("precision " << precision);
    const Runs r = run_each_thread_count(tmp,
                                         "nn-run --model " + test::source_dir() +
                                             "/data/weights/taesd --inputs " + in +
                                             " --out {out}/o.safetensors --precision " + precision,
                                         {"o.safetensors"});
    check_identical(r, {"o.safetensors"});
  }
}

TEST_CASE("determinism: macro nn-run tiny U-Net, VAE and Difix pipeline for 1, 2, 4 and 8 threads",
          "[reliability][determinism]") {
  test::TempDir tmp("det-nets");
  const std::vector<float> z = wave(size_t(1) * 4 * 16 * 16, 1.0f, 0.0f);
  const std::vector<float> ctx = wave(size_t(1) * 77 * 48, 0.5f, 0.0f);
  const std::vector<float> t = {500.f};
  const std::string unet_in = tmp.file("unet.safetensors");
  REQUIRE(write_safetensors(unet_in, {{"input.z", DType::kF32, {1, 4, 16, 16}, z.data()},
                                      {"input.ctx", DType::kF32, {1, 77, 48}, ctx.data()},
                                      {"input.timestep", DType::kF32, {1}, t.data()}})
              .is_ok());
  const Runs u =
      run_each_thread_count(tmp,
                            "nn-run --model " + test::golden_dir() + "/unet-tiny --inputs " +
                                unet_in + " --out {out}/o.safetensors",
                            {"o.safetensors"});
  check_identical(u, {"o.safetensors"});

  const std::vector<float> img = wave(size_t(1) * 3 * 32 * 48, 0.9f, 0.0f);
  const std::string vae_in = tmp.file("vae.safetensors");
  REQUIRE(write_safetensors(vae_in, {{"input.image", DType::kF32, {1, 3, 32, 48}, img.data()}})
              .is_ok());
  for (const char* d : {"run0", "run1", "run2"}) fs::remove_all(tmp.file(d));
  const Runs v =
      run_each_thread_count(tmp,
                            "nn-run --model " + test::golden_dir() + "/vae-tiny --inputs " +
                                vae_in + " --out {out}/o.safetensors",
                            {"o.safetensors"});
  check_identical(v, {"o.safetensors"});

  const std::string pipe = test::make_tiny_pipeline(tmp);
  const std::vector<float> views = wave(size_t(2) * 3 * 32 * 48, 0.9f, 0.0f);
  const std::string pipe_in = tmp.file("pipe.safetensors");
  REQUIRE(write_safetensors(pipe_in, {{"input.images", DType::kF32, {2, 3, 32, 48}, views.data()},
                                      {"input.ctx", DType::kF32, {1, 77, 48}, ctx.data()}})
              .is_ok());
  for (const char* d : {"run0", "run1", "run2"}) fs::remove_all(tmp.file(d));
  const Runs p = run_each_thread_count(
      tmp, "nn-run --model " + pipe + " --inputs " + pipe_in + " --out {out}/o.safetensors",
      {"o.safetensors"});
  check_identical(p, {"o.safetensors"});
}

TEST_CASE(
    "determinism: macro enhance 3dgs and macro write identical images for 1, 2, 4 and 8 threads",
    "[reliability][determinism]") {
  test::TempDir tmp("det-enhance");
  const std::string scene_dir = test::write_synth_scene(tmp, test::tiny_scene_params());
  const std::string pipe = test::make_tiny_pipeline(tmp);
  const std::string base =
      "enhance --scene-dir " + scene_dir + " --closeup closeup.png --out {out}/e.png ";
  const Runs g = run_each_thread_count(tmp, base + "--method 3dgs", {"e.png"});
  check_identical(g, {"e.png"});
  for (const char* d : {"run0", "run1", "run2"}) fs::remove_all(tmp.file(d));
  const Runs m = run_each_thread_count(
      tmp, base + "--method macro --weights " + pipe + " --ctx " + tmp.file("ctx.safetensors"),
      {"e.png"});
  check_identical(m, {"e.png"});
}
