// MACRO depth planes (docs/spec/macro-method.md §1): the close-up's depth split into P planes by
// 1-D k-means on disparity 1/z, bin 0 = farthest.
//
// Legend: H x W close-up pixels; depth [H,W] = the alpha-weighted z sum (not divided by alpha), 0 =
// invalid (alpha < 0.5 or nothing hit); labels [H,W] int32 in [0, planes) or -1 (invalid).
//
// Released behaviour: disparity of every pixel with depth > 0; initial centres are the quantiles
// linspace(0,1,P+2)[1:-1] (linear interpolation between order statistics); at most 20 Lloyd
// iterations with absolute distance (ties to the lower centre), an empty cluster keeps its centre,
// stop when the largest centre shift is below 1e-6; centres sorted ascending (farthest first), then
// a final assignment. Each plane's depth is the LOWER median of the close-up z over its pixels.
// Difference: where the released code raises on an empty final bin (failing the scene), we drop
// that plane and renumber the rest (PlaneResult::dropped counts them).
// Option `auto`: the smallest P <= max_planes whose every plane has z90/z10 <= spread_ratio.
#pragma once

#include <cstdint>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::enhance {

inline constexpr int kKMeansMaxIterations = 20;        // depth_planes.py
inline constexpr double kKMeansTolerance = 1e-6;       // max centre shift to stop
inline constexpr double kAutoPlaneSpreadRatio = 1.5;  // --planes auto: max z90/z10 per plane

struct DepthPlane {
  int index = 0;                        // 0 = farthest
  double inv_depth_centroid = 0;        // k-means centre (1/z)
  double depth_median = 0;              // lower median of z over the plane's pixels
  double depth_p10 = 0, depth_p90 = 0;  // 10th / 90th percentile of z (lower order statistic)
  int64_t pixels = 0;
};

struct PlaneResult {
  int width = 0, height = 0;
  std::vector<int32_t> labels;  // [H,W], -1 = invalid
  std::vector<DepthPlane> planes;
  int requested = 0;  // P asked for (for auto: the P chosen)
  int dropped = 0;    // planes dropped because their k-means bin was empty
  int iterations = 0;
  int64_t valid_pixels = 0;
};

struct PlaneOptions {
  int planes = 3;          // P (released MACRO: 3)
  bool automatic = false;  // choose P <= planes by the spread rule
  double spread_ratio = kAutoPlaneSpreadRatio;
};

// 1-D k-means on values (any order); returns centres ascending and labels per value.
// Empty-cluster handling as above; centres of empty final clusters are kept (callers drop them).
struct KMeans1D {
  std::vector<double> centres;  // ascending
  std::vector<int32_t> labels;  // per value
  int iterations = 0;
};
KMeans1D kmeans_1d(const std::vector<float>& values, int k);

// depth [H,W]; errors: wrong size, no valid pixel, P < 1.
Result<PlaneResult> compute_depth_planes(const std::vector<float>& depth, int width, int height,
                                         const PlaneOptions& options = {});

}  // namespace macro::enhance
