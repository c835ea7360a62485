// antimatter15 .splat: no header, N = file size / 32, one 32-byte little-endian record per
// Gaussian:
//   bytes  0..11  position      3 x f32
//   bytes 12..23  scale         3 x f32, linear (already exponentiated)
//   bytes 24..27  R G B A       4 x u8: RGB = (0.5 + C0*f_dc)*255, A = opacity*255 (after sigmoid)
//   bytes 28..31  quaternion    4 x u8 in order w x y z: q/|q|*128 + 128
// No SH beyond DC. Decoded exactly as stored: f_dc = (c/255 - 0.5)/C0, q = (b - 128)/128.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "attention/runtime/progress.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs::formats {
namespace {

constexpr size_t kRecordBytes = 32;

uint8_t to_u8(float v) {  // round to nearest, clamp to [0, 255]; NaN -> 0
  const float r = std::round(v);
  return static_cast<uint8_t>(r >= 255.f ? 255.f : (r > 0.f ? r : 0.f));
}

}  // namespace

Result<GaussianCloud> decode_splat(const uint8_t* data, size_t size, const std::string& file,
                                   const LoadLimits& limits) {
  if (size == 0) return Status::error(file + ": empty file (a .splat needs 32 bytes per Gaussian)");
  if (size % kRecordBytes != 0)
    return Status::error(file + ": .splat size " + std::to_string(size) +
                         " bytes is not a multiple of the 32-byte record (truncated?)");
  const size_t N = size / kRecordBytes;
  if (N > limits.max_gaussians)
    return Status::error(file + ": " + std::to_string(N) + " Gaussians exceed the limit of " +
                         std::to_string(limits.max_gaussians) + " (--max-gaussians)");
  GaussianCloud cloud;
  cloud.resize(N, 0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (size_t i = 0; i < N; ++i) {
    const uint8_t* rec = data + i * kRecordBytes;
    float f[6];
    std::memcpy(f, rec, sizeof(f));
    bool finite = true;
    for (float v : f) finite &= std::isfinite(v);
    std::copy(f, f + 3, &cloud.position[i * 3]);
    std::copy(f + 3, f + 6, &cloud.scale[i * 3]);
    const uint8_t* rgba = rec + 24;
    for (int c = 0; c < 3; ++c)
      cloud.sh[i * 3 + static_cast<size_t>(c)] = (rgba[c] / 255.f - 0.5f) / kShC0;
    cloud.opacity[i] = finite ? rgba[3] / 255.f : nan;
    for (int a = 0; a < 4; ++a)
      cloud.rotation[i * 4 + static_cast<size_t>(a)] =
          (static_cast<float>(rec[28 + a]) - 128.f) / 128.f;
  }
  return cloud;
}

Result<std::vector<uint8_t>> encode_splat(const GaussianCloud& cloud, const std::string& file) {
  const size_t N = cloud.size();
  const size_t K = static_cast<size_t>(cloud.sh_coeffs());
  std::vector<uint8_t> out(N * kRecordBytes);
  for (size_t i = 0; i < N; ++i) {
    uint8_t* rec = out.data() + i * kRecordBytes;
    std::memcpy(rec, &cloud.position[i * 3], 12);
    std::memcpy(rec + 12, &cloud.scale[i * 3], 12);
    for (size_t c = 0; c < 3; ++c)
      rec[24 + c] = to_u8((0.5f + kShC0 * cloud.sh[i * K * 3 + c]) * 255.f);
    rec[27] = to_u8(cloud.opacity[i] * 255.f);
    const float* q = &cloud.rotation[i * 4];
    const float norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int a = 0; a < 4; ++a)
      rec[28 + a] = to_u8(norm > 0 ? q[a] / norm * 128.f + 128.f : (a == 0 ? 255.f : 128.f));
  }
  if (K > 1)
    log_info("save", file + ": .splat stores SH degree 0 only: dropped SH band" +
                         (cloud.sh_degree > 1 ? "s 1-" + std::to_string(cloud.sh_degree)
                                              : std::string(" 1")) +
                         ", " + std::to_string(K - 1) + " of " + std::to_string(K) +
                         " SH coefficients per colour channel (" + std::to_string((K - 1) * 3) +
                         " values per Gaussian); view-dependent colour is lost");
  return out;
}

}  // namespace macro::gs::formats
