// Shared by the end-to-end enhance tests (test_enhance, test_warp, test_tight_crops, test_transfer,
// test_determinism, test_interrupts): a tiny Difix pipeline folder over the goldens (unet-tiny,
// vae-tiny; cross-attention width 48, so the prompt context is a fixed [1, 77, 48] tensor) and a
// small synthetic DL3DV-Closeup scene folder (gs/synth/synth.h generator,
// enhance/datasets/synth_scene_folder.h).
#pragma once

#include <catch2/catch.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/datasets/synth_scene_folder.h"
#include "enhance/enhance.h"
#include "enhance/scene_input.h"
#include "gs/synth/synth.h"
#include "test_support.h"
#include "tiny_checkpoint_fixture.h"

namespace macro::test {

constexpr int kTinyW = 128, kTinyH = 72;  // close-up and training image size of the tiny scene

// The tiny scene: mixed kind, seed 5, 20k Gaussians, 5 training views, 1 close-up, kTinyW x kTinyH.
inline gs::SynthParams tiny_scene_params() {
  gs::SynthParams p;
  p.seed = 5;
  p.kind = gs::SynthKind::kMixed;
  p.gaussians = 20'000;
  p.width = kTinyW;
  p.height = kTinyH;
  p.training_views = 5;
  p.closeup_views = 1;
  return p;
}

// Generates the scene of `p` and writes it as a DL3DV-Closeup folder at DIR/<rel>; its path.
inline std::string write_synth_scene(const TempDir& dir, const gs::SynthParams& p,
                                     const std::string& rel = "scene") {
  auto scene = gs::generate_synthetic_scene(p);
  REQUIRE(scene.is_ok());
  const std::string scene_dir = dir.file(rel);
  REQUIRE(enhance::write_closeup_scene_folder(*scene, scene_dir).is_ok());
  return scene_dir;
}

// DIR/pipe: model_index.json, unet/ and vae/ (symlinks to the goldens); DIR/ctx.safetensors.
// Returns DIR/pipe.
inline std::string make_tiny_pipeline(const TempDir& dir) {
  const std::string root = dir.file("pipe");
  write_tiny_pipeline(root);
  std::vector<float> ctx(77 * 48);
  for (size_t i = 0; i < ctx.size(); ++i) ctx[i] = 0.5f * std::sin(0.37f * float(i));
  REQUIRE(write_safetensors(dir.file("ctx.safetensors"),
                            {{"ctx", DType::kF32, {1, 77, 48}, ctx.data()}})
              .is_ok());
  return root;
}

// A temporary folder holding the tiny scene (scene_dir), the tiny pipeline (pipe) and its prompt
// context (ctx).
struct TinyEnhanceFolder {
  TempDir tmp;
  std::string scene_dir, pipe, ctx;
  explicit TinyEnhanceFolder(const std::string& tag) : tmp(tag) {
    scene_dir = write_synth_scene(tmp, tiny_scene_params());
    pipe = make_tiny_pipeline(tmp);
    ctx = tmp.file("ctx.safetensors");
  }
  // The scene's inputs for the close-up "closeup.png".
  enhance::SceneInputs inputs() const {
    enhance::SceneInputOptions o;
    o.scene_dir = scene_dir;
    o.closeup = "closeup.png";
    auto in = enhance::load_scene_inputs(o);
    REQUIRE(in.is_ok());
    return std::move(in).value();
  }
};

// enhance_closeup with `o` on a 1-thread pool, then on a 2-thread pool (o.pool is ignored): the
// pair the thread-count invariance checks compare.
struct OneAndTwoThreads {
  enhance::EnhanceResult one, two;
};
inline OneAndTwoThreads enhance_on_1_and_2_threads(const enhance::SceneInputs& in,
                                                   enhance::EnhanceOptions o) {
  ThreadPool one(1), two(2);
  o.pool = &one;
  auto a = enhance::enhance_closeup(in, o);
  INFO((a.is_ok() ? "" : a.status().message()));
  REQUIRE(a.is_ok());
  o.pool = &two;
  auto b = enhance::enhance_closeup(in, o);
  REQUIRE(b.is_ok());
  return {std::move(a).value(), std::move(b).value()};
}

}  // namespace macro::test
