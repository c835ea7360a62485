// Depth planes: k-means on disparity with the released initialisation and ordering, empty bins,
// automatic plane count.
#include <catch2/catch.hpp>

#include "enhance/macro/depth_planes.h"

using namespace macro;
using namespace macro::enhance;

TEST_CASE("k-means 1-D: quantile init, far-to-near order, lower median", "[macro][planes]") {
  // Three depth slabs: 8 m, 4 m, 2 m plus invalid pixels.
  const int w = 30, h = 10;
  std::vector<float> depth(size_t(w * h));
  for (int i = 0; i < h; ++i)
    for (int j = 0; j < w; ++j)
      depth[size_t(i * w + j)] =
          j < 10 ? 8.f + 0.01f * float(i) : (j < 20 ? 4.f + 0.01f * float(i) : 2.f);
  depth[0] = 0.f;  // invalid
  auto r = compute_depth_planes(depth, w, h, {3, false});
  REQUIRE(r.is_ok());
  REQUIRE(r->planes.size() == 3);
  CHECK(r->labels[0] == -1);
  CHECK(r->labels[1] == 0);  // 8 m = farthest = bin 0
  CHECK(r->labels[15] == 1);
  CHECK(r->labels[25] == 2);
  CHECK(r->planes[0].pixels == 99);
  CHECK(r->planes[2].depth_median == Approx(2.0));
  // lower median of 8.00..8.09 with 9 or 10 values each
  CHECK(r->planes[1].depth_median == Approx(4.04f));
  CHECK(r->planes[0].inv_depth_centroid < r->planes[1].inv_depth_centroid);
  CHECK(r->valid_pixels == w * h - 1);
}

TEST_CASE("k-means: an empty bin drops that plane", "[macro][planes]") {
  // Two distinct depths asked for three planes: quantile init puts two centres on one value.
  std::vector<float> depth(100, 2.f);
  for (int i = 0; i < 80; ++i) depth[size_t(i)] = 5.f;
  auto r = compute_depth_planes(depth, 10, 10, {3, false});
  REQUIRE(r.is_ok());
  CHECK(r->dropped == 1);
  REQUIRE(r->planes.size() == 2);
  CHECK(r->planes[0].depth_median == Approx(5.0));
  CHECK(r->planes[1].depth_median == Approx(2.0));
  for (int32_t l : r->labels) CHECK((l == 0 || l == 1));
}

TEST_CASE("k-means: no valid pixel is an error, auto picks the fewest planes", "[macro][planes]") {
  std::vector<float> none(64, 0.f);
  auto bad = compute_depth_planes(none, 8, 8);
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("no valid pixel") != std::string::npos);
  // Two slabs: auto with max 5 chooses 2.
  std::vector<float> depth(200);
  for (size_t i = 0; i < depth.size(); ++i) depth[i] = i < 100 ? 6.f + 0.001f * float(i) : 2.f;
  PlaneOptions o;
  o.planes = 5;
  o.automatic = true;
  auto r = compute_depth_planes(depth, 20, 10, o);
  REQUIRE(r.is_ok());
  CHECK(r->planes.size() == 2);
  CHECK(r->requested == 2);
}

TEST_CASE("k-means matches a direct Lloyd iteration", "[macro][planes]") {
  std::vector<float> v;
  uint32_t s = 12345;
  for (int i = 0; i < 5000; ++i) {
    s = s * 1664525u + 1013904223u;
    v.push_back(0.1f + float(s >> 8) / float(1u << 24));
  }
  const KMeans1D k = kmeans_1d(v, 4);
  REQUIRE(k.centres.size() == 4);
  for (size_t i = 1; i < 4; ++i) CHECK(k.centres[i] > k.centres[i - 1]);
  // Converged: every centre is the mean of its members (within the stopping tolerance).
  for (int c = 0; c < 4; ++c) {
    double sum = 0;
    int n = 0;
    for (size_t i = 0; i < v.size(); ++i)
      if (k.labels[i] == c) {
        sum += v[i];
        ++n;
      }
    REQUIRE(n > 0);
    CHECK(sum / n == Approx(k.centres[size_t(c)]).margin(1e-4));
  }
}
