// Greedy reference selection by reprojected depth coverage (see reference_selection.h).
#include "enhance/macro/reference_selection.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace macro::enhance {

const char* pixel_coords_name(PixelCoords p) {
  return p == PixelCoords::kCentre ? "centre" : "index";
}
Result<PixelCoords> parse_pixel_coords(const std::string& t) {
  if (t == "index" || t == "released") return PixelCoords::kIndex;
  if (t == "centre" || t == "center") return PixelCoords::kCentre;
  return Status::error("--pixel-coords: expected index or centre, found '" + t + "'");
}

std::vector<float> macro_depth(const gs::RenderResult& r) {
  std::vector<float> d(r.depth_sum.size());
  for (size_t i = 0; i < d.size(); ++i)
    d[i] = r.alpha[i] >= kDepthValidAlpha ? r.depth_sum[i] : 0.f;
  return d;
}

std::vector<uint8_t> coverage_map(const DepthView& cand, const gs::Camera& closeup, int grid,
                                  ThreadPool& pool, PixelCoords pixel) {
  const double o = pixel_offset(pixel);
  const gs::Camera g = closeup.resized(grid, grid);
  const gs::Camera& c = cand.camera;
  const int w = c.width, h = c.height;
  MACRO_CHECK(cand.depth.size() == size_t(w) * size_t(h));
  // camera-space point (x, y, z) of the candidate -> close-up camera: M x + b.
  const Eigen::Matrix3d M = g.R * c.R.transpose();
  const Eigen::Vector3d b = g.t - M * c.t;
  std::vector<uint8_t> cov(size_t(grid) * grid, 0);
  // Rows in fixed chunks, each with its own map, OR-ed afterwards: the result does not depend on
  // the thread count.
  const size_t chunk = 32;
  const size_t chunks = (size_t(h) + chunk - 1) / chunk;
  std::vector<std::vector<uint8_t>> part(chunks);
  pool.parallel_for(chunks, [&](size_t b0, size_t b1, int) {
    for (size_t bi = b0; bi < b1; ++bi) {
      std::vector<uint8_t>& m = part[bi];
      m.assign(cov.size(), 0);
      for (int i = int(bi * chunk); i < std::min(h, int((bi + 1) * chunk)); ++i)
        for (int j = 0; j < w; ++j) {
          const double z = cand.depth[size_t(i) * w + j];
          const Eigen::Vector3d xc((j + o - c.cx) / c.fx * z, (i + o - c.cy) / c.fy * z, z);
          const Eigen::Vector3d q = M * xc + b;
          if (!(q.z() > 0)) continue;
          const double u = g.fx * q.x() / q.z() + g.cx, v = g.fy * q.y() / q.z() + g.cy;
          if (u >= 0 && u < grid && v >= 0 && v < grid)
            m[size_t(int(v)) * grid + size_t(int(u))] = 1;
        }
    }
  });
  for (const auto& m : part)
    for (size_t k = 0; k < cov.size(); ++k) cov[k] |= m[k];
  return cov;
}

double visible_fraction(const DepthView& cu, const DepthView& cand, double tolerance,
                        ThreadPool& pool, PixelCoords pixel) {
  const double o = pixel_offset(pixel);
  const gs::Camera& a = cu.camera;
  const gs::Camera& c = cand.camera;
  const Eigen::Matrix3d M = c.R * a.R.transpose();
  const Eigen::Vector3d b = c.t - M * a.t;
  const int h = a.height, w = a.width;
  std::vector<int64_t> valid(size_t(h), 0), seen(size_t(h), 0);
  pool.parallel_for(size_t(h), [&](size_t i0, size_t i1, int) {
    for (size_t i = i0; i < i1; ++i)
      for (int j = 0; j < w; ++j) {
        const double z = cu.depth[i * w + size_t(j)];
        if (!(z > 0)) continue;
        ++valid[i];
        const Eigen::Vector3d q =
            M * Eigen::Vector3d((j + o - a.cx) / a.fx * z, (double(i) + o - a.cy) / a.fy * z, z) +
            b;
        if (!(q.z() > 0)) continue;
        const double u = c.fx * q.x() / q.z() + c.cx, v = c.fy * q.y() / q.z() + c.cy;
        if (!(u >= 0 && u < c.width && v >= 0 && v < c.height)) continue;
        const float dr = cand.depth[size_t(int(v)) * c.width + size_t(int(u))];
        if (dr > 0 && q.z() <= (1.0 + tolerance) * dr) ++seen[i];
      }
  });
  int64_t nv = 0, ns = 0;
  for (int i = 0; i < h; ++i) {
    nv += valid[size_t(i)];
    ns += seen[size_t(i)];
  }
  return nv ? double(ns) / double(nv) : 0.0;
}

Result<ReferenceSelection> greedy_select(const std::vector<std::vector<uint8_t>>& coverage,
                                         const std::vector<std::string>& names, int k,
                                         const std::vector<uint8_t>& eligible, int grid) {
  const size_t n = coverage.size();
  if (k < 1)
    return Status::error("reference selection: K must be >= 1, found " + std::to_string(k));
  if (names.size() != n || (!eligible.empty() && eligible.size() != n))
    return Status::error("reference selection: candidate lists differ in length");
  ReferenceSelection s;
  s.grid = grid;
  std::vector<size_t> pool;
  for (size_t c = 0; c < n; ++c) {
    if (coverage[c].size() != size_t(grid) * grid)
      return Status::error("reference selection: coverage of '" + names[c] + "' has " +
                           std::to_string(coverage[c].size()) + " cells, expected " +
                           std::to_string(grid * grid));
    int64_t cells = 0;
    for (uint8_t v : coverage[c]) cells += v != 0;
    s.candidate_cells.push_back(cells);
    if (eligible.empty() || eligible[c]) pool.push_back(c);
  }
  if (pool.empty())
    return Status::error(n == 0 ? "reference selection: no reference candidates"
                                : "reference selection: every candidate was discarded");
  std::vector<uint8_t> covered(size_t(grid) * grid, 0);
  const int rounds = std::min<int>(k, int(pool.size()));
  for (int r = 0; r < rounds; ++r) {
    int64_t best_gain = 0;
    size_t best_pos = 0;  // the first remaining one if nothing gains
    for (size_t p = 0; p < pool.size(); ++p) {
      const auto& cov = coverage[pool[p]];
      int64_t gain = 0;
      for (size_t e = 0; e < cov.size(); ++e) gain += cov[e] && !covered[e];
      if (gain > best_gain) {
        best_gain = gain;
        best_pos = p;
      }
    }
    const size_t c = pool[best_pos];
    for (size_t e = 0; e < covered.size(); ++e) covered[e] |= coverage[c][e] != 0;
    s.refs.push_back({int(c), names[c], best_gain});
    pool.erase(pool.begin() + std::ptrdiff_t(best_pos));
  }
  while (int(s.refs.size()) < k) {
    SelectedReference again = s.refs.back();
    again.new_coverage = 0;
    s.refs.push_back(again);
  }
  for (uint8_t v : covered) s.covered += v;
  return s;
}

}  // namespace macro::enhance
