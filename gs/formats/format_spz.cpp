// Niantic .spz, versions 2, 3 and 4. The attribute payload is the same in every version: one array
// per attribute (all N values of one attribute before the next):
//   positions N x 3 x 24-bit signed fixed point, / 2^fractionalBits
//   alphas    N x u8, opacity (after sigmoid) * 255
//   colours   N x 3 x u8, f_dc = (c/255 - 0.5) / 0.15
//   scales    N x 3 x u8, log scale = s/16 - 10
//   rotations v2: N x 3 x u8, (x y z) = b/127.5 - 1, w = sqrt(1 - |xyz|^2)
//             v3, v4: N x u32 LE, "smallest three" over (x y z w): bits 30-31 index of the
//                 largest, the other three from the lowest bits upward in reverse order (w, z, y,
//                 x), each 9 bits magnitude (* sqrt(1/2) / 511) and 1 sign bit above it
//   sh        N x (K-1) x 3 x u8, coefficient-major with RGB fastest, (v - 128) / 128
// Containers:
//   v2, v3: one gzip stream holding a 16-byte header (u32 magic 0x5053474e "NGSP", u32 version,
//           u32 N, u8 shDegree 0-4, u8 fractionalBits, u8 flags (bit 0 antialiased, bit 1
//           extensions), u8 reserved) and the arrays above back to back.
//   v4:     a plain 32-byte header (magic, u32 version 4, u32 N, u8 shDegree, u8 fractionalBits,
//           u8 flags, u8 numStreams, u32 tocByteOffset, 12 reserved bytes), extension records up
//           to tocByteOffset (skipped), a table of numStreams x (u64 compressed, u64 uncompressed)
//           sizes, then one zstd frame per attribute array in the order above.
// SPZ stores RUB (OpenGL axes); we load into RDF: y and z negate on positions, quaternion (x, y, z)
// conjugated by the 180-degree turn about x (w, x, -y, -z), and SH coefficients odd in y+z
// (rest index 0 1 3 6 8 10 11 13 for bands 1-3) negate.
//
// Bounds: the header's N is checked against LoadLimits and against what the compressed bytes can
// possibly expand to (deflate's ratio is at most 1032:1, zstd's 32768:1) before anything is
// allocated; decompression writes into exactly the expected buffer and stops there, so a bomb
// costs nothing.
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include "attention/runtime/io/zip_reader.h"
#include "attention/runtime/progress.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs::formats {
namespace {

constexpr uint32_t kMagic = 0x5053474e;
constexpr size_t kHeaderBytes = 16;
constexpr size_t kHeaderBytesV4 = 32;
constexpr uint64_t kMaxZstdRatio = 32768;  // an RLE block: 4 bytes for up to 128 KiB
constexpr float kColourScale = 0.15f;
constexpr int kWriteFractionalBits = 12;
constexpr float kSqrtHalf = 0.70710678118654752f;
// Rest coefficients (0-based, bands 1..3) whose basis function is odd under (y, z) -> (-y, -z).
constexpr bool kFlipRest[15] = {true, true,  false, true, false, false, true, false,
                                true, false, true,  true, false, true,  false};

int rest_dim(int degree) {
  return (degree + 1) * (degree + 1) - 1;
}

uint8_t to_u8(float v) {
  const float r = std::round(v);
  return static_cast<uint8_t>(r >= 255.f ? 255.f : (r > 0.f ? r : 0.f));
}

// Inflates into [dst, dst+n); returns the bytes produced. *error is set on a corrupt stream.
size_t inflate_into(z_stream& zs, uint8_t* dst, size_t n, bool* ended, std::string* error) {
  size_t produced = 0;
  while (produced < n && !*ended) {
    zs.next_out = dst + produced;
    const size_t chunk = std::min<size_t>(n - produced, 1u << 30);
    zs.avail_out = static_cast<uInt>(chunk);
    const int rc = inflate(&zs, Z_NO_FLUSH);
    produced += chunk - zs.avail_out;
    if (rc == Z_STREAM_END) {
      *ended = true;
    } else if (rc == Z_BUF_ERROR) {
      break;  // input exhausted: truncated
    } else if (rc != Z_OK) {
      *error = zs.msg ? zs.msg : "zlib error " + std::to_string(rc);
      break;
    }
  }
  return produced;
}

struct SpzHeader {
  uint32_t version = 0, n_points = 0;
  int degree = 0, frac_bits = 0, flags = 0;
};

// Bytes of each attribute array (positions, alphas, colours, scales, rotations, SH).
std::array<uint64_t, 6> array_bytes(uint64_t N, uint32_t version, int degree) {
  const uint64_t rot = version >= 3 ? 4 : 3;
  return {N * 9, N, N * 3, N * 3, N * rot, N * 3 * static_cast<uint64_t>(rest_dim(degree))};
}

constexpr const char* kArrayNames[6] = {"positions", "alphas",    "colours",
                                        "scales",    "rotations", "sh"};

// Checks the fields every version shares; `what` prefixes the messages.
Status check_header(const SpzHeader& h, const std::string& what, const LoadLimits& limits) {
  if (h.n_points > limits.max_gaussians)
    return Status::error(what + ": numPoints " + std::to_string(h.n_points) +
                         " exceeds the limit of " + std::to_string(limits.max_gaussians) +
                         " (--max-gaussians)");
  if (h.degree > 4)
    return Status::error(what + ": shDegree: expected 0..4, found " + std::to_string(h.degree));
  if (h.frac_bits > 24)
    return Status::error(what + ": fractionalBits: expected 0..24, found " +
                         std::to_string(h.frac_bits));
  return Status::ok();
}

Status unsupported_version(const std::string& what, uint32_t version, const char* container) {
  return Status::error(what + ": unsupported .spz version " + std::to_string(version) + " in a " +
                       container + " (this reader supports versions 2 and 3 in gzip, 4 with a " +
                       "plain NGSP header)");
}

// Versions 2 and 3: the whole file is one gzip stream. Fills the header and the payload.
Status inflate_gzip_spz(const uint8_t* data, size_t size, const std::string& file,
                        const LoadLimits& limits, SpzHeader& h, std::vector<uint8_t>& body) {
  z_stream zs{};
  zs.next_in = const_cast<Bytef*>(data);
  zs.avail_in = static_cast<uInt>(std::min<size_t>(size, std::numeric_limits<uInt>::max()));
  if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK)
    return Status::error(file + ": cannot start gzip decoding");
  struct Guard {
    z_stream* z;
    ~Guard() { inflateEnd(z); }
  } guard{&zs};

