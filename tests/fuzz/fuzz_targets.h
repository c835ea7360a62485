// Fuzz entry points: one function per untrusted-input parser, each feeding raw bytes to the real
// library entry point and returning its Status. Used by the libFuzzer targets
// (tests/fuzz/fuzz_*.cpp, built with -DMACRO_FUZZ=ON) and by tests/test_fuzz_regressions.cpp, which
// replays every input in tests/fuzz/regressions/<target>/ through the normal build.
//
// APIs that take a path get the bytes written to a per-process scratch folder under /tmp
// (/tmp/macro-fuzz-<pid>/). Inputs that need two files (COLMAP cameras + images, tokenizer vocab +
// merges, safetensors index + shard) are split by split_two(): a 4-byte little-endian length of the
// first part, then the first part, then the second. A short input gives an empty first part.
//
// Contract under test (docs/reliability.md): no crash, no hang, no sanitizer report, no exception,
// no allocation from a size the file claims but does not hold. Errors are fine.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "attention/nets/clip_tokenizer.h"
#include "attention/nets/diffusers_config.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/io/torch_checkpoint.h"
#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/colmap_points.h"
#include "gs/image_io.h"
#include "gs/formats/scene_io.h"

namespace macro::fuzz {

// Scratch folder for this process, created on first use and removed at normal exit.
inline const std::string& scratch_dir() {
  // Never destroyed: the exit handler below runs after static destructors registered later.
  static const std::string& dir = *[] {
    auto* d = new std::string("/tmp/macro-fuzz-" + std::to_string(::getpid()));
    std::error_code ec;
    std::filesystem::create_directories(*d, ec);
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(scratch_dir(), ignored);
    });
    return d;
  }();
  return dir;
}

inline std::string write_scratch(const std::string& name, const uint8_t* data, size_t size) {
  std::string path = scratch_dir() + "/" + name;
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    if (size) std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  return path;
}

inline std::pair<std::string, std::string> split_two(const uint8_t* data, size_t size) {
  if (size < 4) return {std::string(), std::string(reinterpret_cast<const char*>(data), size)};
  uint32_t n = uint32_t(data[0]) | uint32_t(data[1]) << 8 | uint32_t(data[2]) << 16 |
               uint32_t(data[3]) << 24;
  size_t first = std::min<size_t>(n, size - 4);
  const char* p = reinterpret_cast<const char*>(data) + 4;
  return {std::string(p, first), std::string(p + first, size - 4 - first)};
}

inline std::string write_scratch(const std::string& name, const std::string& text) {
  return write_scratch(name, reinterpret_cast<const uint8_t*>(text.data()), text.size());
}

// Limits small enough that a lying count is refused quickly instead of exhausting the fuzzer's
// memory budget; the loaders must check counts against the bytes present before allocating anyway.
inline gs::LoadLimits scene_limits() {
  gs::LoadLimits l;
  l.max_gaussians = 1u << 20;
  l.max_file_bytes = 1u << 26;
  return l;
}
inline gs::ImageLimits image_limits() {
  gs::ImageLimits l;
  l.max_pixels = 1u << 22;
  l.max_file_bytes = 1u << 26;
  return l;
}

inline Status scene(const uint8_t* data, size_t size, const char* name) {
  gs::LoadReport report;
  auto r = gs::load_scene_from_memory(data, size, name, scene_limits(), &report);
  return r.is_ok() ? Status::ok() : r.status();
}
// Content detection decides .ply / compressed .ply / .spz; the name decides .splat.
inline Status scene_ply(const uint8_t* d, size_t n) {
  return scene(d, n, "fuzz.ply");
}
inline Status scene_splat(const uint8_t* d, size_t n) {
  return scene(d, n, "fuzz.splat");
}
inline Status scene_spz(const uint8_t* d, size_t n) {
  return scene(d, n, "fuzz.spz");
}
// A .sog zip (meta.json and WebP members) and a gsplat checkpoint (torch zip).
inline Status scene_sog(const uint8_t* d, size_t n) {
  return scene(d, n, "fuzz.sog");
}
inline Status scene_gsplat(const uint8_t* d, size_t n) {
  return scene(d, n, "fuzz.pt");
}

