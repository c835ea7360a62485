// Image files (see image_io.h). stb_image / stb_image_write are instantiated here and only here
// (static linkage, no stdio: bytes go through our bounded reader and atomic writer); PNG deflate
// uses zlib. OpenEXR is used through its C++ API; its exceptions are caught at this file's edge.
#include "gs/image_io.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <limits>

#include "attention/runtime/file_io.h"

// ---- stb, instantiated once ---------------------------------------------------------------------
namespace {
// stb_image_write's deflate replaced by zlib (smaller files, the same bytes everywhere).
constexpr int kPngZlibLevel =
    3;  // 960x540 render: 3 cost ~30 ms CPU for 459 KB, 6 ~100 ms for 406 KB
constexpr int kExrZipLevel = 1;  // float renders barely compress: level 4 was 1% smaller, slower
unsigned char* zlib_compress_for_stb(unsigned char* data, int data_len, int* out_len, int quality) {
  uLongf cap = compressBound(static_cast<uLong>(data_len));
  auto* out = static_cast<unsigned char*>(std::malloc(cap));
  if (!out) return nullptr;
  if (compress2(out, &cap, data, static_cast<uLong>(data_len), kPngZlibLevel) != Z_OK) {
    std::free(out);
    return nullptr;
  }
  *out_len = static_cast<int>(cap);
  return out;
}
}  // namespace

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wunused-but-set-variable"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#pragma GCC diagnostic ignored "-Wdouble-promotion"
#pragma GCC diagnostic ignored "-Wpedantic"
#define STB_IMAGE_STATIC
#define STBI_NO_STDIO
#define STBI_NO_HDR
#define STBI_NO_LINEAR
#define STBI_ONLY_PNG
#define STBI_ONLY_JPEG
#define STBI_ONLY_BMP
#define STBI_ONLY_TGA
#define STB_IMAGE_IMPLEMENTATION
#include <stb/stb_image.h>
#define STB_IMAGE_WRITE_STATIC
#define STBI_WRITE_NO_STDIO
#define STBIW_ZLIB_COMPRESS zlib_compress_for_stb
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb/stb_image_write.h>
#pragma GCC diagnostic pop

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>

