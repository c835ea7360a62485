// Internal to gs/: the per-format decoders and encoders behind load_scene / save_scene
// (gs/formats/scene_io.h). Each works on bytes in memory and names `file` in its messages.
//
// Decoders fill an activated GaussianCloud (gs/gaussians.h) in the RDF frame. They do not drop or
// repair anything themselves: a Gaussian whose raw values are not finite gets a NaN opacity, and
// load_scene's sanitize pass (scene_io.cpp) drops it, repairs quaternions and scales, and counts.
// Encoders take a cloud that passed that pass (finite, unit quaternions, positive scales).
#pragma once

#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "attention/runtime/io/zip_writer.h"
#include "attention/runtime/status.h"
#include "gs/formats/ply_reader.h"
#include "gs/formats/scene_io.h"
#include "gs/gaussians.h"

namespace macro::gs::formats {

// Inria/gsplat .ply (also point-cloud .ply with red/green/blue and no f_dc).
Result<GaussianCloud> decode_ply(const ply::Header& header, const uint8_t* data, size_t size,
                                 const std::string& file, const LoadLimits& limits,
                                 LoadReport& report);
Result<std::vector<uint8_t>> encode_ply(const GaussianCloud& cloud, const std::string& file);
// The header of an Inria-layout binary .ply with N vertices and R higher SH coefficients per
// channel (x y z nx ny nz f_dc_0..2 f_rest_0..3R-1 opacity scale_0..2 rot_0..3, all float);
// `comment` (e.g. "SplatRenderMode: mip") goes in a comment line when not empty.
// With filter_3d a last property filter_3D (Mip-Splatting).
std::string inria_ply_header(size_t N, size_t R, const std::string& comment = "",
                             bool filter_3d = false);

// SuperSplat / splat-transform compressed .ply (elements chunk, vertex, optional sh).
bool is_compressed_ply(const ply::Header& header);
Result<GaussianCloud> decode_compressed_ply(const ply::Header& header, const uint8_t* data,
                                            size_t size, const std::string& file,
                                            const LoadLimits& limits, LoadReport& report);

// antimatter15 .splat: 32-byte records, no header.
Result<GaussianCloud> decode_splat(const uint8_t* data, size_t size, const std::string& file,
                                   const LoadLimits& limits);
Result<std::vector<uint8_t>> encode_splat(const GaussianCloud& cloud, const std::string& file);

// Niantic .spz: versions 2 and 3 (gzip), 4 (plain NGSP header, zstd streams).
bool is_gzip(const uint8_t* data, size_t size);
bool is_spz_v4(const uint8_t* data, size_t size);  // starts with the magic "NGSP"
Result<GaussianCloud> decode_spz(const uint8_t* data, size_t size, const std::string& file,
                                 const LoadLimits& limits, LoadReport& report);
Result<std::vector<uint8_t>> encode_spz(const GaussianCloud& cloud, const std::string& file,
                                        int version);

// PlayCanvas SOG (meta.json + WebP images). `read_member(name)` returns a member's bytes (a file
// of the folder, or a zip record); `file` names the folder or archive in messages.
using SogMemberReader = std::function<Result<std::vector<uint8_t>>(const std::string& name)>;
Result<GaussianCloud> decode_sog(const SogMemberReader& read_member, const std::string& file,
                                 const LoadLimits& limits);
// A .sog zip in memory.
Result<GaussianCloud> decode_sog_zip(const uint8_t* data, size_t size, const std::string& file,
                                     const LoadLimits& limits);
// A SOG folder (holding meta.json).
Result<GaussianCloud> decode_sog_folder(const std::string& folder, const LoadLimits& limits);
// SOG version 2 (format_sog_write.cpp): the WebP images, then meta.json last. `iterations`: the SH
// palette's k-means iterations. A Gaussian with a non-finite value or a scale <= 0 is an error
// naming it and the field.
Result<std::vector<ZipMember>> encode_sog_members(const GaussianCloud& cloud,
                                                  const std::string& file, int iterations);

// gsplat training checkpoint (torch zip with splats.means, .scales, .quats, .opacities, .sh0,
// .shN).
Result<GaussianCloud> decode_gsplat_checkpoint(const uint8_t* data, size_t size,
                                               const std::string& file, const LoadLimits& limits);

// Shared numeric helpers.
inline float sigmoid(float x) {
  return 1.f / (1.f + std::exp(-x));
}
// Degree whose (K-1) coefficients per channel fit in `per_channel` rest values (0..3).
inline int sh_degree_for_rest(size_t per_channel) {
  int d = 0;
  while (d < 3 && static_cast<size_t>((d + 2) * (d + 2) - 1) <= per_channel) ++d;
  return d;
}

}  // namespace macro::gs::formats