// One .safetensors file; every tensor is then read out as float32.
inline Status safetensors(const uint8_t* data, size_t size) {
  auto st = SafeTensors::open(write_scratch("model.safetensors", data, size));
  if (!st.is_ok()) return st.status();
  for (const std::string& name : st->names()) {
    auto v = st->read_f32(name);
    if (!v.is_ok()) return v.status();
  }
  return Status::ok();
}

// A PyTorch zip checkpoint, with automatic selection and with an explicit key; every selected
// tensor is then converted to float32.
inline Status torch_checkpoint(const uint8_t* data, size_t size) {
  Status last = Status::ok();
  for (const char* key : {"", "params"}) {
    auto r = read_torch_checkpoint_from_memory(data, size, "fuzz.pth", key);
    if (!r.is_ok()) {
      last = r.status();
      continue;
    }
    std::vector<float> out;
    for (const TensorEntry& e : r->tensors) {
      out.resize(e.bytes / dtype_size(e.dtype));
      MACRO_TRY(convert_to_f32(e, out.data(), out.size()));
    }
  }
  return last;
}

// An index JSON (first part) naming shards; the second part is written as shard.safetensors.
inline Status safetensors_index(const uint8_t* data, size_t size) {
  auto [index, shard] = split_two(data, size);
  write_scratch("shard.safetensors", shard);
  auto st = SafeTensors::open_checkpoint(write_scratch("model.safetensors.index.json", index));
  if (!st.is_ok()) return st.status();
  for (const std::string& name : st->names()) {
    auto v = st->read_f32(name);
    if (!v.is_ok()) return v.status();
  }
  return Status::ok();
}

inline Status cameras_json(const uint8_t* data, size_t size) {
  auto r = gs::load_cameras_json(write_scratch("cameras.json", data, size));
  return r.is_ok() ? Status::ok() : r.status();
}

// Content detection of load_cameras on a single file (our JSON list, transforms.json, split JSON).
inline Status cameras_any(const uint8_t* data, size_t size) {
  auto r = gs::load_cameras(write_scratch("any/cameras_input.json", data, size));
  return r.is_ok() ? Status::ok() : r.status();
}

inline Status nerfstudio(const uint8_t* data, size_t size) {
  auto r = gs::load_nerfstudio(write_scratch("transforms.json", data, size));
  return r.is_ok() ? Status::ok() : r.status();
}

inline Status closeup_split(const uint8_t* data, size_t size) {
  auto r = gs::load_closeup_split(write_scratch("split.json", data, size));
  return r.is_ok() ? Status::ok() : r.status();
}

// split_two: cameras.txt, images.txt.
inline Status colmap_points_text(const uint8_t* data, size_t size) {
  auto r = gs::load_colmap_points_text(write_scratch("colmap_points/points3D.txt", data, size));
  return r.is_ok() ? Status::ok() : r.status();
}

inline Status colmap_points_binary(const uint8_t* data, size_t size) {
  auto r = gs::load_colmap_points_binary(write_scratch("colmap_points/points3D.bin", data, size));
  return r.is_ok() ? Status::ok() : r.status();
}

inline Status colmap_text(const uint8_t* data, size_t size) {
  auto [cams, imgs] = split_two(data, size);
  auto r = gs::load_colmap_text(write_scratch("colmap_text/cameras.txt", cams),
                                write_scratch("colmap_text/images.txt", imgs));
  return r.is_ok() ? Status::ok() : r.status();
}

// split_two: cameras.bin, images.bin.
inline Status colmap_binary(const uint8_t* data, size_t size) {
  auto [cams, imgs] = split_two(data, size);
  auto r = gs::load_colmap_binary(write_scratch("colmap_bin/cameras.bin", cams),
                                  write_scratch("colmap_bin/images.bin", imgs));
  return r.is_ok() ? Status::ok() : r.status();
}