namespace macro::gs {
namespace {

constexpr uint64_t kMaxDeflateRatio = 1100;  // deflate's limit is ~1032:1
constexpr uint64_t kMaxOtherRatio = 8192;    // JPEG/BMP/TGA decoded bytes per file byte
constexpr uint64_t kMaxExrRatio = 8192;      // EXR float bytes per file byte

std::string dims(uint64_t w, uint64_t h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

Status check_size(const std::string& name, int64_t w, int64_t h, const ImageLimits& limits) {
  if (w <= 0 || h <= 0) {
    return Status::error(name + ": expected a positive image size, found " + std::to_string(w) +
                         "x" + std::to_string(h));
  }
  if (uint64_t(w) * uint64_t(h) > limits.max_pixels) {
    return Status::error(name + ": image " + dims(w, h) + " has more than the limit of " +
                         std::to_string(limits.max_pixels) + " pixels (--max-image-pixels)");
  }
  return Status::ok();
}

// Every PNG chunk must fit in the file: stb grows its IDAT buffer to a chunk's declared length
// before reading it, so a lying length would allocate gigabytes.
Status check_png_chunks(const uint8_t* bytes, size_t size, const std::string& name) {
  size_t at = 8;
  while (at + 8 <= size) {
    const uint32_t length = (uint32_t(bytes[at]) << 24) | (uint32_t(bytes[at + 1]) << 16) |
                            (uint32_t(bytes[at + 2]) << 8) | uint32_t(bytes[at + 3]);
    const std::string type(reinterpret_cast<const char*>(bytes + at + 4), 4);
    if (uint64_t(length) + 12 > uint64_t(size - at)) {
      return Status::error(name + ": PNG chunk '" + type + "' at byte " + std::to_string(at) +
                           " claims " + std::to_string(length) + " bytes but only " +
                           std::to_string(size - at) + " remain: truncated or corrupt");
    }
    at += size_t(length) + 12;
    if (type == "IEND") return Status::ok();
  }
  return Status::ok();  // a missing IEND is stb's to report
}

// TGA: the decoder fills missing pixel data with zeros instead of failing, so the data a header
// promises must fit in the file: exactly for uncompressed images, by RLE's 128:1 bound otherwise.
Status check_tga_size(const uint8_t* bytes, size_t size, const std::string& name, int w, int h) {
  if (size < 18) return Status::ok();  // stb refuses it
  const uint32_t id_length = bytes[0], colormap_type = bytes[1], image_type = bytes[2];
  const uint32_t cmap_length = uint32_t(bytes[5]) | (uint32_t(bytes[6]) << 8);
  const uint32_t cmap_bits = bytes[7], pixel_bits = bytes[16];
  const uint64_t pixel_bytes = std::max<uint64_t>(1, (pixel_bits + 7) / 8);
  const uint64_t header =
      18 + id_length + (colormap_type ? cmap_length * ((cmap_bits + 7) / 8) : 0);
  const uint64_t data = uint64_t(w) * uint64_t(h) * pixel_bytes;
  const bool rle = image_type >= 9;
  const uint64_t available = size > header ? size - header : 0;
  if ((!rle && data > available) || (rle && data > 128 * available + 4096)) {
    return Status::error(name + ": TGA header says " + dims(w, h) + " with " +
                         std::to_string(pixel_bits) + "-bit pixels but the file has only " +
                         std::to_string(size) + " bytes: truncated or corrupt");
  }
  return Status::ok();
}

bool is_jpeg(const uint8_t* b, size_t n) {
  return n >= 3 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF;
}
bool is_bmp(const uint8_t* b, size_t n) {
  return n >= 2 && b[0] == 'B' && b[1] == 'M';
}

// BMP: stb reads missing rows of an uncompressed bitmap as zeros, so the rows the header promises
// (from bfOffBits, the stride of 4-byte-aligned rows and |height|) must fit in the file.
// Compressed bitmaps (RLE4/RLE8) keep the loose ratio bound of decode_image.
Status check_bmp_size(const uint8_t* b, size_t size, const std::string& name, int w, int h) {
  if (size < 26) return Status::ok();  // stb refuses it
  auto le16 = [&](size_t at) { return uint32_t(b[at]) | (uint32_t(b[at + 1]) << 8); };
  auto le32 = [&](size_t at) { return le16(at) | (le16(at + 2) << 16); };
  const uint32_t data_offset = le32(10), info_size = le32(14);
  uint32_t bits = 0, compression = 0;
  if (info_size == 12) {
    bits = le16(24);
  } else if (size >= 34) {
    bits = le16(28);
    compression = le32(30);
  } else {
    return Status::ok();
  }
  if (compression != 0 && compression != 3 && compression != 6) return Status::ok();
  const uint64_t stride = (uint64_t(w) * bits + 31) / 32 * 4;
  const uint64_t need = uint64_t(data_offset) + stride * uint64_t(h);
  if (need > size) {
    return Status::error(
        name + ": BMP header says " + dims(w, h) + " with " + std::to_string(bits) +
        "-bit pixels from byte " + std::to_string(data_offset) + ", " + std::to_string(need) +
        " bytes, but the file has only " + std::to_string(size) + ": truncated or corrupt");
  }
  return Status::ok();
}

}  // namespace

// ---- PNG / JPEG read
// -----------------------------------------------------------------------------

Result<Image> decode_image(const uint8_t* bytes, size_t size, const std::string& name,
                           const ImageLimits& limits) {
  if (size == 0) return Status::error(name + ": empty file, expected an image");
  if (size > uint64_t(std::numeric_limits<int>::max())) {
    return Status::error(name + ": file of " + std::to_string(size) +
                         " bytes is larger than the image decoder accepts (2 GiB)");
  }
  const int len = static_cast<int>(size);
  // PNG: the size from IHDR first, so an absurd size gets our limit message (stb's own cap says
  // only "too large").
  static constexpr uint8_t kPngMagic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  bool is_png = false;
  if (size >= 26 && std::memcmp(bytes, kPngMagic, 8) == 0 &&
      std::memcmp(bytes + 12, "IHDR", 4) == 0) {
    auto be32 = [&](size_t at) {
      return (uint32_t(bytes[at]) << 24) | (uint32_t(bytes[at + 1]) << 16) |
             (uint32_t(bytes[at + 2]) << 8) | uint32_t(bytes[at + 3]);
    };
    const uint32_t pw = be32(16), ph = be32(20);
    MACRO_TRY(check_size(name, pw, ph, limits));
    // Raw (filtered, uncompressed) bytes from bit depth and colour type; deflate expands at most
    // ~1032x, so a file much smaller than raw / 1032 is truncated or lies about its size.
    const uint32_t depth = bytes[24], type = bytes[25];
    const uint32_t samples = type == 2 ? 3 : type == 4 ? 2 : type == 6 ? 4 : 1;
    const uint64_t raw =
        uint64_t(ph) * (1 + (uint64_t(pw) * samples * std::max(depth, 1u) + 7) / 8);
    if (raw > kMaxDeflateRatio * uint64_t(size) + 4096) {
      return Status::error(name + ": header says " + dims(pw, ph) + " but the file has only " +
                           std::to_string(size) + " bytes: truncated or corrupt");
    }
    MACRO_TRY(check_png_chunks(bytes, size, name));
    is_png = true;
  }
  int w = 0, h = 0, comp = 0;
  if (!stbi_info_from_memory(bytes, len, &w, &h, &comp)) {
    return Status::error(name + ": not a readable PNG/JPEG/BMP/TGA image (" +
                         std::string(stbi_failure_reason() ? stbi_failure_reason() : "unknown") +
                         ")");
  }
  MACRO_TRY(check_size(name, w, h, limits));
  // A header may lie about the size, and the decoder allocates from it. PNG was checked above
  // against its raw size; other formats get a loose bound (a flat JPEG compresses a few hundred
  // to one).
  if (!is_png &&
      uint64_t(w) * uint64_t(h) * uint64_t(comp) > kMaxOtherRatio * uint64_t(size) + 4096) {
    return Status::error(name + ": header says " + dims(w, h) + " but the file has only " +
                         std::to_string(size) + " bytes: truncated or corrupt");
  }
  if (comp < 1 || comp > 4) {
    return Status::error(name + ": expected 1 to 4 channels, found " + std::to_string(comp));
  }
  if (is_bmp(bytes, size)) {
    MACRO_TRY(check_bmp_size(bytes, size, name, w, h));
  } else if (!is_png && !is_jpeg(bytes, size)) {
    MACRO_TRY(check_tga_size(bytes, size, name, w, h));  // the only other format compiled in
  }
  Image out(w, h, 3);
  const size_t n = out.pixels();
  int dw = 0, dh = 0, dc = 0;
  if (stbi_is_16_bit_from_memory(bytes, len)) {
    stbi_us* px = stbi_load_16_from_memory(bytes, len, &dw, &dh, &dc, 0);
    if (!px) {
      return Status::error(name + ": cannot decode the 16-bit image (" +
                           std::string(stbi_failure_reason()) + "): truncated or corrupt");
    }
    if (dw != w || dh != h || dc != comp) {
      stbi_image_free(px);
      return Status::error(name + ": header and decoded image disagree");
    }
    const float s = 1.f / 65535.f;
    for (size_t p = 0; p < n; ++p) {
      const stbi_us* q = px + p * size_t(comp);
      for (int c = 0; c < 3; ++c) out.data[p * 3 + c] = float(q[comp < 3 ? 0 : c]) * s;
    }
    stbi_image_free(px);
  } else {
    stbi_uc* px = stbi_load_from_memory(bytes, len, &dw, &dh, &dc, 0);
    if (!px) {
      // stb tries each decoder in turn and reports the last one's complaint ("bad png sig" for a
      // broken JPEG), so the message names the format the header announced.
      const char* kind = is_png                 ? "PNG"
                         : is_jpeg(bytes, size) ? "JPEG"
                         : is_bmp(bytes, size)  ? "BMP"
                                                : "TGA";
      return Status::error(name + ": cannot decode the " + dims(w, h) + " " + kind + " image (" +
                           std::string(stbi_failure_reason()) + "): truncated or corrupt");
    }
    if (dw != w || dh != h || dc != comp) {
      stbi_image_free(px);
      return Status::error(name + ": header and decoded image disagree");
    }
    const float s = 1.f / 255.f;
    for (size_t p = 0; p < n; ++p) {
      const stbi_uc* q = px + p * size_t(comp);
      for (int c = 0; c < 3; ++c) out.data[p * 3 + c] = float(q[comp < 3 ? 0 : c]) * s;
    }
    stbi_image_free(px);
  }
  return out;
}

Result<Image> read_image(const std::string& path, const ImageLimits& limits) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(path, limits.max_file_bytes));
  return decode_image(bytes.data(), bytes.size(), path, limits);
}