  bool ended = false;
  std::string zerr;
  uint8_t hdr[kHeaderBytes];
  const size_t got = inflate_into(zs, hdr, kHeaderBytes, &ended, &zerr);
  if (!zerr.empty()) return Status::error(file + ": corrupt gzip stream: " + zerr);
  if (got < kHeaderBytes)
    return Status::error(file + ": .spz header: expected 16 bytes, the stream holds " +
                         std::to_string(got) + " (truncated?)");
  const uint32_t magic = le32(hdr);
  h.version = le32(hdr + 4);
  h.n_points = le32(hdr + 8);
  h.degree = hdr[12], h.frac_bits = hdr[13], h.flags = hdr[14];
  char hex[16];
  std::snprintf(hex, sizeof(hex), "0x%08x", magic);
  if (magic != kMagic)
    return Status::error(file + ": .spz header: magic: expected 0x5053474e ('NGSP'), found " + hex);
  if (h.version != 2 && h.version != 3)
    return unsupported_version(file + ": .spz header", h.version, "gzip stream");
  MACRO_TRY(check_header(h, file + ": .spz header", limits));
  if (h.flags & 0x2)
    return Status::error(file + ": .spz header: flags bit 1 (extensions) is not supported in " +
                         "version " + std::to_string(h.version));