// split_two: vocab.json, merges.txt; a loaded tokenizer then encodes a fixed prompt.
inline Status clip_tokenizer(const uint8_t* data, size_t size) {
  auto [vocab, merges] = split_two(data, size);
  write_scratch("tokenizer/vocab.json", vocab);
  write_scratch("tokenizer/merges.txt", merges);
  auto t = nets::ClipTokenizer::load(scratch_dir() + "/tokenizer");
  if (!t.is_ok()) return t.status();
  auto ids = t->encode("a photo of a cat, close-up &amp; 42 caf\xc3\xa9 \xe2\x9c\x93");
  if (ids.size() != size_t(nets::ClipTokenizer::kContextLength))
    return Status::error("encode returned " + std::to_string(ids.size()) + " ids");
  return Status::ok();
}

// The text side: a tiny fixed tokenizer encodes the input. The input keeps the split_two layout
// (first part ignored) so seeds and findings look like those of clip_tokenizer.
inline Status clip_tokenizer_text(const uint8_t* data, size_t size) {
  auto [ignored, text] = split_two(data, size);
  static const char kVocab[] =
      R"({"a": 0, "b": 1, "c": 2, "a</w>": 3, "b</w>": 4, "c</w>": 5, "ab": 6, "ab</w>": 7,)"
      R"( "!": 8, "<|startoftext|>": 9, "<|endoftext|>": 10})";
  static const char kMerges[] = "#version: 0.2\na b\na b</w>\n";
  write_scratch("tokenizer_text/vocab.json", std::string(kVocab));
  write_scratch("tokenizer_text/merges.txt", std::string(kMerges));
  static auto t = nets::ClipTokenizer::load(scratch_dir() + "/tokenizer_text");
  if (!t.is_ok()) return t.status();
  (void)ignored;
  auto ids = t->encode(text);
  if (ids.size() != size_t(nets::ClipTokenizer::kContextLength))
    return Status::error("encode returned " + std::to_string(ids.size()) + " ids");
  return Status::ok();
}

// PNG / JPEG / BMP / TGA from memory.
inline Status image(const uint8_t* data, size_t size) {
  auto r = gs::decode_image(data, size, "fuzz.png", image_limits());
  return r.is_ok() ? Status::ok() : r.status();
}

inline Status exr(const uint8_t* data, size_t size) {
  auto r = gs::read_exr(write_scratch("fuzz.exr", data, size), image_limits());
  return r.is_ok() ? Status::ok() : r.status();
}

// The same JSON text parsed as a U-Net, a VAE and a CLIP text config.
inline Status diffusers_config(const uint8_t* data, size_t size) {
  std::string text(reinterpret_cast<const char*>(data), size);
  auto u = nets::parse_unet_config(text, "config.json");
  auto v = nets::parse_vae_config(text, "config.json");
  auto c = nets::parse_clip_text_config(text, "config.json");
  if (u.is_ok() || v.is_ok() || c.is_ok()) return Status::ok();
  return u.status();
}

using EntryFn = Status (*)(const uint8_t*, size_t);
struct Entry {
  const char* name;  // target name: fuzz_<name>, regressions/<name>/
  EntryFn fn;
};
inline const std::vector<Entry>& entries() {
  static const std::vector<Entry> all = {
      {"scene_ply", scene_ply},
      {"scene_splat", scene_splat},
      {"scene_spz", scene_spz},
      {"scene_sog", scene_sog},
      {"scene_gsplat", scene_gsplat},
      {"safetensors", safetensors},
      {"safetensors_index", safetensors_index},
      {"torch_checkpoint", torch_checkpoint},
      {"cameras_json", cameras_json},
      {"cameras_any", cameras_any},
      {"nerfstudio", nerfstudio},
      {"closeup_split", closeup_split},
      {"colmap_text", colmap_text},
      {"colmap_binary", colmap_binary},
      {"colmap_points_text", colmap_points_text},
      {"colmap_points_binary", colmap_points_binary},
      {"clip_tokenizer", clip_tokenizer},
      {"clip_tokenizer_text", clip_tokenizer_text},
      {"image", image},
      {"exr", exr},
      {"diffusers_config", diffusers_config},
  };
  return all;
}

}  // namespace macro::fuzz