// ---- PNG write
// -----------------------------------------------------------------------------------

uint8_t png_byte(float v) {
  if (!(v > 0.f)) return 0;  // also NaN
  if (v >= 1.f) return 255;
  return static_cast<uint8_t>(v * 255.f + 0.5f);
}

void round_to_png_levels(std::vector<float>* values) {
  for (float& v : *values) v = float(png_byte(v)) * (1.f / 255.f);
}

Image png_levels_image(const float* rgb, int w, int h) {
  Image img(w, h, 3);
  std::copy(rgb, rgb + img.data.size(), img.data.begin());
  round_to_png_levels(&img.data);
  return img;
}

namespace {
uint8_t to_u8(float v) {
  return png_byte(v);
}
void append_bytes(void* context, void* data, int size) {
  auto* out = static_cast<std::vector<uint8_t>*>(context);
  const auto* p = static_cast<const uint8_t*>(data);
  out->insert(out->end(), p, p + size);
}
}  // namespace

namespace {
// The 8-bit samples of `image` for an encoder named `format`, after checking channels and size.
Result<std::vector<uint8_t>> to_u8_samples(const Image& image, const char* format) {
  const int c = image.channels;
  if (c != 1 && c != 3 && c != 4) {
    return Status::error(std::string(format) + ": expected 1, 3 or 4 channels, found " +
                         std::to_string(c));
  }
  if (image.width <= 0 || image.height <= 0 || image.width > (1 << 24) ||
      image.height > (1 << 24)) {
    return Status::error(std::string(format) + ": expected a positive size below 16M, found " +
                         dims(image.width, image.height));
  }
  if (image.data.size() != image.pixels() * size_t(c)) {
    return Status::error(std::string(format) + ": image data holds " +
                         std::to_string(image.data.size()) + " values, expected " +
                         std::to_string(image.pixels() * size_t(c)));
  }
  std::vector<uint8_t> px(image.data.size());
  for (size_t k = 0; k < px.size(); ++k) px[k] = to_u8(image.data[k]);
  return px;
}
}  // namespace

