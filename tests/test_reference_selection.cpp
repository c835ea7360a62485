// Reference selection: coverage maps against the analytic geometry, greedy order, ties, repeats,
// the occlusion option.
#include <catch2/catch.hpp>

#include "enhance/macro/reference_selection.h"
#include "macro_synth_fixture.h"

using namespace macro;
using namespace macro::enhance;

namespace {

DepthView render_depth(const gs::SynthScene& s, const gs::Camera& c) {
  auto r = gs::render(s.cloud, c);
  MACRO_CHECK(r.is_ok());
  return {c, macro_depth(*r)};
}

}  // namespace

TEST_CASE("coverage and greedy selection on a synthetic scene", "[macro][refs]") {
  const auto scene = test::three_plane_scene();
  const gs::Camera cu = test::axis_camera("closeup", {0.1, 0.0, 0.5}, 0, 320, 180);
  // Candidates: looking away, shifted left (partial), the close-up pose widened (covers all).
  const gs::Camera away = test::axis_camera("away", {0, 0, 0}, 180, 320, 180);
  const gs::Camera left = test::axis_camera("left", {-1.6, 0.0, 0.5}, 0, 320, 180);
  const gs::Camera wide = test::axis_camera("wide", {0.1, 0.0, -0.5}, 0, 320, 180, 0.6);
  std::vector<DepthView> views = {render_depth(scene, away), render_depth(scene, left),
                                  render_depth(scene, wide)};
  std::vector<std::vector<uint8_t>> cov;
  std::vector<std::string> names;
  for (const DepthView& v : views) {
    cov.push_back(coverage_map(v, cu));
    names.push_back(v.camera.name);
  }
  // Analytic coverage: the same forward projection with ray-cast depths (pixels whose ray hits
  // nothing have depth 0, as in the render). Cells agree except along silhouettes.
  for (size_t v = 1; v < views.size(); ++v) {
    const gs::Camera& c = views[v].camera;
    DepthView exact{c, std::vector<float>(size_t(c.width) * c.height, 0.f)};
    for (int i = 0; i < c.height; ++i)
      for (int j = 0; j < c.width; ++j)
        if (auto hit = gs::cast_pixel(scene.geometry, c, i, j))
          exact.depth[size_t(i) * c.width + j] = float(hit->t);
    const auto want = coverage_map(exact, cu);
    // A covered cell matches if the other map covers a cell within one cell (a candidate sparser
    // than the grid hits scattered cells, which tiny depth differences move to a neighbour).
    auto near = [&](const std::vector<uint8_t>& m, int i, int j) {
      for (int di = -1; di <= 1; ++di)
        for (int dj = -1; dj <= 1; ++dj) {
          const int a = i + di, b = j + dj;
          if (a >= 0 && b >= 0 && a < kCoverageGrid && b < kCoverageGrid &&
              m[size_t(a) * kCoverageGrid + size_t(b)])
            return true;
        }
      return false;
    };
    int64_t got = 0, got_ok = 0, exp = 0, exp_ok = 0;
    for (int i = 0; i < kCoverageGrid; ++i)
      for (int j = 0; j < kCoverageGrid; ++j) {
        const size_t e = size_t(i) * kCoverageGrid + size_t(j);
        if (cov[v][e]) {
          ++got;
          got_ok += near(want, i, j);
        }
        if (want[e]) {
          ++exp;
          exp_ok += near(cov[v], i, j);
        }
      }
    INFO(names[v] << ": render cells " << got_ok << "/" << got << " near analytic, analytic "
                  << exp_ok << "/" << exp << " near render");
    REQUIRE(exp > 1000);
    // Render cells off the analytic set come from silhouette pixels, whose alpha-weighted depth
    // mixes two surfaces (the released depth); they stay a small share.
    CHECK(double(got_ok) >= 0.93 * double(got));
    CHECK(double(exp_ok) >= 0.98 * double(exp));
  }
  int64_t away_cells = 0;
  for (uint8_t x : cov[0]) away_cells += x;
  CHECK(away_cells <= 1);  // only its zero-depth pixels, collapsed on its centre
  std::vector<int64_t> cells;
  for (const auto& m : cov) {
    int64_t k = 0;
    for (uint8_t x : m) k += x;
    cells.push_back(k);
  }
  const std::string first = cells[2] > cells[1] ? "wide" : "left";

  auto sel = greedy_select(cov, names, 3);
  REQUIRE(sel.is_ok());
  REQUIRE(sel->refs.size() == 3);
  const size_t fi = first == "wide" ? 2 : 1, si = 3 - fi;
  CHECK(sel->refs[0].name == first);
  CHECK(sel->refs[0].new_coverage == cells[fi]);
  int64_t gain = 0;
  for (size_t e = 0; e < cov[si].size(); ++e) gain += cov[si][e] && !cov[fi][e];
  // Second: the other camera if it adds anything (it does: they see different parts), then away.
  CHECK(gain > 0);
  CHECK(sel->refs[1].name == names[si]);
  CHECK(sel->refs[1].new_coverage == gain);
  CHECK(sel->refs[2].name == "away");
  CHECK(sel->covered == cells[fi] + gain + sel->refs[2].new_coverage);

  // Occlusion option: the away camera sees none of the close-up, the wide one nearly all.
  const DepthView cud = render_depth(scene, cu);
  CHECK(visible_fraction(cud, views[0], kOcclusionTolerance) == 0.0);
  CHECK(visible_fraction(cud, views[2], kOcclusionTolerance) > 0.95);
}

