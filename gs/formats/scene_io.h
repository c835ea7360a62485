// Splat scene files: Inria/gsplat .ply (binary LE/BE, ascii), SuperSplat compressed .ply, .splat,
// .spz (v2, v3, v4), PlayCanvas SOG (a folder with meta.json, or a .sog zip) and gsplat training
// checkpoints (a torch .pt zip with a `splats` dict). The format is detected from the content (PLY
// header, gzip / NGSP / zip magic, the zip's members) and the extension. All loaders return an
// activated GaussianCloud (gs/gaussians.h) in the RDF frame of .ply files.
//
// Bad input never crashes, hangs or allocates from a lying size: counts are checked against the
// file size and LoadLimits before allocating, and messages name the file and the field. Values that
// cannot be used are handled by one policy for every format (docs/formats.md):
//   - a Gaussian with any NaN/Inf value (raw or after activation) is dropped   -> dropped_nonfinite
//   - a zero quaternion becomes the identity; others are normalised          -> fixed_quaternions
//   - a zero/negative linear scale becomes |s|, at least kMinScale             -> clamped_scales
// A one-line note goes to stderr (macro::log_info, silenced by --quiet / MACRO_QUIET=1).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/limits.h"
#include "attention/runtime/status.h"
#include "gs/gaussians.h"

namespace macro::gs {

enum class SceneFormat { kPly, kCompressedPly, kSplat, kSpz, kSog, kGsplatCheckpoint };
// "ply", "compressed.ply", "splat", "spz", "sog", "gsplat checkpoint"
const char* scene_format_name(SceneFormat format);

struct LoadLimits {
  // Checked before allocating; default from resource_limits() (50 M, --max-gaussians).
  size_t max_gaussians = size_t(resource_limits().max_gaussians);
  uint64_t max_file_bytes = 1ull << 36;  // 64 GiB: files larger than this are refused unread
};

struct LoadReport {
  size_t dropped_nonfinite = 0;  // Gaussians with NaN/Inf fields, dropped
  size_t fixed_quaternions = 0;  // zero quaternions replaced by identity
  size_t clamped_scales = 0;     // zero/negative linear scales replaced by max(|s|, kMinScale)
  SceneFormat format = SceneFormat::kPly;  // what the file was read as
  size_t ignored_sh_coeffs = 0;  // rest coefficients per channel beyond degree 3 (or a ragged
                                 // f_rest count) that were not loaded
};

// Smallest linear scale a loader keeps (see LoadReport::clamped_scales).
inline constexpr float kMinScale = 1e-7f;

// path: a scene file, a SOG folder (holding meta.json) or a SOG meta.json itself.
Result<GaussianCloud> load_scene(const std::string& path, const LoadLimits& limits = {},
                                 LoadReport* report = nullptr);
// The same from bytes already in memory; `name` is used for format detection (its extension) and
// in messages.
Result<GaussianCloud> load_scene_from_memory(const uint8_t* data, size_t size,
                                             const std::string& name, const LoadLimits& limits = {},
                                             LoadReport* report = nullptr);
// Format from the content first (PLY header, gzip / NGSP magic, zip members), then the extension
// (.splat, .spz).
Result<SceneFormat> detect_scene_format(const uint8_t* data, size_t size, const std::string& name);

struct SaveOptions {
  int spz_version = 4;      // .spz: 2, 3 or 4 (the reference library's current version)
  int sog_iterations = 10;  // SOG: k-means iterations of the SH palette (splat-transform's default)
};

// By name: .ply (Inria binary little-endian layout), .splat (SH degree 0: higher bands are
// dropped, with a note naming how many coefficients), .spz (options.spz_version), .sog (SOG
// version 2 in one zip), a file named meta.json (SOG version 2 as a folder: the images are written
// next to it, each atomically, meta.json last). Atomic write. Compressed .ply and checkpoints are
// read-only.
Status save_scene(const GaussianCloud& cloud, const std::string& path,
                  const SaveOptions& options = {});
// True for a path save_scene writes as a SOG folder (its file name is meta.json).
bool is_sog_folder_output(const std::string& path);
// The bytes save_scene would write (SceneFormat::kSog: the .sog zip).
Result<std::vector<uint8_t>> encode_scene(const GaussianCloud& cloud, SceneFormat format,
                                          const std::string& name, const SaveOptions& options = {});

}  // namespace macro::gs
