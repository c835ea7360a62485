// SuperSplat / splat-transform "compressed.ply" (decode only).
//   element chunk   one row per 256 Gaussians (Gaussian i uses chunk i/256), float properties
//                   min_x min_y min_z max_x max_y max_z, min_scale_x..z max_scale_x..z (log space),
//                   optionally min_r min_g min_b max_r max_g max_b
//   element vertex  uint32 packed_position, packed_rotation, packed_scale, packed_color
//   element sh      optional, uchar f_rest_0..f_rest_{3R-1}, channel-major as in the Inria .ply
// Bit layout (bit 31 is the most significant):
//   position, scale  x = bits 21-31 (11), y = bits 11-20 (10), z = bits 0-10 (11); each u/(2^b-1)
//                    lerped between the chunk min and max; scale is then exp'ed
//   colour           R = bits 24-31, G = 16-23, B = 8-15, A = 0-7; RGB u/255 lerped between the
//                    chunk min/max colour when present (else used as is) and equal 0.5 + C0*f_dc;
//                    A/255 is the opacity after the sigmoid
//   rotation         bits 30-31 index of the largest component in (w, x, y, z) order; the other
//                    three in that order at bits 20-29, 10-19, 0-9, each (u/1023 - 0.5)*sqrt(2);
//                    the largest is sqrt(1 - sum of squares)
//   sh               f_rest = u*8/255 - 4 (the PlayCanvas engine's decode, CPU and shader; see
//                    docs/formats.md for splat-transform's midpoint variant)
#include <algorithm>
#include <cmath>

#include "gs/formats/scene_formats.h"