  const auto sizes = array_bytes(h.n_points, h.version, h.degree);
  uint64_t payload = 0;
  for (uint64_t b : sizes) payload += b;
  if (payload + kHeaderBytes > static_cast<uint64_t>(size) * kMaxDeflateRatio + 1024)
    return Status::error(file + ": .spz header: numPoints " + std::to_string(h.n_points) +
                         " needs " + std::to_string(payload) + " bytes, more than the " +
                         std::to_string(size) + "-byte gzip stream can hold (corrupt header?)");
  body.resize(static_cast<size_t>(payload));
  const size_t have = inflate_into(zs, body.data(), body.size(), &ended, &zerr);
  if (!zerr.empty()) return Status::error(file + ": corrupt gzip stream: " + zerr);
  if (have < body.size())
    return Status::error(file + ": .spz data: " + std::to_string(h.n_points) + " points need " +
                         std::to_string(body.size()) + " bytes after the header, the stream " +
                         "holds " + std::to_string(have) + " (truncated?)");
  // The payload is complete; the gzip trailer (CRC-32 and length) must follow, so a file cut just
  // before its end, or with a damaged data check, is refused rather than half trusted. Bytes past
  // the payload are read into a scratch buffer and ignored (bounded by the deflate ratio).
  uint8_t scratch[4096];
  while (!ended && zerr.empty()) {
    const size_t extra = inflate_into(zs, scratch, sizeof scratch, &ended, &zerr);
    if (extra == 0 && !ended) break;
  }
  if (!zerr.empty()) return Status::error(file + ": corrupt gzip stream: " + zerr);
  if (!ended)
    return Status::error(file + ": gzip stream: ends before its trailer (CRC-32 and length), " +
                         "after the .spz data (truncated?)");
  return Status::ok();
}

// Version 4: plain header, table of contents, one zstd frame per attribute array.
Status read_v4_spz(const uint8_t* data, size_t size, const std::string& file,
                   const LoadLimits& limits, SpzHeader& h, std::vector<uint8_t>& body) {
  const std::string what = file + ": .spz v4 header";
  if (size < kHeaderBytesV4)
    return Status::error(what + ": expected 32 bytes, the file holds " + std::to_string(size) +
                         " (truncated?)");
  h.version = le32(data + 4);
  h.n_points = le32(data + 8);
  h.degree = data[12], h.frac_bits = data[13], h.flags = data[14];
  const int n_streams = data[15];
  const uint32_t toc_offset = le32(data + 16);
  if (h.version != 4) return unsupported_version(what, h.version, "plain NGSP header");
  MACRO_TRY(check_header(h, what, limits));
  if (toc_offset < kHeaderBytesV4 || toc_offset > size)
    return Status::error(what + ": tocByteOffset: expected 32.." + std::to_string(size) +
                         " (inside the file), found " + std::to_string(toc_offset));
  if (toc_offset > kHeaderBytesV4 && !(h.flags & 0x2))
    return Status::error(what + ": tocByteOffset " + std::to_string(toc_offset) +
                         " leaves room for extension records but flags bit 1 is not set");
  if (toc_offset > kHeaderBytesV4)
    log_info("load", file + ": .spz extension records (" +
                         std::to_string(toc_offset - kHeaderBytesV4) + " bytes) are skipped");
  const auto sizes = array_bytes(h.n_points, h.version, h.degree);
  const int needed = rest_dim(h.degree) > 0 ? 6 : 5;
  if (n_streams < needed || n_streams > 6)
    return Status::error(what + ": numStreams: expected " + (needed == 6 ? "6" : "5 or 6") +
                         " (positions, alphas, colours, scales, rotations, sh), found " +
                         std::to_string(n_streams));
  const uint64_t toc_bytes = uint64_t(n_streams) * 16;
  if (toc_offset + toc_bytes > size)
    return Status::error(file + ": .spz v4 table of contents: " + std::to_string(toc_bytes) +
                         " bytes at offset " + std::to_string(toc_offset) + ", the file holds " +
                         std::to_string(size) + " (truncated?)");
  uint64_t payload = 0, stream_at = toc_offset + toc_bytes;
  std::array<uint64_t, 6> comp{}, offsets{};
  for (int s = 0; s < n_streams; ++s) {
    comp[s] = le64(data + toc_offset + 16 * s);
    const uint64_t raw = le64(data + toc_offset + 16 * s + 8);
    const std::string name =
        std::string("stream ") + std::to_string(s) + " (" + kArrayNames[s] + ")";
    if (raw != sizes[s])
      return Status::error(file + ": .spz v4 " + name + ": uncompressed size: expected " +
                           std::to_string(sizes[s]) + " bytes for " + std::to_string(h.n_points) +
                           " points, found " + std::to_string(raw));
    if (comp[s] > size - stream_at)
      return Status::error(file + ": .spz v4 " + name + ": " + std::to_string(comp[s]) +
                           " compressed bytes at offset " + std::to_string(stream_at) +
                           ", the file holds " + std::to_string(size) + " (truncated?)");
    if (raw > comp[s] * kMaxZstdRatio + 1024)
      return Status::error(file + ": .spz v4 " + name + ": " + std::to_string(raw) +
                           " bytes cannot come from " + std::to_string(comp[s]) +
                           " compressed bytes (corrupt header?)");
    offsets[s] = stream_at;
    stream_at += comp[s];
    payload += raw;
  }
  body.resize(static_cast<size_t>(payload));
  uint8_t* dst = body.data();
  for (int s = 0; s < n_streams; ++s) {
    const size_t r = ZSTD_decompress(dst, sizes[s], data + offsets[s], comp[s]);
    if (ZSTD_isError(r) || r != sizes[s])
      return Status::error(file + ": .spz v4 stream " + std::to_string(s) + " (" + kArrayNames[s] +
                           "): corrupt zstd frame: " +
                           (ZSTD_isError(r) ? std::string(ZSTD_getErrorName(r))
                                            : "produced " + std::to_string(r) +
                                                  " bytes, expected " + std::to_string(sizes[s])));
    dst += sizes[s];
  }
  return Status::ok();
}

}  // namespace

