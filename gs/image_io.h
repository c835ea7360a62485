// Image files: PNG/JPEG read, 8-bit PNG and JPEG write, OpenEXR float read/write with named
// channels.
//
// Legend: H x W pixels, C channels; data is row-major [H,W,C], row 0 at the top.
//
// Reading validates before decoding: the file must exist and be non-empty, the header must give a
// positive size whose pixel count is at most ImageLimits::max_pixels (checked from the header,
// before the pixels are allocated), the file must be large enough to hold what its header claims
// (PNG: its raw size within deflate's ~1032:1; other formats within 8192:1), and a truncated or
// corrupt file is an error naming it.
// PNG (8- or 16-bit, gray, gray+alpha, RGB, RGBA) and the other formats stb decodes (JPEG, BMP,
// TGA) come back as float RGB in [0, 1] (value / 255 or / 65535; gray is copied to R, G, B; alpha
// is dropped, not composited). Writing clamps to [0, 1] and rounds to 8 bits (round half up).
// EXR holds 32-bit float channels under names (uncompressed unless asked) (e.g. R, G, B, A, depth);
// OpenEXR stores channels sorted by name, so callers look channels up by name. All writes are
// atomic (temporary + rename). No third-party type appears in this header (stb and OpenEXR live in
// image_io.cpp only).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/limits.h"
#include "attention/runtime/status.h"

namespace macro::gs {

struct Image {
  int width = 0, height = 0, channels = 0;  // W, H, C
  std::vector<float> data;                  // [H,W,C]

  Image() = default;
  Image(int w, int h, int c) : width(w), height(h), channels(c), data(size_t(w) * h * c, 0.f) {}
  size_t pixels() const { return size_t(width) * size_t(height); }
  float& at(int i, int j, int c) { return data[(size_t(i) * width + j) * channels + c]; }
  float at(int i, int j, int c) const { return data[(size_t(i) * width + j) * channels + c]; }
};

struct ImageLimits {
  // 2^27 = 134 M pixels by default (a 16k x 8k panorama fits); --max-image-pixels.
  uint64_t max_pixels = resource_limits().max_image_pixels;
  uint64_t max_file_bytes = 1ull << 32;  // 4 GiB
};

// PNG (or JPEG/BMP/TGA) -> float RGB [H,W,3] in [0, 1].
Result<Image> read_image(const std::string& path, const ImageLimits& limits = {});
// The same from bytes in memory; `name` is used in messages.
Result<Image> decode_image(const uint8_t* bytes, size_t size, const std::string& name,
                           const ImageLimits& limits = {});

// 8-bit PNG from a float image with 1 (gray), 3 (RGB) or 4 (RGBA) channels; values clamped to
// [0, 1] and rounded. Non-finite values are written as 0.
Status write_png(const std::string& path, const Image& image);
// The 8-bit level write_png writes for v (round half up; v <= 0 or NaN: 0; v >= 1: 255).
uint8_t png_byte(float v);
// The values an image takes through write_png and read_image (each value its level / 255), in
// place: what a pipeline that saves its output as 8-bit PNG is scored on.
void round_to_png_levels(std::vector<float>* values);
// The first w * h * 3 values of `rgb` as a w x h RGB image through round_to_png_levels: a render
// as a pipeline that saves it as an 8-bit PNG and reads it back is scored (and shown) on.
Image png_levels_image(const float* rgb, int w, int h);
// The bytes write_png would write (for tests and for callers that bundle files).
Result<std::vector<uint8_t>> encode_png(const Image& image);
// Baseline JPEG (stb: 4:2:0 up to quality 90, 4:4:4 above) from a 1- or 3-channel float image,
// clamped and rounded as write_png; `quality` 1..100.
Status write_jpeg(const std::string& path, const Image& image, int quality);
Result<std::vector<uint8_t>> encode_jpeg(const Image& image, int quality);

// One float plane [H,W] under a channel name.
struct ExrChannel {
  std::string name;
  const float* data = nullptr;  // [H,W], must hold width * height values
};
// Lossless options. Float renders barely compress: for a 960x540 six-channel render (12.4 MB raw)
// none took 13 ms CPU, ZIP level 1 300 ms for 10.5 MB, PIZ 310 ms for 8.7 MB (docs/PERFORMANCE.md).
enum class ExrCompression { kNone, kZip, kPiz };
// 32-bit float EXR, one scanline image with the given channels.
Status write_exr(const std::string& path, int width, int height,
                 const std::vector<ExrChannel>& channels,
                 ExrCompression compression = ExrCompression::kNone);

struct ExrImage {
  int width = 0, height = 0;
  std::vector<std::string> names;          // channel names as stored (sorted by OpenEXR)
  std::vector<std::vector<float>> planes;  // [channel][H,W], same order as names
  // The plane of a named channel, or nullptr.
  const std::vector<float>* find(const std::string& name) const;
};
// Any scanline or tiled EXR; every channel (half, float or uint) is returned as float.
Result<ExrImage> read_exr(const std::string& path, const ImageLimits& limits = {});

// Colour map for viewing a scalar in [0, 1] (outside clamped) -> RGB: dark blue (0, far) through
// purple and orange to pale yellow (1, near). Piecewise linear over five fixed colours.
void colormap(float value, float rgb[3]);

}  // namespace macro::gs
