// A Gaussian splat scene in memory, structure of arrays, values ACTIVATED (what the rasterizer uses).
//
// Legend: N Gaussians, K = (sh_degree+1)^2 SH coefficients per colour channel.
//   position  [N,3]  world space (x, y, z), the file's own frame (Inria/COLMAP: RDF)
//   scale     [N,3]  linear standard deviations (exp of the .ply's log scale), Mip 3D filter folded in
//   rotation  [N,4]  unit quaternion (w, x, y, z)
//   opacity   [N]    in [0, 1] (sigmoid of the .ply logit), Mip 3D filter folded in
//   sh        [N,K,3] SH coefficients, coefficient-major, RGB fastest; sh[n][0] is f_dc, so the DC
//                    colour is 0.5 + C0 * sh[n][0][c]. The .ply's channel-major f_rest is reordered.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace macro::gs {

struct GaussianCloud {
  int sh_degree = 0;                 // 0..3
  std::vector<float> position;       // [N,3]
  std::vector<float> scale;          // [N,3]
  std::vector<float> rotation;       // [N,4] w,x,y,z
  std::vector<float> opacity;        // [N]
  std::vector<float> sh;             // [N,K,3]

  // Provenance flags recorded by the loaders.
  bool mip_filter_3d_applied = false;  // a Mip-Splatting filter_3D property was folded in
  bool trained_antialiased = false;    // .spz flag bit 0 / PLY comment: trained with AA

  size_t size() const { return opacity.size(); }
  int sh_coeffs() const { return (sh_degree + 1) * (sh_degree + 1); }
  void resize(size_t n, int degree) {
    sh_degree = degree;
    position.assign(n * 3, 0.f);
    scale.assign(n * 3, 0.f);
    rotation.assign(n * 4, 0.f);
    opacity.assign(n, 0.f);
    sh.assign(n * static_cast<size_t>(sh_coeffs()) * 3, 0.f);
  }
};

// SH constants (Inria / gsplat, see docs/formats.md).
inline constexpr float kShC0 = 0.28209479177387814f;

}  // namespace macro::gs
