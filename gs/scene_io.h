// Splat scene files: Inria/gsplat .ply (binary LE/BE, ascii), SuperSplat compressed .ply, .splat,
// .spz (v2, v3). The format is detected from the content (PLY header, gzip magic) and the extension.
// All loaders return an activated GaussianCloud (gs/gaussians.h) in the RDF frame of .ply files.
#pragma once

#include <string>

#include "attention/runtime/status.h"
#include "gs/gaussians.h"

namespace macro::gs {

enum class SceneFormat { kPly, kCompressedPly, kSplat, kSpz };

struct LoadLimits {
  size_t max_gaussians = 50'000'000;  // checked before allocating (raise with --max-gaussians)
};

struct LoadReport {
  size_t dropped_nonfinite = 0;   // Gaussians with NaN/Inf fields, dropped
  size_t fixed_quaternions = 0;   // zero quaternions replaced by identity
  size_t clamped_scales = 0;      // zero/negative linear scales (.splat) clamped to a tiny positive value
};

Result<GaussianCloud> load_scene(const std::string& path, const LoadLimits& limits = {},
                                 LoadReport* report = nullptr);
Status save_scene(const GaussianCloud& cloud, const std::string& path);  // by extension: .ply, .splat

}  // namespace macro::gs
