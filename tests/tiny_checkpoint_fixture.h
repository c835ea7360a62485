// Tiny checkpoints for the network tests: a Difix pipeline folder over the tiny goldens
// (unet-tiny, vae-tiny; cross-attention width 48), shared by test_difix, test_clip_text and the
// end-to-end enhance tests (enhance_fixture.h); and `macro nn-run` over such a folder.
#pragma once

#include <catch2/catch.hpp>

#include <filesystem>
#include <string>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "test_support.h"

namespace macro::test {

inline constexpr const char* kTinyModelIndex = R"({"_class_name": "DifixPipeline"})";

// Creates `root` with unet/ and vae/ (symlinks to unet-tiny and vae-tiny) and model_index.json
// holding `model_index`.
inline void write_tiny_pipeline(const std::string& root,
                                const std::string& model_index = kTinyModelIndex) {
  namespace fs = std::filesystem;
  fs::create_directories(root);
  fs::create_directory_symlink(golden_dir() + "/unet-tiny", root + "/unet");
  fs::create_directory_symlink(golden_dir() + "/vae-tiny", root + "/vae");
  REQUIRE(write_file_atomic(root + "/model_index.json", model_index).is_ok());
}

// `macro nn-run` on the model folder with two threads, its stdout and stderr into `log`.
inline std::string nn_run_command(const std::string& model, const std::string& in,
                                  const std::string& out, const std::string& log) {
  return macro_exe() + " nn-run --model " + model + " --inputs " + in + " --out " + out +
         " --threads 2 > " + log + " 2>&1";
}

// Runs `cmd` (nn_run_command), requires exit status 0 (showing `log` otherwise), opens `out`.
inline Result<SafeTensors> run_nn_run(const std::string& cmd, const std::string& log,
                                      const std::string& out) {
  const int rc = run_command(cmd);
  auto text = read_text_file(log);
  INFO((text.is_ok() ? *text : std::string("no log")));
  REQUIRE(rc == 0);
  return SafeTensors::open(out);
}

}  // namespace macro::test