TEST_CASE("greedy set cover: ties to the earliest, zero gain, repeats", "[macro][refs]") {
  const int G = 4;
  auto cells = [&](std::initializer_list<int> on) {
    std::vector<uint8_t> v(G * G, 0);
    for (int c : on) v[size_t(c)] = 1;
    return v;
  };
  std::vector<std::vector<uint8_t>> cov = {cells({0, 1}), cells({2, 3}), cells({0, 1, 2}),
                                           cells({})};
  std::vector<std::string> names = {"a", "b", "c", "d"};
  auto s = greedy_select(cov, names, 3, {}, G);
  REQUIRE(s.is_ok());
  CHECK(s->refs[0].name == "c");  // 3 cells
  CHECK(s->refs[1].name == "b");  // gains cell 3; a gains nothing
  CHECK(s->refs[1].new_coverage == 1);
  CHECK(s->refs[2].name == "a");  // zero gain: the first remaining
  CHECK(s->refs[2].new_coverage == 0);
  // Tie: a and b both gain 2 first -> a.
  auto t = greedy_select({cells({0, 1}), cells({2, 3})}, {"a", "b"}, 1, {}, G);
  REQUIRE(t.is_ok());
  CHECK(t->refs[0].name == "a");
  // Fewer candidates than K: the last pick repeats.
  auto r = greedy_select({cells({0}), cells({1, 2})}, {"a", "b"}, 4, {}, G);
  REQUIRE(r.is_ok());
  REQUIRE(r->refs.size() == 4);
  CHECK(r->refs[0].name == "b");
  CHECK(r->refs[1].name == "a");
  CHECK(r->refs[2].name == "a");
  CHECK(r->refs[3].name == "a");
  // Eligibility (occlusion): discarded candidates are never picked; none left is an error.
  auto e = greedy_select(cov, names, 1, {1, 1, 0, 1}, G);
  REQUIRE(e.is_ok());
  CHECK(e->refs[0].name == "a");
  CHECK_FALSE(greedy_select(cov, names, 1, {0, 0, 0, 0}, G).is_ok());
  CHECK_FALSE(greedy_select({}, {}, 3, {}, G).is_ok());
}

TEST_CASE("coverage map: integer pixel indices (released) or pixel centres (ours)",
          "[macro][refs]") {
  // The close-up (256 x 256, the grid itself) and a candidate with the same pose and field of
  // view at 128 x 128, flat depth 1, power-of-two intrinsics (exact arithmetic). Candidate pixel
  // j lands at grid column 2 (j + o): the even columns with indices (released), the odd ones with
  // pixel centres.
  gs::Camera cu;
  cu.name = "cu";
  cu.width = cu.height = kCoverageGrid;
  cu.fx = cu.fy = 128;
  cu.cx = cu.cy = 128;
  cu.R.setIdentity();
  cu.t.setZero();
  DepthView cand{cu.resized(128, 128), std::vector<float>(128 * 128, 1.f)};
  const auto released = coverage_map(cand, cu);  // the default
  const auto centres =
      coverage_map(cand, cu, kCoverageGrid, ThreadPool::global(), PixelCoords::kCentre);
  int64_t n_released = 0, n_centres = 0;
  for (int i = 0; i < kCoverageGrid; ++i)
    for (int j = 0; j < kCoverageGrid; ++j) {
      const size_t k = size_t(i) * kCoverageGrid + size_t(j);
      INFO("cell " << i << "," << j);
      REQUIRE(released[k] == uint8_t(i % 2 == 0 && j % 2 == 0));
      REQUIRE(centres[k] == uint8_t(i % 2 == 1 && j % 2 == 1));
      n_released += released[k];
      n_centres += centres[k];
    }
  CHECK(n_released == 128 * 128);
  CHECK(n_centres == 128 * 128);
}