Result<std::vector<uint8_t>> encode_png(const Image& image) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> px, to_u8_samples(image, "PNG"));
  std::vector<uint8_t> out;
  if (!stbi_write_png_to_func(append_bytes, &out, image.width, image.height, image.channels,
                              px.data(), image.width * image.channels)) {
    return Status::error("PNG: encoding failed");
  }
  return out;
}

Result<std::vector<uint8_t>> encode_jpeg(const Image& image, int quality) {
  if (quality < 1 || quality > 100) {
    return Status::error("JPEG: quality must be 1..100, found " + std::to_string(quality));
  }
  if (image.channels == 4) return Status::error("JPEG: has no alpha; expected 1 or 3 channels");
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> px, to_u8_samples(image, "JPEG"));
  std::vector<uint8_t> out;
  if (!stbi_write_jpg_to_func(append_bytes, &out, image.width, image.height, image.channels,
                              px.data(), quality)) {
    return Status::error("JPEG: encoding failed");
  }
  return out;
}

Status write_jpeg(const std::string& path, const Image& image, int quality) {
  auto bytes = encode_jpeg(image, quality);
  if (!bytes) return bytes.status().with_context(path);
  return write_file_atomic(path, bytes->data(), bytes->size());
}

Status write_png(const std::string& path, const Image& image) {
  auto bytes = encode_png(image);
  if (!bytes) return bytes.status().with_context(path);
  return write_file_atomic(path, bytes->data(), bytes->size());
}

// ---- EXR
// -----------------------------------------------------------------------------------------

Status write_exr(const std::string& path, int width, int height,
                 const std::vector<ExrChannel>& channels, ExrCompression compression) {
  if (width <= 0 || height <= 0) {
    return Status::error(path + ": EXR: expected a positive size, found " + dims(width, height));
  }
  if (channels.empty()) return Status::error(path + ": EXR: no channels to write");
  for (size_t k = 0; k < channels.size(); ++k) {
    if (channels[k].name.empty()) return Status::error(path + ": EXR: a channel has no name");
    if (!channels[k].data)
      return Status::error(path + ": EXR: channel '" + channels[k].name + "' has no data");
    for (size_t m = 0; m < k; ++m) {
      if (channels[m].name == channels[k].name) {
        return Status::error(path + ": EXR: channel '" + channels[k].name + "' given twice");
      }
    }
  }
  const std::string temp = temp_path_for(path);
  try {
    Imf::Header header(width, height);
    header.compression() = compression == ExrCompression::kZip   ? Imf::ZIP_COMPRESSION
                           : compression == ExrCompression::kPiz ? Imf::PIZ_COMPRESSION
                                                                 : Imf::NO_COMPRESSION;
    header.zipCompressionLevel() = kExrZipLevel;
    Imf::FrameBuffer fb;
    for (const ExrChannel& ch : channels) {
      header.channels().insert(ch.name, Imf::Channel(Imf::FLOAT));
      fb.insert(ch.name,
                Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(ch.data)),
                           sizeof(float), sizeof(float) * size_t(width)));
    }
    Imf::OutputFile file(temp.c_str(), header, 0);
    file.setFrameBuffer(fb);
    file.writePixels(height);
  } catch (const std::exception& e) {
    remove_temp_file(temp);
    return Status::error(path + ": cannot write EXR: " + e.what());
  }
  return commit_temp_file(temp, path);
}