bool is_gzip(const uint8_t* data, size_t size) {
  return size >= 2 && data[0] == 0x1f && data[1] == 0x8b;
}

bool is_spz_v4(const uint8_t* data, size_t size) {
  return size >= 4 && le32(data) == kMagic;
}

Result<GaussianCloud> decode_spz(const uint8_t* data, size_t size, const std::string& file,
                                 const LoadLimits& limits, LoadReport& report) {
  if (size == 0) return Status::error(file + ": empty file");
  SpzHeader h;
  std::vector<uint8_t> body;
  if (is_spz_v4(data, size)) {
    MACRO_TRY(read_v4_spz(data, size, file, limits, h, body));
  } else if (is_gzip(data, size)) {
    MACRO_TRY(inflate_gzip_spz(data, size, file, limits, h, body));
  } else {
    char hex[16];
    std::snprintf(hex, sizeof(hex), "%02x %02x", data[0], size > 1 ? data[1] : 0);
    return Status::error(file +
                         ": not a .spz file: expected a gzip stream (bytes 1f 8b, versions " +
                         "2 and 3) or a plain 'NGSP' header (version 4), found bytes " + hex);
  }
  const size_t N = h.n_points;
  const int degree = h.degree, frac_bits = h.frac_bits, flags = h.flags;
  const uint32_t version = h.version;
  const int dim = rest_dim(degree);  // rest coefficients per channel in the file
  const size_t rot_bytes = version >= 3 ? 4 : 3;

  const int out_degree = std::min(degree, 3);
  if (degree > 3) {
    report.ignored_sh_coeffs = static_cast<size_t>(dim - rest_dim(3));
    log_info("load", file + ": SH degree 4 in .spz; loading degree 3");
  }
  GaussianCloud cloud;
  cloud.resize(N, out_degree);
  cloud.trained_antialiased = (flags & 0x1) != 0;
  const size_t K = static_cast<size_t>(cloud.sh_coeffs());
  const uint8_t* pos = body.data();
  const uint8_t* alpha = pos + N * 9;
  const uint8_t* colour = alpha + N;
  const uint8_t* scale = colour + N * 3;
  const uint8_t* rot = scale + N * 3;
  const uint8_t* sh = rot + N * rot_bytes;
  const float pos_scale = 1.f / static_cast<float>(1 << frac_bits);
  const float flip3[3] = {1.f, -1.f, -1.f};  // RUB -> RDF

  for (size_t i = 0; i < N; ++i) {
    for (size_t a = 0; a < 3; ++a) {
      const uint8_t* p = pos + (i * 3 + a) * 3;
      int32_t v = int32_t(uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16);
      if (v & 0x800000) v -= 0x1000000;  // sign-extend 24 bits
      cloud.position[i * 3 + a] = flip3[a] * static_cast<float>(v) * pos_scale;
      cloud.scale[i * 3 + a] = std::exp(scale[i * 3 + a] / 16.f - 10.f);
      cloud.sh[i * K * 3 + a] = (colour[i * 3 + a] / 255.f - 0.5f) / kColourScale;
    }
    cloud.opacity[i] = alpha[i] / 255.f;
    float xyzw[4];
    if (version >= 3) {
      uint32_t bits = le32(rot + i * 4);
      const int largest = static_cast<int>(bits >> 30);
      float sum = 0;
      for (int c = 3; c >= 0; --c) {
        if (c == largest) continue;
        const float mag = static_cast<float>(bits & 0x1ffu) * (kSqrtHalf / 511.f);
        xyzw[c] = (bits & 0x200u) ? -mag : mag;
        sum += xyzw[c] * xyzw[c];
        bits >>= 10;
      }
      xyzw[largest] = std::sqrt(std::max(0.f, 1.f - sum));
    } else {
      const uint8_t* r = rot + i * 3;
      float sum = 0;
      for (int c = 0; c < 3; ++c) {
        xyzw[c] = r[c] / 127.5f - 1.f;
        sum += xyzw[c] * xyzw[c];
      }
      xyzw[3] = std::sqrt(std::max(0.f, 1.f - sum));
    }
    float* q = &cloud.rotation[i * 4];
    q[0] = xyzw[3];
    q[1] = xyzw[0];
    q[2] = -xyzw[1];
    q[3] = -xyzw[2];
    const uint8_t* s = sh + i * static_cast<size_t>(dim) * 3;
    for (size_t k = 1; k < K; ++k) {
      const float sign = kFlipRest[k - 1] ? -1.f : 1.f;
      for (size_t c = 0; c < 3; ++c)
        cloud.sh[(i * K + k) * 3 + c] = sign * (s[(k - 1) * 3 + c] - 128.f) / 128.f;
    }
  }
  return cloud;
}