namespace macro::gs::formats {
namespace {

constexpr size_t kChunkSize = 256;
constexpr float kSqrt2 = 1.41421356237309515f;

float unorm(uint32_t v, int bits) {
  const uint32_t max = (1u << bits) - 1u;
  return static_cast<float>(v & max) / static_cast<float>(max);
}
float lerp(float a, float b, float t) {
  return a * (1.f - t) + b * t;
}

}  // namespace

bool is_compressed_ply(const ply::Header& header) {
  const ply::Element* vertex = header.find("vertex");
  return header.find("chunk") && vertex && vertex->find("packed_position") >= 0;
}

Result<GaussianCloud> decode_compressed_ply(const ply::Header& header, const uint8_t* data,
                                            size_t size, const std::string& file,
                                            const LoadLimits& limits, LoadReport& report) {
  const int ci = header.find_index("chunk"), vi = header.find_index("vertex");
  const int si = header.find_index("sh");
  if (ci < 0 || vi < 0)
    return Status::error(file + ": compressed PLY needs elements 'chunk' and 'vertex'");
  const ply::Element& chunk = header.elements[static_cast<size_t>(ci)];
  const ply::Element& vertex = header.elements[static_cast<size_t>(vi)];
  if (vertex.count > limits.max_gaussians)
    return Status::error(file + ": element 'vertex': " + std::to_string(vertex.count) +
                         " Gaussians exceed the limit of " + std::to_string(limits.max_gaussians) +
                         " (--max-gaussians)");
  const size_t N = static_cast<size_t>(vertex.count);
  if (chunk.count < (vertex.count + kChunkSize - 1) / kChunkSize)
    return Status::error(file + ": element 'chunk': " + std::to_string(vertex.count) +
                         " Gaussians need " +
                         std::to_string((vertex.count + kChunkSize - 1) / kChunkSize) +
                         " chunks of 256, found " + std::to_string(chunk.count));

  // Chunk columns by name: 12 required, 6 optional colour bounds.
  const char* kChunkNames[18] = {
      "min_x",       "min_y",       "min_z",       "max_x",       "max_y",       "max_z",
      "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z",
      "min_r",       "min_g",       "min_b",       "max_r",       "max_g",       "max_b"};
  int chunk_prop[18];
  int colour_props = 0;
  for (int k = 0; k < 18; ++k) {
    MACRO_ASSIGN_OR_RETURN(chunk_prop[k], ply::find_scalar(chunk, kChunkNames[k], file));
    if (k < 12 && chunk_prop[k] < 0)
      return Status::error(file + ": element 'chunk': missing property '" +
                           std::string(kChunkNames[k]) + "'");
    if (k >= 12 && chunk_prop[k] >= 0) ++colour_props;
  }
  if (colour_props != 0 && colour_props != 6)
    return Status::error(file + ": element 'chunk': expected all of min_r..max_b or none, found " +
                         std::to_string(colour_props) + " of 6");
  const bool chunk_colour = colour_props == 6;

  const char* kPacked[4] = {"packed_position", "packed_rotation", "packed_scale", "packed_color"};
  int packed[4];
  for (int k = 0; k < 4; ++k) {
    MACRO_ASSIGN_OR_RETURN(packed[k], ply::find_scalar(vertex, kPacked[k], file));
    if (packed[k] < 0)
      return Status::error(file + ": element 'vertex': missing property '" +
                           std::string(kPacked[k]) + "'");
    const ply::Type t = vertex.properties[static_cast<size_t>(packed[k])].type;
    if (t != ply::Type::kUint32 && t != ply::Type::kInt32)
      return Status::error(file + ": element 'vertex', property '" + std::string(kPacked[k]) +
                           "': expected uint, found " + ply::type_name(t));
  }
  if (vertex.has_lists() || chunk.has_lists())
    return Status::error(file +
                         ": compressed PLY elements 'chunk' and 'vertex' must not have "
                         "list properties");

  // Optional SH element.
  size_t per_channel = 0;
  std::vector<int> rest;
  const ply::Element* sh = si >= 0 ? &header.elements[static_cast<size_t>(si)] : nullptr;
  if (sh) {
    if (sh->count != vertex.count)
      return Status::error(file + ": element 'sh': expected " + std::to_string(vertex.count) +
                           " rows (one per vertex), found " + std::to_string(sh->count));
    while (true) {
      MACRO_ASSIGN_OR_RETURN(int i,
                             ply::find_scalar(*sh, "f_rest_" + std::to_string(rest.size()), file));
      if (i < 0) break;
      rest.push_back(i);
    }
    if (rest.size() % 3 != 0)
      return Status::error(file +
                           ": element 'sh': expected a multiple of 3 f_rest_* properties, "
                           "found " +
                           std::to_string(rest.size()));
    per_channel = rest.size() / 3;
  }
  const int degree = sh_degree_for_rest(per_channel);
  const size_t K = static_cast<size_t>((degree + 1) * (degree + 1));
  if (per_channel > K - 1) report.ignored_sh_coeffs = per_channel - (K - 1);

  MACRO_ASSIGN_OR_RETURN(auto elements, ply::locate_elements(header, data, size, file));
  const ply::ElementRows& chunk_rows = elements[static_cast<size_t>(ci)];
  const ply::ElementRows& vertex_rows = elements[static_cast<size_t>(vi)];

  GaussianCloud cloud;
  cloud.resize(N, degree);
  const size_t n_chunks = (N + kChunkSize - 1) / kChunkSize;
  float bounds[18] = {};
  for (size_t ch = 0; ch < n_chunks; ++ch) {
    for (int k = 0; k < 18; ++k)
      bounds[k] =
          chunk_prop[k] >= 0 ? static_cast<float>(chunk_rows.value(ch, chunk_prop[k])) : 0.f;
    const size_t end = std::min(N, (ch + 1) * kChunkSize);
    for (size_t i = ch * kChunkSize; i < end; ++i) {
      uint32_t v[4];
      for (int k = 0; k < 4; ++k)
        v[k] = static_cast<uint32_t>(static_cast<int64_t>(vertex_rows.value(i, packed[k])));
      const float tp[3] = {unorm(v[0] >> 21, 11), unorm(v[0] >> 11, 10), unorm(v[0], 11)};
      const float ts[3] = {unorm(v[2] >> 21, 11), unorm(v[2] >> 11, 10), unorm(v[2], 11)};
      bool finite = true;
      for (int a = 0; a < 3; ++a) {
        cloud.position[i * 3 + static_cast<size_t>(a)] = lerp(bounds[a], bounds[3 + a], tp[a]);
        cloud.scale[i * 3 + static_cast<size_t>(a)] =
            std::exp(lerp(bounds[6 + a], bounds[9 + a], ts[a]));
      }
      for (int k = 0; k < 12 + (chunk_colour ? 6 : 0); ++k) finite &= std::isfinite(bounds[k]);
      // Colour.
      for (int c = 0; c < 3; ++c) {
        float t = unorm(v[3] >> (24 - 8 * c), 8);
        if (chunk_colour) t = lerp(bounds[12 + c], bounds[15 + c], t);
        cloud.sh[i * K * 3 + static_cast<size_t>(c)] = (t - 0.5f) / kShC0;
      }
      cloud.opacity[i] = finite ? unorm(v[3], 8) : std::nanf("");
      // Rotation, smallest three in (w, x, y, z) order.
      const float abc[3] = {(unorm(v[1] >> 20, 10) - 0.5f) * kSqrt2,
                            (unorm(v[1] >> 10, 10) - 0.5f) * kSqrt2,
                            (unorm(v[1], 10) - 0.5f) * kSqrt2};
      const float m =
          std::sqrt(std::max(0.f, 1.f - (abc[0] * abc[0] + abc[1] * abc[1] + abc[2] * abc[2])));
      const int largest = static_cast<int>(v[1] >> 30);
      float* q = &cloud.rotation[i * 4];
      for (int a = 0, j = 0; a < 4; ++a) q[a] = a == largest ? m : abc[j++];
    }
  }
  if (sh && K > 1) {
    std::vector<int> columns;  // cloud order (k, c) from the file's c*R + (k-1)
    for (size_t k = 1; k < K; ++k)
      for (size_t c = 0; c < 3; ++c) columns.push_back(rest[c * per_channel + (k - 1)]);
    const ply::ElementRows& sh_rows = elements[static_cast<size_t>(si)];
    MACRO_TRY(sh_rows.for_each_block(columns, [&](size_t first, size_t n, const float* const* col) {
      for (size_t r = 0; r < n; ++r)
        for (size_t j = 0; j < columns.size(); ++j)
          cloud.sh[(first + r) * K * 3 + 3 + j] = col[j][r] * (8.f / 255.f) - 4.f;
    }));
  }
  return cloud;
}

}  // namespace macro::gs::formats
