// MACRO reference selection (docs/spec/macro-method.md §2): greedy set cover of a 256x256 grid over
// the close-up by each candidate's reprojected depth pixels.
//
// Legend: a DepthView is a camera and its MACRO depth [H,W] at the camera's size (the
// alpha-weighted z sum, NOT divided by alpha, 0 where alpha < 0.5); G x G coverage grid (G = 256).
//
// Coverage (released): every pixel (j + 0.5, i + 0.5) of the candidate's depth is unprojected at
// its depth (zero-depth pixels included: they land on the candidate's centre, as in the released
// code) and projected into the close-up camera resized to G x G (anisotropic intrinsics); the cell
// (floor u, floor v) is covered if z > 0 and 0 <= u < G, 0 <= v < G. No occlusion test.
// Greedy: min(K, N) rounds take the candidate with the most newly covered cells (ties -> the
// earliest, strict >); a round whose best gain is 0 takes the first remaining candidate; fewer than
// K candidates -> the last pick is repeated up to K.
// Option (paper, off by default): before the greedy rounds, discard candidates that cannot see
// the close-up: close-up pixels are projected into the candidate and count as seen when they land
// inside it with z_ref <= (1 + tolerance) * depth_ref at that pixel; a candidate with fewer than
// min_visible_fraction of the close-up's valid pixels seen is discarded.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/cameras/camera.h"
#include "gs/raster/rasterizer.h"

namespace macro::enhance {

inline constexpr int kCoverageGrid = 256;             // references.py grid
inline constexpr float kDepthValidAlpha = 0.5f;       // evaluate.py: alpha < 0.5 -> depth 0
inline constexpr double kOcclusionTolerance = 0.05;   // relative depth slack of the test
inline constexpr double kOcclusionMinVisible = 0.01;  // fraction of close-up pixels seen

// Where a pixel (column j, row i) sits when it is unprojected (coverage maps, crop centroids,
// the occlusion test). kIndex: at (j, i), as the released code's meshgrid of pixel indices
// (docs/macro.md §9; the default). kCentre: at its centre (j + 0.5, i + 0.5), the
// convention of our cameras and renderer (docs/rasterizer.md); ours, kept as an option.
enum class PixelCoords { kIndex, kCentre };
const char* pixel_coords_name(PixelCoords p);
Result<PixelCoords> parse_pixel_coords(const std::string& text);  // "index" | "centre"
inline double pixel_offset(PixelCoords p) {
  return p == PixelCoords::kCentre ? 0.5 : 0.0;
}

struct DepthView {
  gs::Camera camera;
  std::vector<float> depth;  // [H,W] at camera.width x camera.height
};

// MACRO depth from a render: depth_sum where alpha >= 0.5, else 0.
std::vector<float> macro_depth(const gs::RenderResult& render);

// Coverage cells [G*G] (1 = covered) of the close-up by one candidate.
std::vector<uint8_t> coverage_map(const DepthView& candidate, const gs::Camera& closeup,
                                  int grid = kCoverageGrid, ThreadPool& pool = ThreadPool::global(),
                                  PixelCoords pixel = PixelCoords::kIndex);

// Fraction of the close-up's valid pixels that the candidate sees (the occlusion test above).
double visible_fraction(const DepthView& closeup, const DepthView& candidate, double tolerance,
                        ThreadPool& pool = ThreadPool::global(),
                        PixelCoords pixel = PixelCoords::kIndex);

struct SelectedReference {
  int candidate = 0;  // index into the candidate list
  std::string name;
  int64_t new_coverage = 0;  // cells this pick added (0 for a repeat)
};
struct ReferenceSelection {
  std::vector<SelectedReference> refs;  // K entries, greedy order
  int64_t covered = 0;                  // cells covered by the union
  int grid = kCoverageGrid;
  std::vector<int64_t> candidate_cells;  // cells each candidate covers alone
  std::vector<int> discarded;            // candidates removed by the occlusion test
  std::vector<double> visible;           // per candidate, when the test ran
  double coverage_fraction() const { return double(covered) / (double(grid) * grid); }
};

// coverage [N][G*G]; names [N]; eligible [N] (empty = all). K >= 1. N = 0 (or none eligible) is
// an error.
Result<ReferenceSelection> greedy_select(const std::vector<std::vector<uint8_t>>& coverage,
                                         const std::vector<std::string>& names, int k,
                                         const std::vector<uint8_t>& eligible = {},
                                         int grid = kCoverageGrid);

}  // namespace macro::enhance