const std::vector<float>* ExrImage::find(const std::string& name) const {
  for (size_t k = 0; k < names.size(); ++k) {
    if (names[k] == name) return &planes[k];
  }
  return nullptr;
}

Result<ExrImage> read_exr(const std::string& path, const ImageLimits& limits) {
  MACRO_ASSIGN_OR_RETURN(uint64_t bytes, file_size(path));
  if (bytes == 0) return Status::error(path + ": empty file, expected an EXR image");
  if (bytes > limits.max_file_bytes) {
    return Status::error(path + ": file of " + std::to_string(bytes) + " bytes exceeds the limit");
  }
  ExrImage out;
  try {
    Imf::InputFile file(path.c_str(), 0);
    const Imath::Box2i dw = file.header().dataWindow();
    const int64_t w = int64_t(dw.max.x) - dw.min.x + 1;
    const int64_t h = int64_t(dw.max.y) - dw.min.y + 1;
    MACRO_TRY(check_size(path, w, h, limits));
    size_t count = 0;
    const Imf::ChannelList& list = file.header().channels();
    for (auto it = list.begin(); it != list.end(); ++it) {
      if (it.channel().xSampling != 1 || it.channel().ySampling != 1) {
        return Status::error(path + ": channel '" + it.name() +
                             "' is subsampled, expected full-resolution channels");
      }
      ++count;
    }
    if (count == 0) return Status::error(path + ": EXR has no channels");
    if (count * uint64_t(w) * uint64_t(h) > 4 * limits.max_pixels) {
      return Status::error(path + ": " + std::to_string(count) + " channels of " + dims(w, h) +
                           " exceed the limit of " + std::to_string(4 * limits.max_pixels) +
                           " values");
    }
    // The header may lie; the planes are allocated from it. Compressed EXR stays within a few
    // thousand to one of its raw size, so a small file claiming a huge image is refused first.
    if (count * uint64_t(w) * uint64_t(h) * sizeof(float) > kMaxExrRatio * bytes + (1u << 20)) {
      return Status::error(path + ": header says " + std::to_string(count) + " channels of " +
                           dims(w, h) + " but the file has only " + std::to_string(bytes) +
                           " bytes: truncated or corrupt");
    }
    out.width = int(w);
    out.height = int(h);
    Imf::FrameBuffer fb;
    out.names.reserve(count);
    out.planes.reserve(count);
    const ptrdiff_t origin = ptrdiff_t(dw.min.x) + ptrdiff_t(dw.min.y) * ptrdiff_t(w);
    for (auto it = list.begin(); it != list.end(); ++it) {
      out.names.push_back(it.name());
      out.planes.emplace_back(size_t(w) * size_t(h), 0.f);
      char* base =
          reinterpret_cast<char*>(out.planes.back().data()) - origin * ptrdiff_t(sizeof(float));
      fb.insert(it.name(), Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * size_t(w)));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
  } catch (const std::exception& e) {
    return Status::error(path + ": cannot read EXR (truncated or corrupt?): " + e.what());
  }
  return out;
}

// ---- colour map
// ----------------------------------------------------------------------------------

void colormap(float value, float rgb[3]) {
  static constexpr float kStops[5][3] = {
      {0.05f, 0.03f, 0.22f},  // 0: far / empty
      {0.40f, 0.10f, 0.55f}, {0.85f, 0.30f, 0.30f},
      {0.98f, 0.65f, 0.15f}, {1.00f, 0.97f, 0.70f},  // 1: near
  };
  float v = std::isfinite(value) ? std::clamp(value, 0.f, 1.f) : 0.f;
  float x = v * 4.f;
  int k = std::min(3, int(x));
  float f = x - float(k);
  for (int c = 0; c < 3; ++c) rgb[c] = kStops[k][c] * (1.f - f) + kStops[k + 1][c] * f;
}

}  // namespace macro::gs
