// Niantic .spz, versions 2 and 3: a gzip stream holding a 16-byte little-endian header and then one
// array per attribute (all N values of one attribute before the next):
//   header    u32 magic 0x5053474e ("NGSP"), u32 version, u32 N, u8 shDegree (0-4),
//             u8 fractionalBits, u8 flags (bit 0: trained with antialiasing), u8 reserved
//   positions N x 3 x 24-bit signed fixed point, / 2^fractionalBits
//   alphas    N x u8, opacity (after sigmoid) * 255
//   colours   N x 3 x u8, f_dc = (c/255 - 0.5) / 0.15
//   scales    N x 3 x u8, log scale = s/16 - 10
//   rotations v2: N x 3 x u8, (x y z) = b/127.5 - 1, w = sqrt(1 - |xyz|^2)
//             v3: N x u32 LE, "smallest three" over (x y z w): bits 30-31 index of the largest,
//                 the other three from the lowest bits upward in reverse order (w, z, y, x), each
//                 9 bits magnitude (* sqrt(1/2) / 511) and 1 sign bit above it
//   sh        N x (K-1) x 3 x u8, coefficient-major with RGB fastest, (v - 128) / 128
// SPZ stores RUB (OpenGL axes); we load into RDF: y and z negate on positions, quaternion (x, y, z)
// conjugated by the 180-degree turn about x (w, x, -y, -z), and SH coefficients odd in y+z
// (rest index 0 1 3 6 8 10 11 13 for bands 1-3) negate.
//
// Bounds: the header's N is checked against LoadLimits and against what the compressed size can
// possibly expand to (deflate's ratio is at most 1032:1) before the payload is allocated; inflate
// then writes into exactly that buffer and stops there, so a gzip bomb costs nothing.
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "attention/runtime/progress.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs::formats {
namespace {

constexpr uint32_t kMagic = 0x5053474e;
constexpr size_t kHeaderBytes = 16;
constexpr uint64_t kMaxDeflateRatio = 1032;  // zlib's documented worst-case expansion
constexpr float kColourScale = 0.15f;
constexpr int kWriteFractionalBits = 12;
constexpr float kSqrtHalf = 0.70710678118654752f;
// Rest coefficients (0-based, bands 1..3) whose basis function is odd under (y, z) -> (-y, -z).
constexpr bool kFlipRest[15] = {true, true,  false, true, false, false, true, false,
                                true, false, true,  true, false, true,  false};

int rest_dim(int degree) {
  return (degree + 1) * (degree + 1) - 1;
}

uint32_t le32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
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

}  // namespace

bool is_gzip(const uint8_t* data, size_t size) {
  return size >= 2 && data[0] == 0x1f && data[1] == 0x8b;
}