namespace {

// Version 4: the 32-byte header, the table of contents and one zstd frame per array. raw holds the
// 16-byte legacy header (magic, version, N, degree, fractional bits, flags) and the arrays.
Result<std::vector<uint8_t>> zstd_container(const std::vector<uint8_t>& raw,
                                            const std::array<uint64_t, 6>& sizes,
                                            const std::string& file) {
  std::vector<uint8_t> out(kHeaderBytesV4 + 6 * 16, 0);
  std::copy_n(raw.data(), 15, out.data());  // magic .. flags
  out[15] = 6;                              // numStreams
  out[16] = static_cast<uint8_t>(kHeaderBytesV4);
  const uint8_t* src = raw.data() + kHeaderBytes;
  for (int s = 0; s < 6; ++s) {
    const size_t bound = ZSTD_compressBound(sizes[s]);
    const size_t at = out.size();
    out.resize(at + bound);
    const size_t n = ZSTD_compress(out.data() + at, bound, src, sizes[s], 3);
    if (ZSTD_isError(n))
      return Status::error(file + ": zstd encoding of " + kArrayNames[s] +
                           " failed: " + ZSTD_getErrorName(n));
    out.resize(at + n);
    for (int b = 0; b < 8; ++b) {
      out[kHeaderBytesV4 + 16 * s + b] = static_cast<uint8_t>(uint64_t(n) >> (8 * b));
      out[kHeaderBytesV4 + 16 * s + 8 + b] = static_cast<uint8_t>(sizes[s] >> (8 * b));
    }
    src += sizes[s];
  }
  return out;
}

// Versions 2 and 3: gzip of raw with zlib (windowBits 16+15 selects the gzip wrapper).
Result<std::vector<uint8_t>> gzip_bytes(const std::vector<uint8_t>& raw, const std::string& file) {
  z_stream zs{};
  if (deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) !=
      Z_OK)
    return Status::error(file + ": cannot start gzip encoding");
  std::vector<uint8_t> out(deflateBound(&zs, static_cast<uLong>(raw.size())) + 64);
  constexpr size_t kChunk = 1u << 30;  // zlib counts in 32-bit uInt
  size_t in_done = 0, written = 0;
  int rc = Z_OK;
  while (rc == Z_OK) {
    const size_t in_chunk = std::min(kChunk, raw.size() - in_done);
    const size_t out_chunk = std::min(kChunk, out.size() - written);
    zs.next_in = const_cast<Bytef*>(raw.data()) + in_done;
    zs.avail_in = static_cast<uInt>(in_chunk);
    zs.next_out = out.data() + written;
    zs.avail_out = static_cast<uInt>(out_chunk);
    const bool last = in_done + in_chunk == raw.size();
    rc = deflate(&zs, last ? Z_FINISH : Z_NO_FLUSH);
    in_done += in_chunk - zs.avail_in;
    written += out_chunk - zs.avail_out;
  }
  deflateEnd(&zs);
  if (rc != Z_STREAM_END) return Status::error(file + ": gzip encoding failed");
  out.resize(written);
  return out;
}

}  // namespace

