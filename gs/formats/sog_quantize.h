// The quantisers behind the SOG writer (format_sog_write.cpp), internal to gs/formats/:
//   - codebook_1d: a k-entry codebook for a set of scalars (1-D k-means: exact Lloyd iterations on
//     the sorted values, started from their quantiles). At most k distinct values are kept exactly.
//   - kmeans: a palette of D-dimensional vectors (Lloyd iterations from seeded distinct points;
//     deterministic for a given seed and iteration count on one kernel path, whatever the thread
//     count). The nearest-centroid search uses ||x||^2 - 2 x.c + ||c||^2 with x.c from the
//     runtime's GEMM, in blocks of points and centroids, on the thread pool. Up to
//     kExactMaxCentroids centroids every point searches all of them; beyond (the 65536-entry SH
//     palette of a large scene, where that is ~1.6 TFLOP per pass over 500k points) the centroids
//     are themselves clustered into sqrt(k) groups and each point searches the kGroupProbes groups
//     whose centres are nearest to it (an inverted-file search: not always the exact nearest, ~32x
//     less work).
//   - morton_order: Gaussians sorted by the Morton code of their position (10 bits per axis over
//     the bounding box), so neighbouring pixels hold neighbouring Gaussians and the images
//     compress.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/cpu.h"
#include "attention/runtime/thread_pool.h"

namespace macro::gs::formats {

// Sorted ascending, exactly k entries (padded with the largest when there are fewer values).
std::vector<float> codebook_1d(std::vector<float> values, size_t k, int iterations = 50);
// Index of the entry nearest to v in a sorted codebook (the lower one on a tie).
size_t nearest_entry(const std::vector<float>& codebook, float v);

inline constexpr size_t kExactMaxCentroids = 4096;
inline constexpr size_t kGroupProbes = 8;

struct KMeansResult {
  std::vector<float> centroids;  // [k, dim]
  std::vector<uint32_t> labels;  // [n]
};
// x: n rows of dim floats, row stride ld. k <= n (k == n: each row is its own centroid, no
// iterations). Progress ("stage", none when empty) on stderr.
KMeansResult kmeans(const float* x, size_t n, size_t dim, size_t ld, size_t k, int iterations,
                    uint64_t seed, const std::string& stage, ThreadPool& pool,
                    Isa isa = active_isa());
// labels[i] = the centroid nearest to row i (the lowest index on a tie), for x as above and
// centroids [k, dim] (k >= 1).
void assign_nearest(const float* x, size_t n, size_t dim, size_t ld, const float* centroids,
                    size_t k, uint32_t* labels, ThreadPool& pool, Isa isa = active_isa());

// The grouped search described above: `groups` clusters of the centroids, `probes` searched per
// point.
void assign_grouped(const float* x, size_t n, size_t dim, size_t ld, const float* centroids,
                    size_t k, uint32_t* labels, size_t groups, size_t probes, ThreadPool& pool,
                    Isa isa = active_isa());

std::vector<uint32_t> morton_order(const std::vector<float>& position);

}  // namespace macro::gs::formats
