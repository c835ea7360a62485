// SOG quantisers (see sog_quantize.h).
#include "gs/formats/sog_quantize.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <random>

#include "attention/runtime/gemm.h"
#include "attention/runtime/progress.h"

namespace macro::gs::formats {

std::vector<float> codebook_1d(std::vector<float> v, size_t k, int iterations) {
  std::vector<float> c(k, 0.f);
  if (v.empty() || k == 0) return c;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  // Few distinct values: each is an entry, exactly.
  std::vector<float> distinct;
  for (size_t i = 0; i < n && distinct.size() <= k; ++i)
    if (distinct.empty() || v[i] != distinct.back()) distinct.push_back(v[i]);
  if (distinct.size() <= k) {
    for (size_t j = 0; j < k; ++j) c[j] = distinct[std::min(j, distinct.size() - 1)];
    return c;
  }
  std::vector<double> prefix(n + 1, 0.0);
  for (size_t i = 0; i < n; ++i) prefix[i + 1] = prefix[i] + double(v[i]);
  for (size_t j = 0; j < k; ++j)
    c[j] = v[std::min(
        n - 1, static_cast<size_t>((2.0 * double(j) + 1.0) / (2.0 * double(k)) * double(n)))];
  std::vector<size_t> start(k + 1);
  for (int it = 0; it < iterations; ++it) {
    // Cluster j holds the values nearer to c[j] than to its neighbours: a run of the sorted array.
    start[0] = 0;
    start[k] = n;
    for (size_t j = 1; j < k; ++j) {
      const float mid = 0.5f * (c[j - 1] + c[j]);
      start[j] = size_t(std::lower_bound(v.begin(), v.end(), mid) - v.begin());
      start[j] = std::max(start[j], start[j - 1]);
    }
    bool moved = false;
    for (size_t j = 0; j < k; ++j) {
      if (start[j + 1] <= start[j]) continue;  // empty: keep the entry where it is
      const float m =
          float((prefix[start[j + 1]] - prefix[start[j]]) / double(start[j + 1] - start[j]));
      moved = moved || m != c[j];
      c[j] = m;
    }
    std::sort(c.begin(), c.end());
    if (!moved) break;
  }
  return c;
}

size_t nearest_entry(const std::vector<float>& cb, float v) {
  const size_t hi = size_t(std::lower_bound(cb.begin(), cb.end(), v) - cb.begin());
  if (hi == 0) return 0;
  if (hi == cb.size()) return cb.size() - 1;
  // cb[hi - 1] < v <= cb[hi]; the first of equal entries on a tie.
  size_t lo = hi - 1;
  while (lo > 0 && cb[lo - 1] == cb[lo]) --lo;
  return (v - cb[hi - 1] <= cb[hi] - v) ? lo : hi;
}

namespace {

constexpr size_t kPointBlock = 256, kCentroidBlock = 1024;

// Centroids packed for the GEMM in blocks of kCentroidBlock, with their squared norms.
// ||x - c||^2 = ||x||^2 - 2 x.c + ||c||^2: ||x||^2 is the same for every c, so a point's nearest c
// minimises ||c||^2 - 2 x.c, which the GEMM gives with alpha = -2 and a column bias.
struct PackedSet {
  size_t k = 0;
  std::vector<PackedWeights> blocks;
  std::vector<float> norms;
};

PackedSet pack_set(const float* c, size_t k, size_t dim, Isa isa) {
  PackedSet s;
  s.k = k;
  s.norms.resize(k);
  for (size_t j = 0; j < k; ++j) {
    double t = 0;
    for (size_t d = 0; d < dim; ++d) t += double(c[j * dim + d]) * c[j * dim + d];
    s.norms[j] = float(t);
  }
  for (size_t c0 = 0; c0 < k; c0 += kCentroidBlock) {
    const size_t cn = std::min(kCentroidBlock, k - c0);
    s.blocks.push_back(PackedWeights::pack(c + c0 * dim, int64_t(cn), int64_t(dim), int64_t(dim),
                                           WeightType::kF32, isa));
  }
  return s;
}

// For rows <= kPointBlock rows of x: the `p` smallest ||c||^2 - 2 x.c of the set, ascending (the
// lower index first on a tie), in best[r * p ..], their indices in index[r * p ..]. `d` holds
// kPointBlock * kCentroidBlock floats.
void nearest_in_set(const float* x, size_t rows, size_t ld, const PackedSet& s, size_t p, float* d,
                    float* best, uint32_t* index) {
  std::fill(best, best + rows * p, std::numeric_limits<float>::infinity());
  std::fill(index, index + rows * p, 0u);
  for (size_t b = 0; b < s.blocks.size(); ++b) {
    const size_t c0 = b * kCentroidBlock, cn = std::min(kCentroidBlock, s.k - c0);
    GemmParams gp;
    gp.alpha = -2.f;
    gp.bias_n = s.norms.data() + c0;
    gemm_packed(int64_t(rows), x, int64_t(ld), s.blocks[b], d, int64_t(cn), gp, nullptr);
    for (size_t i = 0; i < rows; ++i) {
      const float* row = d + i * cn;
      float* bi = best + i * p;
      uint32_t* ii = index + i * p;
      if (p == 1) {
        float m = row[0];
        for (size_t j = 1; j < cn; ++j) m = row[j] < m ? row[j] : m;
        if (!(m < bi[0])) continue;  // a tie keeps the earlier block's lower index
        size_t j = 0;
        while (row[j] != m) ++j;
        bi[0] = m;
        ii[0] = uint32_t(c0 + j);
        continue;
      }
      for (size_t j = 0; j < cn; ++j) {
        if (!(row[j] < bi[p - 1])) continue;
        size_t q = p - 1;
        for (; q > 0 && row[j] < bi[q - 1]; --q) bi[q] = bi[q - 1], ii[q] = ii[q - 1];
        bi[q] = row[j];
        ii[q] = uint32_t(c0 + j);
      }
    }
  }
}

}  // namespace

void assign_nearest(const float* x, size_t n, size_t dim, size_t ld, const float* centroids,
                    size_t k, uint32_t* labels, ThreadPool& pool, Isa isa) {
  const PackedSet set = pack_set(centroids, k, dim, isa);
  const size_t point_blocks = (n + kPointBlock - 1) / kPointBlock;
  pool.parallel_for(
      point_blocks,
      [&](size_t pb0, size_t pb1, int) {
        std::vector<float> d(kPointBlock * kCentroidBlock), best(kPointBlock);
        for (size_t pb = pb0; pb < pb1; ++pb) {
          const size_t p0 = pb * kPointBlock, pn = std::min(kPointBlock, n - p0);
          nearest_in_set(x + p0 * ld, pn, ld, set, 1, d.data(), best.data(), labels + p0);
        }
      },
      1);
}

void assign_grouped(const float* x, size_t n, size_t dim, size_t ld, const float* centroids,
                    size_t k, uint32_t* labels, size_t groups, size_t probes, ThreadPool& pool,
                    Isa isa) {
  groups = std::max<size_t>(1, std::min(groups, k));
  probes = std::max<size_t>(1, std::min(probes, groups));
  // The centroids' own clusters, and the centroids reordered group by group.
  const KMeansResult coarse = kmeans(centroids, k, dim, dim, groups, 4, 0x9e3779b9u, "", pool, isa);
  std::vector<size_t> offset(groups + 1, 0);
  for (uint32_t g : coarse.labels) ++offset[g + 1];
  for (size_t g = 0; g < groups; ++g) offset[g + 1] += offset[g];
  std::vector<uint32_t> original(k);
  std::vector<float> sorted(k * dim);
  {
    std::vector<size_t> fill(offset.begin(), offset.end() - 1);
    for (size_t j = 0; j < k; ++j) {
      const size_t at = fill[coarse.labels[j]]++;
      original[at] = uint32_t(j);
      std::copy_n(centroids + j * dim, dim, sorted.begin() + ptrdiff_t(at * dim));
    }
  }
  std::vector<PackedSet> sets(groups);
  pool.parallel_for(groups, [&](size_t g0, size_t g1, int) {
    for (size_t g = g0; g < g1; ++g)
      if (offset[g + 1] > offset[g])
        sets[g] = pack_set(sorted.data() + offset[g] * dim, offset[g + 1] - offset[g], dim, isa);
  });
  // Each point's `probes` nearest group centres.
  const PackedSet centres = pack_set(coarse.centroids.data(), groups, dim, isa);
  std::vector<uint32_t> probe(n * probes);
  const size_t point_blocks = (n + kPointBlock - 1) / kPointBlock;
  pool.parallel_for(
      point_blocks,
      [&](size_t pb0, size_t pb1, int) {
        std::vector<float> d(kPointBlock * kCentroidBlock), best(kPointBlock * probes);
        for (size_t pb = pb0; pb < pb1; ++pb) {
          const size_t p0 = pb * kPointBlock, pn = std::min(kPointBlock, n - p0);
          nearest_in_set(x + p0 * ld, pn, ld, centres, probes, d.data(), best.data(),
                         probe.data() + p0 * probes);
        }
      },
      1);
  // Per group, the (point, probe slot) pairs that search it, in point order.
  std::vector<size_t> first(groups + 1, 0);
  for (uint32_t g : probe) ++first[g + 1];
  for (size_t g = 0; g < groups; ++g) first[g + 1] += first[g];
  std::vector<uint32_t> pair(n * probes);  // point * probes + slot
  {
    std::vector<size_t> fill(first.begin(), first.end() - 1);
    for (size_t i = 0; i < n * probes; ++i) pair[fill[probe[i]]++] = uint32_t(i);
  }
  std::vector<float> dist(n * probes, std::numeric_limits<float>::infinity());
  std::vector<uint32_t> found(n * probes, 0);
  pool.parallel_for(
      groups,
      [&](size_t g0, size_t g1, int) {
        std::vector<float> d(kPointBlock * kCentroidBlock), rows(kPointBlock * dim),
            best(kPointBlock);
        std::vector<uint32_t> local(kPointBlock);
        for (size_t g = g0; g < g1; ++g) {
          if (offset[g + 1] == offset[g]) continue;
          for (size_t a = first[g]; a < first[g + 1]; a += kPointBlock) {
            const size_t m = std::min(kPointBlock, first[g + 1] - a);
            for (size_t r = 0; r < m; ++r)
              std::copy_n(x + size_t(pair[a + r] / probes) * ld, dim,
                          rows.begin() + ptrdiff_t(r * dim));
            nearest_in_set(rows.data(), m, dim, sets[g], 1, d.data(), best.data(), local.data());
            for (size_t r = 0; r < m; ++r) {
              dist[pair[a + r]] = best[r];
              found[pair[a + r]] = original[offset[g] + local[r]];
            }
          }
        }
      },
      1);
  // The best of each point's probes (the lower index on a tie); a point whose probed groups were
  // all empty searches every centroid.
  pool.parallel_for(n, [&](size_t i0, size_t i1, int) {
    for (size_t i = i0; i < i1; ++i) {
      float b = std::numeric_limits<float>::infinity();
      uint32_t l = 0;
      for (size_t s = 0; s < probes; ++s) {
        const float v = dist[i * probes + s];
        const uint32_t c = found[i * probes + s];
        if (v < b || (v == b && c < l)) b = v, l = c;
      }
      if (!(b < std::numeric_limits<float>::infinity())) {
        double bd = std::numeric_limits<double>::infinity();
        for (size_t c = 0; c < k; ++c) {
          double t = 0;
          for (size_t e = 0; e < dim; ++e)
            t += std::pow(double(x[i * ld + e]) - centroids[c * dim + e], 2);
          if (t < bd) bd = t, l = uint32_t(c);
        }
      }
      labels[i] = l;
    }
  });
}

KMeansResult kmeans(const float* x, size_t n, size_t dim, size_t ld, size_t k, int iterations,
                    uint64_t seed, const std::string& stage, ThreadPool& pool, Isa isa) {
  KMeansResult r;
  k = std::min(k, n);
  r.centroids.resize(k * dim);
  r.labels.resize(n);
  auto copy_row = [&](size_t dst, size_t src) {
    std::copy(x + src * ld, x + src * ld + dim, r.centroids.begin() + ptrdiff_t(dst * dim));
  };
  if (k == 0) return r;
  if (k == n) {
    for (size_t i = 0; i < n; ++i) copy_row(i, i), r.labels[i] = uint32_t(i);
    return r;
  }
  // k distinct rows, chosen by a seeded partial shuffle (the generator's raw output only, so the
  // choice is the same with every standard library).
  std::mt19937_64 rng(seed);
  std::vector<uint32_t> pick(n);
  std::iota(pick.begin(), pick.end(), 0u);
  for (size_t i = 0; i < k; ++i) {
    const size_t j = i + size_t(rng() % uint64_t(n - i));
    std::swap(pick[i], pick[j]);
    copy_row(i, pick[i]);
  }
  std::optional<Progress> progress;
  if (!stage.empty()) progress.emplace(stage, size_t(iterations) + 1, 0.5);
  // Large palettes search each point's nearest groups of centroids only (sog_quantize.h).
  const bool grouped = k > kExactMaxCentroids;
  const size_t groups = size_t(std::lround(std::sqrt(double(k))));
  auto assign = [&] {
    if (grouped)
      assign_grouped(x, n, dim, ld, r.centroids.data(), k, r.labels.data(), groups, kGroupProbes,
                     pool, isa);
    else
      assign_nearest(x, n, dim, ld, r.centroids.data(), k, r.labels.data(), pool, isa);
  };
  std::vector<double> sums(k * dim);
  std::vector<uint32_t> counts(k);
  for (int it = 0; it < iterations; ++it) {
    assign();
    std::fill(sums.begin(), sums.end(), 0.0);
    std::fill(counts.begin(), counts.end(), 0u);
    for (size_t i = 0; i < n; ++i) {
      const size_t c = r.labels[i];
      ++counts[c];
      for (size_t d = 0; d < dim; ++d) sums[c * dim + d] += double(x[i * ld + d]);
    }
    for (size_t c = 0; c < k; ++c) {
      if (counts[c] == 0) {  // empty: restart at a seeded random row
        copy_row(c, size_t(rng() % uint64_t(n)));
        continue;
      }
      for (size_t d = 0; d < dim; ++d)
        r.centroids[c * dim + d] = float(sums[c * dim + d] / double(counts[c]));
    }
    if (progress) progress->advance();
  }
  // The labels of the final centroids.
  assign();
  if (progress) progress->advance(), progress->finish();
  return r;
}

std::vector<uint32_t> morton_order(const std::vector<float>& position) {
  const size_t n = position.size() / 3;
  float lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a] = hi[a] = n ? position[size_t(a)] : 0.f;
  for (size_t i = 0; i < n; ++i)
    for (size_t a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], position[i * 3 + a]);
      hi[a] = std::max(hi[a], position[i * 3 + a]);
    }
  auto spread = [](uint32_t v) {  // 10 bits to every third bit
    v &= 0x3ff;
    v = (v | v << 16) & 0x030000ff;
    v = (v | v << 8) & 0x0300f00f;
    v = (v | v << 4) & 0x030c30c3;
    v = (v | v << 2) & 0x09249249;
    return v;
  };
  std::vector<uint32_t> code(n);
  for (size_t i = 0; i < n; ++i) {
    uint32_t m = 0;
    for (size_t a = 0; a < 3; ++a) {
      const double range = double(hi[a]) - double(lo[a]);
      const double t = range > 0 ? (double(position[i * 3 + a]) - lo[a]) / range : 0.0;
      m |= spread(uint32_t(std::clamp(t * 1023.0 + 0.5, 0.0, 1023.0))) << a;
    }
    code[i] = m;
  }
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return code[a] < code[b]; });
  return order;
}

}  // namespace macro::gs::formats
