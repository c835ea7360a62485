// Tiny checkpoints for the network tests: a Difix pipeline folder over the tiny goldens
// (unet-tiny, vae-tiny; cross-attention width 48), shared by test_difix, test_clip_text and the
// end-to-end enhance tests (enhance_fixture.h).
#pragma once

#include <catch2/catch.hpp>

#include <filesystem>
#include <string>

#include "attention/runtime/file_io.h"
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

}  // namespace macro::test
