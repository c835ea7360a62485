// SOG quantisers (see sog_quantize.h).
#include "gs/formats/sog_quantize.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
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

void assign_nearest(const float* x, size_t n, size_t dim, size_t ld, const float* centroids,
                    size_t k, uint32_t* labels, ThreadPool& pool, Isa isa) {
  constexpr size_t kPointBlock = 256, kCentroidBlock = 1024;
  // ||x - c||^2 = ||x||^2 - 2 x.c + ||c||^2: ||x||^2 is the same for every c, so each point takes
  // the c minimising ||c||^2 - 2 x.c, which the GEMM gives with alpha = -2 and a column bias.
  const size_t blocks = (k + kCentroidBlock - 1) / kCentroidBlock;
  std::vector<PackedWeights> packed(blocks);
  std::vector<float> norms(k);
  for (size_t j = 0; j < k; ++j) {
    double s = 0;
    for (size_t d = 0; d < dim; ++d) s += double(centroids[j * dim + d]) * centroids[j * dim + d];
    norms[j] = float(s);
  }
  for (size_t b = 0; b < blocks; ++b) {
    const size_t c0 = b * kCentroidBlock, cn = std::min(kCentroidBlock, k - c0);
    packed[b] = PackedWeights::pack(centroids + c0 * dim, int64_t(cn), int64_t(dim), int64_t(dim),
                                    WeightType::kF32, isa);
  }
  const size_t point_blocks = (n + kPointBlock - 1) / kPointBlock;
  std::vector<std::vector<float>> scratch(size_t(pool.size()));
  pool.parallel_for(
      point_blocks,
      [&](size_t pb0, size_t pb1, int worker) {
        std::vector<float>& d = scratch[size_t(worker)];
        d.resize(kPointBlock * kCentroidBlock);
        std::vector<float> best(kPointBlock);
        for (size_t pb = pb0; pb < pb1; ++pb) {
          const size_t p0 = pb * kPointBlock, pn = std::min(kPointBlock, n - p0);
          std::fill(best.begin(), best.end(), std::numeric_limits<float>::infinity());
          for (size_t i = 0; i < pn; ++i) labels[p0 + i] = 0;
          for (size_t b = 0; b < blocks; ++b) {
            const size_t c0 = b * kCentroidBlock, cn = std::min(kCentroidBlock, k - c0);
            GemmParams p;
            p.alpha = -2.f;
            p.bias_n = norms.data() + c0;
            gemm_packed(int64_t(pn), x + p0 * ld, int64_t(ld), packed[b], d.data(), int64_t(cn), p,
                        nullptr);
            for (size_t i = 0; i < pn; ++i) {
              const float* row = d.data() + i * cn;
              float m = row[0];
              for (size_t j = 1; j < cn; ++j) m = row[j] < m ? row[j] : m;
              if (!(m < best[i])) continue;  // a tie keeps the earlier block's lower index
              size_t j = 0;
              while (row[j] != m) ++j;
              best[i] = m;
              labels[p0 + i] = uint32_t(c0 + j);
            }
          }
        }
      },
      1);
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
  Progress progress(stage, size_t(iterations) + 1, 0.5);
  std::vector<double> sums(k * dim);
  std::vector<uint32_t> counts(k);
  for (int it = 0; it < iterations; ++it) {
    assign_nearest(x, n, dim, ld, r.centroids.data(), k, r.labels.data(), pool, isa);
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
    progress.advance();
  }
  // The labels of the final centroids.
  assign_nearest(x, n, dim, ld, r.centroids.data(), k, r.labels.data(), pool, isa);
  progress.advance();
  progress.finish();
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