Result<GaussianCloud> decode_spz(const uint8_t* data, size_t size, const std::string& file,
                                 const LoadLimits& limits, LoadReport& report) {
  if (size == 0) return Status::error(file + ": empty file");
  if (!is_gzip(data, size))
    return Status::error(file + ": .spz is not a gzip stream (expected bytes 1f 8b at the start)");
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
  const uint32_t magic = le32(hdr), version = le32(hdr + 4), n_points = le32(hdr + 8);
  const int degree = hdr[12], frac_bits = hdr[13], flags = hdr[14];
  char hex[16];
  std::snprintf(hex, sizeof(hex), "0x%08x", magic);
  if (magic != kMagic)
    return Status::error(file + ": .spz header: magic: expected 0x5053474e ('NGSP'), found " + hex);
  if (version != 2 && version != 3)
    return Status::error(file + ": .spz header: version: expected 2 or 3, found " +
                         std::to_string(version));
  if (n_points > limits.max_gaussians)
    return Status::error(file + ": .spz header: numPoints " + std::to_string(n_points) +
                         " exceeds the limit of " + std::to_string(limits.max_gaussians) +
                         " (--max-gaussians)");
  if (degree > 4)
    return Status::error(file + ": .spz header: shDegree: expected 0..4, found " +
                         std::to_string(degree));
  if (frac_bits > 24)
    return Status::error(file + ": .spz header: fractionalBits: expected 0..24, found " +
                         std::to_string(frac_bits));
  if (flags & 0x2)
    return Status::error(file + ": .spz header: flags bit 1 (extensions) is not supported");

  const size_t N = n_points;
  const int dim = rest_dim(degree);  // rest coefficients per channel in the file
  const size_t rot_bytes = version >= 3 ? 4 : 3;
  const uint64_t per_point = 9 + 1 + 3 + 3 + rot_bytes + 3 * static_cast<uint64_t>(dim);
  const uint64_t payload = per_point * N;
  if (payload + kHeaderBytes > static_cast<uint64_t>(size) * kMaxDeflateRatio + 1024)
    return Status::error(file + ": .spz header: numPoints " + std::to_string(N) + " needs " +
                         std::to_string(payload) + " bytes, more than the " + std::to_string(size) +
                         "-byte gzip stream can hold (corrupt header?)");
  std::vector<uint8_t> body(static_cast<size_t>(payload));
  const size_t have = inflate_into(zs, body.data(), body.size(), &ended, &zerr);
  if (!zerr.empty()) return Status::error(file + ": corrupt gzip stream: " + zerr);
  if (have < body.size())
    return Status::error(file + ": .spz data: " + std::to_string(N) + " points need " +
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

Result<std::vector<uint8_t>> encode_spz(const GaussianCloud& cloud, const std::string& file) {
  const size_t N = cloud.size();
  if (N > std::numeric_limits<uint32_t>::max())
    return Status::error(file + ": " + std::to_string(N) + " Gaussians do not fit a .spz");
  const size_t K = static_cast<size_t>(cloud.sh_coeffs());
  const size_t dim = K - 1;
  const float fixed = static_cast<float>(1 << kWriteFractionalBits);
  const float limit = static_cast<float>((1 << 23) - 1) / fixed;
  std::vector<uint8_t> raw(kHeaderBytes + N * (9 + 1 + 3 + 3 + 4 + dim * 3));
  uint8_t* h = raw.data();
  auto put32 = [](uint8_t* p, uint32_t v) {
    for (int b = 0; b < 4; ++b) p[b] = static_cast<uint8_t>(v >> (8 * b));
  };
  put32(h, kMagic);
  put32(h + 4, 3);
  put32(h + 8, static_cast<uint32_t>(N));
  h[12] = static_cast<uint8_t>(cloud.sh_degree);
  h[13] = kWriteFractionalBits;
  h[14] = cloud.trained_antialiased ? 1 : 0;
  h[15] = 0;
  uint8_t* pos = raw.data() + kHeaderBytes;
  uint8_t* alpha = pos + N * 9;
  uint8_t* colour = alpha + N;
  uint8_t* scale = colour + N * 3;
  uint8_t* rot = scale + N * 3;
  uint8_t* sh = rot + N * 4;
  const float flip3[3] = {1.f, -1.f, -1.f};  // RDF -> RUB
  for (size_t i = 0; i < N; ++i) {
    for (size_t a = 0; a < 3; ++a) {
      const float v = flip3[a] * cloud.position[i * 3 + a];
      if (!(std::abs(v) <= limit))
        return Status::error(file + ": Gaussian " + std::to_string(i) + " position " +
                             std::to_string(v) + " is outside the .spz range +-" +
                             std::to_string(limit));
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
    // wxyz (RDF) -> xyzw (RUB), normalised, then smallest three with the largest made positive.
    const float* q = &cloud.rotation[i * 4];
    float xyzw[4] = {q[1], -q[2], -q[3], q[0]};
    float norm =
        std::sqrt(xyzw[0] * xyzw[0] + xyzw[1] * xyzw[1] + xyzw[2] * xyzw[2] + xyzw[3] * xyzw[3]);
    if (!(norm > 0)) xyzw[0] = xyzw[1] = xyzw[2] = 0, xyzw[3] = norm = 1;
    int largest = 0;
    for (int c = 0; c < 4; ++c) {
      xyzw[c] /= norm;
      if (std::abs(xyzw[c]) > std::abs(xyzw[largest])) largest = c;
    }
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
    for (size_t k = 1; k < K; ++k) {
      const float sign = kFlipRest[k - 1] ? -1.f : 1.f;
      for (size_t c = 0; c < 3; ++c)
        sh[(i * dim + k - 1) * 3 + c] = to_u8(sign * cloud.sh[(i * K + k) * 3 + c] * 128.f + 128.f);
    }
  }

  // gzip with zlib (windowBits 16+15 selects the gzip wrapper).
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
    zs.next_in = raw.data() + in_done;
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

}  // namespace macro::gs::formats