Result<std::vector<uint8_t>> encode_spz(const GaussianCloud& cloud, const std::string& file,
                                        int version) {
  if (version < 2 || version > 4)
    return Status::error(file + ": .spz version: expected 2, 3 or 4, found " +
                         std::to_string(version));
  const size_t N = cloud.size();
  if (N > std::numeric_limits<uint32_t>::max())
    return Status::error(file + ": " + std::to_string(N) + " Gaussians do not fit a .spz");
  const size_t K = static_cast<size_t>(cloud.sh_coeffs());
  const size_t dim = K - 1;
  // Fixed point: 12 fractional bits (the reference's choice) while every coordinate fits the
  // 24-bit range (+-2048); fewer bits for a larger scene, down to 0 (+-8388607).
  float max_abs = 0.f;
  for (size_t i = 0; i < N * 3; ++i) {
    const float a = std::abs(cloud.position[i]);
    if (!(a <= std::numeric_limits<float>::max()))
      return Status::error(file + ": Gaussian " + std::to_string(i / 3) +
                           " has a non-finite position");
    max_abs = std::max(max_abs, a);
  }
  const float max_fixed = static_cast<float>((1 << 23) - 1);
  int frac_bits = kWriteFractionalBits;
  while (frac_bits > 0 && std::round(max_abs * static_cast<float>(1 << frac_bits)) > max_fixed)
    --frac_bits;
  if (std::round(max_abs * static_cast<float>(1 << frac_bits)) > max_fixed)
    return Status::error(file + ": positions reach " + std::to_string(max_abs) +
                         ", outside the largest .spz range +-" + std::to_string(max_fixed) +
                         " (24-bit fixed point with 0 fractional bits)");
  if (frac_bits < kWriteFractionalBits)
    log_info("save", file + ": positions reach " + std::to_string(max_abs) +
                         ", beyond +-2048: writing " + std::to_string(frac_bits) +
                         " fractional bits (position step " +
                         std::to_string(1.0 / double(1 << frac_bits)) + ") instead of 12");
  const float fixed = static_cast<float>(1 << frac_bits);
  const uint32_t uversion = static_cast<uint32_t>(version);
  const auto sizes = array_bytes(N, uversion, cloud.sh_degree);
  uint64_t payload = 0;
  for (uint64_t b : sizes) payload += b;
  std::vector<uint8_t> raw(kHeaderBytes + static_cast<size_t>(payload));
  uint8_t* h = raw.data();
  auto put32 = [](uint8_t* p, uint32_t v) {
    for (int b = 0; b < 4; ++b) p[b] = static_cast<uint8_t>(v >> (8 * b));
  };
  put32(h, kMagic);
  put32(h + 4, uversion);
  put32(h + 8, static_cast<uint32_t>(N));
  h[12] = static_cast<uint8_t>(cloud.sh_degree);
  h[13] = static_cast<uint8_t>(frac_bits);
  h[14] = cloud.trained_antialiased ? 1 : 0;
  h[15] = 0;
  uint8_t* pos = raw.data() + kHeaderBytes;
  uint8_t* alpha = pos + sizes[0];
  uint8_t* colour = alpha + sizes[1];
  uint8_t* scale = colour + sizes[2];
  uint8_t* rot = scale + sizes[3];
  uint8_t* sh = rot + sizes[4];
  const float flip3[3] = {1.f, -1.f, -1.f};  // RDF -> RUB
  for (size_t i = 0; i < N; ++i) {
    for (size_t a = 0; a < 3; ++a) {
      const float v = flip3[a] * cloud.position[i * 3 + a];
      const int32_t f = static_cast<int32_t>(std::lround(v * fixed));
      uint8_t* p = pos + (i * 3 + a) * 3;
      p[0] = static_cast<uint8_t>(f);
      p[1] = static_cast<uint8_t>(f >> 8);
      p[2] = static_cast<uint8_t>(f >> 16);
      const float s = std::max(cloud.scale[i * 3 + a], kMinScale);
      scale[i * 3 + a] = to_u8((std::log(s) + 10.f) * 16.f);
      colour[i * 3 + a] = to_u8(cloud.sh[i * K * 3 + a] * (kColourScale * 255.f) + 127.5f);
    }
    alpha[i] = to_u8(cloud.opacity[i] * 255.f);
    // wxyz (RDF) -> xyzw (RUB), normalised.
    const float* q = &cloud.rotation[i * 4];
    float xyzw[4] = {q[1], -q[2], -q[3], q[0]};
    float norm =
        std::sqrt(xyzw[0] * xyzw[0] + xyzw[1] * xyzw[1] + xyzw[2] * xyzw[2] + xyzw[3] * xyzw[3]);
    if (!(norm > 0)) xyzw[0] = xyzw[1] = xyzw[2] = 0, xyzw[3] = norm = 1;
    for (float& c : xyzw) c /= norm;
    if (version == 2) {
      // (x, y, z) of the quaternion with w >= 0.
      const float sign = xyzw[3] < 0 ? -1.f : 1.f;
      for (int c = 0; c < 3; ++c) rot[i * 3 + c] = to_u8((sign * xyzw[c] + 1.f) * 127.5f);
    } else {
      // Smallest three with the largest made positive.
      int largest = 0;
      for (int c = 0; c < 4; ++c)
        if (std::abs(xyzw[c]) > std::abs(xyzw[largest])) largest = c;
      const bool negate = xyzw[largest] < 0;
      uint32_t bits = static_cast<uint32_t>(largest);
      for (int c = 0; c < 4; ++c) {
        if (c == largest) continue;
        const float v = negate ? -xyzw[c] : xyzw[c];
        uint32_t mag =
            static_cast<uint32_t>(std::min(511.f, std::round(std::abs(v) / kSqrtHalf * 511.f)));
        bits = bits << 10 | (v < 0 ? 0x200u : 0u) | mag;
      }
      put32(rot + i * 4, bits);
    }
    for (size_t k = 1; k < K; ++k) {
      const float sign = kFlipRest[k - 1] ? -1.f : 1.f;
      for (size_t c = 0; c < 3; ++c)
        sh[(i * dim + k - 1) * 3 + c] = to_u8(sign * cloud.sh[(i * K + k) * 3 + c] * 128.f + 128.f);
    }
  }
  if (version == 4) return zstd_container(raw, sizes, file);
  return gzip_bytes(raw, file);
}

}  // namespace macro::gs::formats
