// The parameters of a splat scene BEFORE activation, exactly as an Inria/gsplat .ply stores them
// and as gsplat's trainer optimises them (its `splats` dict). The trainer (gs/train/) works on
// these; the renderer works on the activated GaussianCloud (gs/gaussians.h), see to_cloud().
//
// Legend: N Gaussians, K = (sh_degree+1)^2 SH coefficients per channel.
//   means      [N,3]      x y z, world space (the file's frame)
//   scales     [N,3]      log standard deviations (scale_0..2); activation exp
//   quats      [N,4]      raw, unnormalised w x y z (rot_0..3); activation q / |q|
//   opacities  [N]        logits (opacity); activation sigmoid
//   sh0        [N,1,3]    f_dc_0..2 (DC colour = 0.5 + C0 * sh0)
//   shN        [N,K-1,3]  coefficient-major, RGB fastest; the file's f_rest is channel-major:
//                         f_rest_{c*(K-1) + k-1} = shN[n][k-1][c]
//
// Reading is exact (no activation round trip), so a file written by write_splat_params reads back
// bit for bit. Unlike load_scene (gs/formats/scene_io.h), nothing is dropped or repaired: a
// non-finite value or a zero quaternion is an error naming the file, the vertex and the property,
// because the Gaussians' indices are the rows of every gradient and optimizer state.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/formats/scene_io.h"
#include "gs/gaussians.h"

namespace macro::gs {

struct SplatParams {
  int sh_degree = 0;             // 0..3
  std::vector<float> means;      // [N,3]
  std::vector<float> scales;     // [N,3] log
  std::vector<float> quats;      // [N,4] raw w,x,y,z
  std::vector<float> opacities;  // [N] logits
  std::vector<float> sh0;        // [N,1,3]
  std::vector<float> shN;        // [N,K-1,3]

  size_t size() const { return opacities.size(); }
  int sh_coeffs() const { return (sh_degree + 1) * (sh_degree + 1); }
  int sh_rest() const { return sh_coeffs() - 1; }  // K-1
  void resize(size_t n, int degree);
  // Every array has the size N implies, and sh_degree is 0..3; the message names the field.
  Status check_shapes() const;
};

// An Inria-layout .ply (any numeric type, either byte order or ascii; properties by name; extra
// properties ignored). Required: x y z, f_dc_0..2, opacity, scale_0..2, rot_0..3; f_rest_* as for
// load_scene (0, 9, 24 or 45 of them). A point cloud without f_dc is refused. A filter_3D property
// (Mip-Splatting's 3D filter, written by `macro train --mode mip`) goes to *filter_3d [N]; without
// filter_3d such a file is refused (its scales and opacities are the unfiltered ones, so using
// them without the filter would be another model). *filter_3d is cleared when the file has none.
Result<SplatParams> read_splat_params(const std::string& path, const LoadLimits& limits = {},
                                      std::vector<float>* filter_3d = nullptr);
Result<SplatParams> decode_splat_params(const uint8_t* data, size_t size, const std::string& name,
                                        const LoadLimits& limits = {},
                                        std::vector<float>* filter_3d = nullptr);

// The Inria layout, binary little-endian, 62 floats per vertex at degree 3 (normals zero),
// written atomically. The values go out as stored, with no activation. With filter_3d ([N]) a
// last property filter_3D, as Mip-Splatting writes it (readers that fold it, ours included, then
// render the filtered Gaussians).
Status write_splat_params(const SplatParams& params, const std::string& path,
                          const std::vector<float>* filter_3d = nullptr);
std::vector<uint8_t> encode_splat_params(const SplatParams& params,
                                         const std::vector<float>* filter_3d = nullptr);

// The activated cloud the rasterizer draws: exp(scales), quats / |q| (computed in double),
// sigmoid(opacities), sh = [sh0, shN]. Shapes must be consistent (check_shapes()).
GaussianCloud to_cloud(const SplatParams& params);
// The inverse, for a scene any loader read (.spz, .splat, SOG: only activated values): log
// scales, the unit quaternion, logit opacities, the SH split into sh0 and shN. A scale below 1e-12
// is taken as 1e-12 and an opacity outside [1e-6, 1 - 1e-6] is clamped into it (a quantised
// format can store 0 or 1 exactly), so every parameter is finite; to_cloud(from_cloud(c)) gives c
// back up to float rounding where nothing was clamped. A mip-filtered cloud is refused: its
// filter cannot be taken back out.
Result<SplatParams> from_cloud(const GaussianCloud& cloud, const std::string& name);

}  // namespace macro::gs
