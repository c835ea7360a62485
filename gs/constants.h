// Tuning constants of the splat rasterizer, each named once with where it comes from.
// (docs/spec/gs-rasterizer.md §1 has the derivations; docs/rasterizer.md the conventions.)
#pragma once

namespace macro::gs::raster {

// Screen-space low-pass dilation added to both diagonal entries of the 2D covariance.
// gsplat `eps2d` = 0.3 (Inria uses the same 0.3 inline).
inline constexpr float kEps2d = 0.3f;
// Mip-Splatting 2D mip filter `kernel_size` (replaces eps2d in RasterMode::kMip).
inline constexpr float kMipKernelSize = 0.1f;
// Mip-Splatting: determinants clamped to at least this, coef = sqrt(det0/(det1+e)+e).
inline constexpr float kMipDetEps = 1e-6f;
// gsplat antialiased mode / Inria `antialiasing`: compensation floored at 0.005^2 inside the sqrt.
inline constexpr float kAaCompFloor = 0.005f * 0.005f;

// Per-pixel alpha clamp: Inria 0.99, gsplat MAX_ALPHA 0.99 (since Feb 2026).
inline constexpr float kMaxAlpha = 0.99f;
// Contributions below this alpha are skipped (both libraries: 1/255).
inline constexpr float kMinAlpha = 1.0f / 255.0f;
// A pixel stops before blending a Gaussian that would leave T*(1-alpha) <= this
// (gsplat: (1 - MAX_ALPHA)^2, "two opaque splats"; Inria 1e-4 with '<').
inline constexpr float kTransmittanceStop = 1e-4f;

// Depth culling of the mean in camera space (gsplat near_plane / far_plane defaults).
inline constexpr float kNearPlane = 0.01f;
inline constexpr float kFarPlane = 1e10f;
// gsplat perspective Jacobian clamp: |t.x/t.z| limited to the image side + 0.3 * tan(fov/2).
inline constexpr float kJacobianFovMargin = 0.3f;

// Tiles are kTile x kTile pixels (Inria BLOCK_X/Y, gsplat tile_size).
inline constexpr int kTile = 16;
inline constexpr int kTilePixels = kTile * kTile;

// Extent culling. A Gaussian reaches alpha >= kMinAlpha only where its squared Mahalanobis distance
// d^2 <= 2 ln(o / kMinAlpha) (o = opacity after AA/mip factors). The cull uses that radius^2
// enlarged by this relative margin plus kCutoffAbsMargin, so float round-off in the culling can
// only keep extra pixels (which the exact per-pixel test then skips), never drop a contributing
// one.
inline constexpr float kCutoffRelMargin = 1e-3f;
inline constexpr float kCutoffAbsMargin = 1e-3f;

// Spherical harmonics (Inria / gsplat sh_utils): rgb = sum basis*coeff + kShOffset, clamped >= 0.
inline constexpr float kShOffset = 0.5f;
inline constexpr int kMaxShDegree = 3;

// Blend works through a tile's depth-sorted list in batches of this many Gaussians, so a tile
// whose pixels all reached kTransmittanceStop stops early without preparing the rest.
inline constexpr int kBlendBatch = 128;
// Stable counting sort by tile runs over this many fixed chunks (independent of the thread count,
// so the result is identical for any number of threads).
inline constexpr int kBinChunks = 64;

}  // namespace macro::gs::raster
