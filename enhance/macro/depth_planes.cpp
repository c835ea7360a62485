// Depth planes by 1-D k-means on disparity (see depth_planes.h).
#include "enhance/macro/depth_planes.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace macro::enhance {
namespace {

// torch.quantile (linear): position q * (n - 1) between order statistics.
double quantile_sorted(const std::vector<float>& sorted, double q) {
  const double pos = q * double(sorted.size() - 1);
  const size_t lo = size_t(std::floor(pos));
  const size_t hi = std::min(lo + 1, sorted.size() - 1);
  const double f = pos - double(lo);
  return double(sorted[lo]) + (double(sorted[hi]) - double(sorted[lo])) * f;
}

int nearest_centre(double v, const std::vector<double>& c) {
  int best = 0;
  double bd = std::abs(v - c[0]);
  for (size_t i = 1; i < c.size(); ++i) {
    const double d = std::abs(v - c[i]);
    if (d < bd) {
      bd = d;
      best = int(i);
    }
  }
  return best;
}

}  // namespace

KMeans1D kmeans_1d(const std::vector<float>& values, int k) {
  MACRO_CHECK(k >= 1 && !values.empty());
  KMeans1D r;
  std::vector<float> sorted = values;
  std::sort(sorted.begin(), sorted.end());
  r.centres.resize(size_t(k));
  for (int i = 0; i < k; ++i)
    r.centres[size_t(i)] = quantile_sorted(sorted, double(i + 1) / (k + 1));
  r.labels.assign(values.size(), 0);
  std::vector<double> sum(static_cast<size_t>(k));
  std::vector<int64_t> cnt(static_cast<size_t>(k));
  for (int it = 0; it < kKMeansMaxIterations; ++it) {
    std::fill(sum.begin(), sum.end(), 0.0);
    std::fill(cnt.begin(), cnt.end(), 0);
    for (size_t i = 0; i < values.size(); ++i) {
      const int l = nearest_centre(values[i], r.centres);
      sum[size_t(l)] += values[i];
      ++cnt[size_t(l)];
    }
    double shift = 0;
    for (int c = 0; c < k; ++c) {
      if (cnt[size_t(c)] == 0) continue;  // an empty cluster keeps its centre
      const double nc = sum[size_t(c)] / double(cnt[size_t(c)]);
      shift = std::max(shift, std::abs(nc - r.centres[size_t(c)]));
      r.centres[size_t(c)] = nc;
    }
    r.iterations = it + 1;
    if (shift < kKMeansTolerance) break;
  }
  std::sort(r.centres.begin(), r.centres.end());
  for (size_t i = 0; i < values.size(); ++i) r.labels[i] = nearest_centre(values[i], r.centres);
  return r;
}

namespace {

Result<PlaneResult> planes_fixed(const std::vector<float>& depth, int width, int height, int p,
                                 const std::vector<float>& disparity,
                                 const std::vector<int64_t>& where) {
  PlaneResult out;
  out.width = width;
  out.height = height;
  out.requested = p;
  out.valid_pixels = int64_t(where.size());
  const KMeans1D km = kmeans_1d(disparity, p);
  out.iterations = km.iterations;
  std::vector<std::vector<float>> z(static_cast<size_t>(p));
  for (size_t i = 0; i < where.size(); ++i)
    z[size_t(km.labels[i])].push_back(depth[size_t(where[i])]);
  // Drop empty bins; renumber the rest in far-to-near order.
  std::vector<int32_t> remap(size_t(p), -1);
  for (int c = 0; c < p; ++c) {
    if (z[size_t(c)].empty()) {
      ++out.dropped;
      continue;
    }
    std::vector<float>& v = z[size_t(c)];
    std::sort(v.begin(), v.end());
    DepthPlane pl;
    pl.index = int(out.planes.size());
    pl.inv_depth_centroid = km.centres[size_t(c)];
    pl.depth_median = v[(v.size() - 1) / 2];  // lower median (torch.median)
    pl.depth_p10 = v[size_t(std::floor(0.1 * double(v.size() - 1)))];
    pl.depth_p90 = v[size_t(std::floor(0.9 * double(v.size() - 1)))];
    pl.pixels = int64_t(v.size());
    remap[size_t(c)] = pl.index;
    out.planes.push_back(pl);
  }
  out.labels.assign(size_t(width) * height, -1);
  for (size_t i = 0; i < where.size(); ++i)
    out.labels[size_t(where[i])] = remap[size_t(km.labels[i])];
  return out;
}

}  // namespace

Result<PlaneResult> compute_depth_planes(const std::vector<float>& depth, int width, int height,
                                         const PlaneOptions& options) {
  if (width <= 0 || height <= 0 || depth.size() != size_t(width) * size_t(height))
    return Status::error("depth planes: depth map has " + std::to_string(depth.size()) +
                         " values, expected " + std::to_string(width) + "x" +
                         std::to_string(height));
  if (options.planes < 1 || options.planes > 64)
    return Status::error("depth planes: planes must be in [1, 64], found " +
                         std::to_string(options.planes));
  std::vector<float> disparity;
  std::vector<int64_t> where;
  for (size_t i = 0; i < depth.size(); ++i)
    if (depth[i] > 0 && std::isfinite(depth[i])) {
      disparity.push_back(1.0f / depth[i]);
      where.push_back(int64_t(i));
    }
  if (where.empty())
    return Status::error(
        "depth planes: the close-up depth has no valid pixel (alpha >= 0.5 "
        "nowhere): the close-up sees no part of the scene");
  if (!options.automatic)
    return planes_fixed(depth, width, height, options.planes, disparity, where);
  Result<PlaneResult> last = Status::error("depth planes: no plane count tried");
  for (int p = 1; p <= options.planes; ++p) {
    last = planes_fixed(depth, width, height, p, disparity, where);
    if (!last) return last;
    bool ok = true;
    for (const DepthPlane& pl : last->planes)
      if (pl.depth_p10 <= 0 || pl.depth_p90 / pl.depth_p10 > options.spread_ratio) ok = false;
    if (ok) return last;
  }
  return last;
}

}  // namespace macro::enhance
