// Appendix D pair construction (enhance/datasets/pair_construction.h), the COLMAP points3D reader/writer
// (gs/cameras/colmap_points.h) and `macro bench pairs` end to end, on synthetic camera rigs whose depths,
// angles, IoUs and set memberships are known in closed form.
#include <Eigen/Geometry>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "attention/runtime/file_io.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/datasets/pair_construction.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/colmap_points.h"
#include "gs/image_io.h"
#include "gs/synth/random_scene.h"
#include "gs/formats/scene_io.h"
#include "tests/pair_rig_fixture.h"
#include "tests/test_support.h"

namespace macro {
namespace {
namespace fs = std::filesystem;
using namespace pair_test;

TEST_CASE("pairs: visible cone, median and percentile depths on known points", "[pairs]") {
  // Camera at the origin looking along +z. Points on the axis at depths 1..100 (all visible),
  // points behind the camera, and points just outside and just inside the 54.7356 deg cone.
  const gs::Camera cam = rig_camera("axis", {0, 0, 0}, {0, 0, 1});
  std::vector<Eigen::Vector3d> pts;
  for (int k = 1; k <= 100; ++k) pts.emplace_back(0, 0, k);
  for (int k = 1; k <= 50; ++k) pts.emplace_back(0, 0, -k);  // behind
  const double tan_half = std::sqrt(2.0);
  pts.emplace_back(10 * tan_half * 1.01, 0, 10);   // outside the cone
  pts.emplace_back(0, 10 * tan_half * 1.01, 10);   // outside
  pts.emplace_back(10 * tan_half * 0.99, 0, 10);   // inside, depth 10
  pts.emplace_back(0, -10 * tan_half * 0.99, 91);  // inside, depth 91
  std::vector<uint64_t> bits((pts.size() + 63) / 64, 0);
  const enhance::CameraDepth d = enhance::camera_depth(cam, pts, &bits);
  CHECK(d.visible == 102);
  CHECK(d.half_fov_deg == Approx(std::atan(tan_half) / kDeg).epsilon(1e-12));
  CHECK(d.axis.isApprox(Eigen::Vector3d(0, 0, 1)));
  // Depths: 1..100 plus 10 and 91, 102 values s[0..101] with s[9] = s[10] = 10, s[11] = 11,
  // s[91] = s[92] = 91. Linear positions: p10 at 10.1 -> 10 + 0.1 * (11 - 10); median at 50.5
  // -> (50 + 51) / 2; p90 at 90.9 -> 90 + 0.9 * (91 - 90).
  CHECK(d.p10 == Approx(10.1).epsilon(1e-12));
  CHECK(d.median == Approx(50.5).epsilon(1e-12));
  CHECK(d.p90 == Approx(90.9).epsilon(1e-12));
  CHECK(d.span == Approx(9.0).epsilon(1e-12));
  for (size_t m = 0; m < pts.size(); ++m) {
    const bool expect = m < 100 || m == 152 || m == 153;
    CHECK(bool((bits[m >> 6] >> (m & 63)) & 1) == expect);
  }
  // Percentiles on an uneven list against a sorted reference.
  std::vector<double> v = {7, 1, 9, 3, 3, 12, 0.5, 8};
  for (double p : {0.0, 10.0, 37.5, 50.0, 90.0, 100.0}) {
    std::vector<double> copy = v;
    CHECK(enhance::percentile_linear(copy, p) == Approx(sorted_percentile(v, p)).epsilon(1e-14));
  }
  // No visible point: no depth.
  const enhance::CameraDepth none = enhance::camera_depth(cam, {{0, 0, -5}}, nullptr);
  CHECK(none.visible == 0);
  CHECK(none.median == 0);
}

TEST_CASE("pairs: IoU of visible sets on a plane is the ratio of the disk areas", "[pairs]") {
  // A dense grid on the plane z = 0 (spacing 0.01 over [-3, 3]^2). Two cameras on the z axis
  // looking at it from heights 1 and 2: visible disks of radius h * sqrt(2), nested, so
  // IoU = (1 / 2)^2 = 0.25 up to the grid's edge error. Both depths are exact (a fronto-parallel
  // plane), so the depth ratio is 2 and the paper's IoU >= 0.4 can never hold with ratio >= 2 on
  // such a scene (docs/benchmark.md).
  std::vector<Eigen::Vector3d> pts;
  for (int i = -300; i <= 300; ++i)
    for (int j = -300; j <= 300; ++j) pts.emplace_back(i * 0.01, j * 0.01, 0);
  gs::CameraSet cams;
  cams.cameras.push_back(rig_camera("a_near", {0, 0, -1}, {0, 0, 1}));
  cams.cameras.push_back(rig_camera("b_far", {0, 0, -2}, {0, 0, 1}));
  std::vector<uint64_t> ba((pts.size() + 63) / 64, 0), bb = ba;
  const auto da = enhance::camera_depth(cams.cameras[0], pts, &ba);
  const auto db = enhance::camera_depth(cams.cameras[1], pts, &bb);
  CHECK(da.median == Approx(1.0).epsilon(1e-12));
  CHECK(da.p10 == Approx(1.0).epsilon(1e-12));
  CHECK(db.median == Approx(2.0).epsilon(1e-12));
  CHECK(da.span == Approx(1.0).epsilon(1e-12));
  // Disk areas in grid cells: pi r^2 / 0.01^2.
  CHECK(double(da.visible) == Approx(kPi * 2.0 / 1e-4).epsilon(0.005));
  CHECK(double(db.visible) == Approx(kPi * 8.0 / 1e-4).epsilon(0.005));
  int64_t inter = 0;
  for (size_t w = 0; w < ba.size(); ++w) inter += __builtin_popcountll(ba[w] & bb[w]);
  CHECK(inter == da.visible);  // nested
  const double iou = double(inter) / double(da.visible + db.visible - inter);
  CHECK(iou == Approx(0.25).epsilon(0.01));
}

TEST_CASE("pairs: ten-camera rig, accepted and rejected pairs and why", "[pairs]") {
  const Rig rig = ten_camera_rig();
  auto pc = enhance::construct_pairs(rig.cameras, rig.points, quiet_params());
  REQUIRE(pc.is_ok());
  const gs::CameraSet& cams = rig.cameras;
  for (size_t i = 0; i < cams.cameras.size(); ++i) {
    INFO(cams.cameras[i].name);
    CHECK(pc->depth[i].visible == 1331);  // its own object only
    CHECK(pc->depth[i].median == Approx(rig.distance[i]).epsilon(1e-12));
  }
  CHECK(names(cams, pc->close_set) == std::vector<std::string>{"cA", "cB", "cC", "cD"});
  CHECK(names(cams, pc->far_set) == std::vector<std::string>{"fA", "fB", "fC", "fD"});
  std::set<std::string> accepted;
  for (const PairMeasure& m : pc->candidates) accepted.insert(pair_name(cams, m));
  CHECK(accepted == std::set<std::string>{"cA-fB", "cA-fD", "cB-fB", "cC-fB", "cD-fD"});
  // Each criterion on its own over the 16 close x far pairs (table above).
  CHECK(pc->candidate_counts.pairs == 16);
  CHECK(pc->candidate_counts.depth_ratio == 11);
  CHECK(pc->candidate_counts.iou == 12);
  CHECK(pc->candidate_counts.angle == 10);
  CHECK(pc->candidate_counts.all == 5);
  for (const PairMeasure& m : pc->candidates) {
    INFO(pair_name(cams, m));
    CHECK(m.depth_ratio ==
          Approx(rig.distance[size_t(m.far)] / rig.distance[size_t(m.close)]).epsilon(1e-12));
    CHECK(m.iou == 1.0);
    CHECK(m.pair_score == Approx(std::log2(m.depth_ratio)).epsilon(1e-12));
  }
  // Angles of the accepted pairs: differences of phi.
  std::map<std::string, double> angle;
  for (const PairMeasure& m : pc->candidates) angle[pair_name(cams, m)] = m.angle_deg;
  CHECK(angle["cA-fB"] == Approx(30).epsilon(1e-9));
  CHECK(angle["cA-fD"] == Approx(20).epsilon(1e-9));
  CHECK(angle["cB-fB"] == Approx(42).epsilon(1e-9));
  CHECK(angle["cC-fB"] == Approx(15).epsilon(1e-9));
  CHECK(angle["cD-fD"] == Approx(20).epsilon(1e-9));

  // Split 30/40/30 and the training views (the pool has 3 < 16: all three, farthest first from
  // the pool centroid: fC, 100 units away, then fB (10009.0 squared) before fD (10006.0)).
  CHECK(names(cams, pc->test_pool) == std::vector<std::string>{"cA", "cB", "cC"});
  CHECK(names(cams, pc->discarded) == std::vector<std::string>{"cD", "m1", "m2", "fA"});
  CHECK(names(cams, pc->train_pool) == std::vector<std::string>{"fB", "fC", "fD"});
  CHECK(names(cams, pc->training) == std::vector<std::string>{"fC", "fB", "fD"});
  // Evaluation pairs: cA takes fD (log2 3.5 > log2 2.5), cB and cC take fB.
  std::vector<std::string> eval;
  for (const PairMeasure& m : pc->eval_pairs) eval.push_back(pair_name(cams, m));
  CHECK(eval == std::vector<std::string>{"cA-fD", "cB-fB", "cC-fB"});
  CHECK(pc->unpaired_tests.empty());
  CHECK(pc->eval_counts.pairs == 9);
  CHECK(pc->eval_counts.all == 4);  // cA-fB, cA-fD, cB-fB, cC-fB
  CHECK(enhance::check_pairs_found(*pc, quiet_params()).is_ok());

  // Scene score: the five factors from the definitions (percentiles by full sort here).
  std::vector<double> d, d10, span;
  for (size_t i = 0; i < cams.cameras.size(); ++i) {
    const Eigen::Vector3d c = cams.cameras[i].center();
    const Eigen::Vector3d v = cams.cameras[i].R.row(2).transpose();
    std::vector<double> z;
    for (const Eigen::Vector3d& x : rig.points)
      if ((x - c).dot(v) > (x - c).norm() / std::sqrt(3.0))  // cos(atan(sqrt 2)) = 1 / sqrt 3
        z.push_back((x - c).dot(v));
    REQUIRE(z.size() == 1331);
    d.push_back(rig.distance[i]);
    d10.push_back(sorted_percentile(z, 10));
    span.push_back(sorted_percentile(z, 90) / d10.back());
  }
  double mu = 0, var = 0, mean_span = 0;
  for (size_t i = 0; i < d.size(); ++i) mu += d[i] / 10, mean_span += span[i] / 10;
  for (double x : d) var += (x - mu) * (x - mu) / 10;
  const double near =
      *std::max_element(d10.begin(), d10.end()) / *std::min_element(d10.begin(), d10.end());
  const double expect = std::sqrt(var) / mu * (1 + std::log(1 + mean_span)) *
                        (1 + std::log(1 + near)) * (1 + std::log(1 + 1 / 2.0)) * std::log(1 + 5.0);
  CHECK(pc->score.candidates == 5);
  CHECK(pc->score.closeness == Approx(0.5).epsilon(1e-12));
  CHECK(pc->score.near_ratio == Approx(near).epsilon(1e-12));
  CHECK(pc->score.mean_span == Approx(mean_span).epsilon(1e-12));
  CHECK(pc->score.score == Approx(expect).epsilon(1e-12));
}

TEST_CASE("pairs: thresholds move pairs in and out, no-pair errors give the counts", "[pairs]") {
  const Rig rig = ten_camera_rig();
  PairParams p = quiet_params();
  SECTION("a lower ratio admits cB-fA, cC-fA and cD-fB") {
    p.min_depth_ratio = 1.5;
    auto pc = enhance::construct_pairs(rig.cameras, rig.points, p);
    REQUIRE(pc.is_ok());
    std::set<std::string> accepted;
    for (const PairMeasure& m : pc->candidates) accepted.insert(pair_name(rig.cameras, m));
    CHECK(accepted == std::set<std::string>{"cA-fB", "cA-fD", "cB-fA", "cB-fB", "cC-fA", "cC-fB",
                                            "cD-fB", "cD-fD"});
  }
  SECTION("angles 0-70 admit cA-fA, cB-fD (8 deg) and cC-fD (65 deg)") {
    p.min_angle_deg = 0;
    p.max_angle_deg = 70;
    auto pc = enhance::construct_pairs(rig.cameras, rig.points, p);
    REQUIRE(pc.is_ok());
    std::set<std::string> accepted;
    for (const PairMeasure& m : pc->candidates) accepted.insert(pair_name(rig.cameras, m));
    CHECK(accepted == std::set<std::string>{"cA-fA", "cA-fB", "cA-fD", "cB-fB", "cB-fD", "cC-fB",
                                            "cC-fD", "cD-fD"});
  }
  SECTION("ratio 4 leaves no candidate: score 0 and an error with the counts") {
    p.min_depth_ratio = 4;
    auto pc = enhance::construct_pairs(rig.cameras, rig.points, p);
    REQUIRE(pc.is_ok());
    CHECK(pc->candidates.empty());
    CHECK(pc->score.score == 0);
    const Status s = enhance::check_pairs_found(*pc, p);
    REQUIRE_FALSE(s.is_ok());
    CHECK(s.message() ==
          "no candidate close-up pair (scene score 0): of 16 pairs (4 close x 4 far): depth ratio "
          ">= 4 holds for 0, IoU >= 0.4 for 12, angle in [10, 60] deg for 10; all three for 0");
  }
  SECTION("one training view (fC, object B) pairs with no test frame") {
    p.training_views = 1;
    auto pc = enhance::construct_pairs(rig.cameras, rig.points, p);
    REQUIRE(pc.is_ok());
    CHECK(names(rig.cameras, pc->training) == std::vector<std::string>{"fC"});
    CHECK(pc->eval_pairs.empty());
    CHECK(pc->unpaired_tests.size() == 3);
    const Status s = enhance::check_pairs_found(*pc, p);
    REQUIRE_FALSE(s.is_ok());
    CHECK(s.message().find("5 candidate pairs, but no evaluation pair between the 3 test "
                           "candidates and the 1 training views: of 3 pairs (3 test x 1 "
                           "training)") == 0);
    CHECK(s.message().find("IoU >= 0.4 for 0") != std::string::npos);
  }
  SECTION("a camera that sees no point is set aside, the rest unchanged") {
    Rig blind = rig;
    blind.cameras.cameras.push_back(rig_camera("z_blind", {0, 0, -3}, {0, 0, -1}));
    auto pc = enhance::construct_pairs(blind.cameras, blind.points, p);
    REQUIRE(pc.is_ok());
    CHECK(pc->no_depth == std::vector<int>{10});
    CHECK(pc->depth[10].visible == 0);
    CHECK(pc->by_depth.size() == 10);
    CHECK(pc->candidates.size() == 5);
    CHECK(pc->eval_pairs.size() == 3);
    const std::string json = enhance::split_json(blind.cameras, *pc, p, "blind", 2662);
    CHECK(json.find("\"cameras_without_points\": 1") != std::string::npos);
  }
  SECTION("a seeded start is deterministic") {
    p.seed = 7;
    auto a = enhance::construct_pairs(rig.cameras, rig.points, p);
    auto b = enhance::construct_pairs(rig.cameras, rig.points, p);
    REQUIRE(a.is_ok());
    REQUIRE(b.is_ok());
    CHECK(a->training == b->training);
    CHECK(a->training.size() == 3);
  }
  SECTION("bad parameters and too few cameras are errors") {
    p.min_iou = 1.5;
    CHECK_FALSE(enhance::construct_pairs(rig.cameras, rig.points, p).is_ok());
    p = quiet_params();
    p.min_angle_deg = 50;
    p.max_angle_deg = 40;
    CHECK_FALSE(enhance::construct_pairs(rig.cameras, rig.points, p).is_ok());
    gs::CameraSet three;
    three.cameras.assign(rig.cameras.cameras.begin(), rig.cameras.cameras.begin() + 3);
    auto few = enhance::construct_pairs(three, rig.points, quiet_params());
    REQUIRE_FALSE(few.is_ok());
    CHECK(few.status().message() ==
          "pair construction: 3 of 3 cameras see any 3D point; the 30/30 test/training split "
          "needs at least 4 of them");
  }
}

TEST_CASE("pairs: split proportions and 16 training views by farthest-point sampling", "[pairs]") {
  // 100 cameras looking along +z at the cube from distances 2.00 .. 3.98 (step 0.02), with a
  // lateral offset on a 10 x 10 grid so that positions differ in x and y too.
  gs::CameraSet cams;
  std::vector<Eigen::Vector3d> pts;
  add_cube(&pts, kA);
  for (int k = 0; k < 100; ++k) {
    char name[16];
    std::snprintf(name, sizeof name, "f%03d", k);
    const Eigen::Vector3d c(0.05 * (k % 10) - 0.225, 0.05 * (k / 10) - 0.225, -(2.0 + 0.02 * k));
    cams.cameras.push_back(rig_camera(name, c, {0, 0, 1}));
  }
  auto pc = enhance::construct_pairs(cams, pts, quiet_params());
  REQUIRE(pc.is_ok());
  CHECK(pc->close_set.size() == 40);
  CHECK(pc->far_set.size() == 40);
  CHECK(pc->test_pool.size() == 30);
  CHECK(pc->discarded.size() == 40);
  CHECK(pc->train_pool.size() == 30);
  CHECK(pc->test_pool.front() == 0);
  CHECK(pc->test_pool.back() == 29);
  CHECK(pc->train_pool.front() == 70);
  CHECK(pc->train_pool.back() == 99);
  REQUIRE(pc->training.size() == 16);
  std::set<int> unique(pc->training.begin(), pc->training.end());
  CHECK(unique.size() == 16);
  for (int i : pc->training) CHECK(i >= 70);
  // All axes are parallel: every pair fails the angle test, so there is no candidate.
  CHECK(pc->candidate_counts.angle == 0);
  CHECK(pc->candidates.empty());
  // One camera per task, so one thread gives bit-identical depths and the same sets.
  ThreadPool::set_global_threads(1);
  auto one = enhance::construct_pairs(cams, pts, quiet_params());
  ThreadPool::set_global_threads(0);
  REQUIRE(one.is_ok());
  for (size_t i = 0; i < cams.cameras.size(); ++i) {
    CHECK(one->depth[i].median == pc->depth[i].median);
    CHECK(one->depth[i].p10 == pc->depth[i].p10);
    CHECK(one->depth[i].visible == pc->depth[i].visible);
  }
  CHECK(one->training == pc->training);
  CHECK(one->candidate_counts.iou == pc->candidate_counts.iou);

  // Farthest-point sampling on its own: the 8 corners of the unit cube (indices 20..27, corner c
  // at (c & 1, c >> 1 & 1, c >> 2 & 1)) plus 20 points near its centre, drifting to +x, -y, -z so
  // the centroid is off-centre that way. 8 samples are exactly the corners; the default start is
  // the corner farthest from the centroid, (0, 1, 1) = index 26, and the second is the opposite
  // corner (1, 0, 0) = index 21.
  std::vector<Eigen::Vector3d> pos;
  for (int k = 0; k < 20; ++k) pos.emplace_back(0.5 + 0.01 * k, 0.5 - 0.003 * k, 0.5 - 0.005 * k);
  for (int c = 0; c < 8; ++c) pos.emplace_back(c & 1, (c >> 1) & 1, (c >> 2) & 1);
  const std::vector<int> fps = enhance::farthest_point_sampling(pos, 8, std::nullopt);
  CHECK(std::set<int>(fps.begin(), fps.end()) == std::set<int>{20, 21, 22, 23, 24, 25, 26, 27});
  CHECK(fps[0] == 26);
  CHECK(fps[1] == 21);
  // With a seed the start is the seeded pick; 9 samples from a centre start still cover the
  // corners (the centre point is the 9th or the 1st).
  const std::vector<int> seeded = enhance::farthest_point_sampling(pos, 9, uint64_t(3));
  CHECK(seeded == enhance::farthest_point_sampling(pos, 9, uint64_t(3)));
  std::set<int> corners(seeded.begin(), seeded.end());
  for (int c = 20; c < 28; ++c) CHECK(corners.count(c) == 1);
  CHECK(enhance::farthest_point_sampling(pos, 100, std::nullopt).size() == pos.size());
}

// ---- points3D reader / writer
// --------------------------------------------------------------------

template <typename T>
void put(std::vector<uint8_t>* b, T v) {
  const size_t at = b->size();
  b->resize(at + sizeof(T));
  std::memcpy(b->data() + at, &v, sizeof(T));
}

TEST_CASE("pairs: points3D text and binary readers agree, bad files are named errors", "[pairs]") {
  test::TempDir tmp("pairs-points");
  const std::string txt =
      "# 3D point list\n"
      "1 0.5 -1.25 3 255 0 10 0.75 4 12 7 3\n"
      "\n"
      "9 1e3 2 -3.5 1 2 3 0 \n";
  REQUIRE(write_file_atomic(tmp.file("points3D.txt"), txt).is_ok());
  auto t = gs::load_colmap_points_text(tmp.file("points3D.txt"));
  REQUIRE(t.is_ok());
  REQUIRE(t->size() == 2);
  CHECK(t->ids == std::vector<int64_t>{1, 9});
  CHECK(t->xyz[0] == Eigen::Vector3d(0.5, -1.25, 3));
  CHECK(t->xyz[1] == Eigen::Vector3d(1000, 2, -3.5));
  CHECK(t->rgb == std::vector<uint8_t>{255, 0, 10, 1, 2, 3});
  CHECK(t->error == std::vector<double>{0.75, 0});
  CHECK(t->track_offsets == std::vector<uint64_t>{0, 2, 2});
  CHECK(t->track_image_ids == std::vector<uint32_t>{4, 7});
  CHECK(t->track_point2d == std::vector<uint32_t>{12, 3});

  // The same points as points3D.bin.
  std::vector<uint8_t> bin;
  put<uint64_t>(&bin, 2);
  put<uint64_t>(&bin, 1);
  for (double v : {0.5, -1.25, 3.0}) put(&bin, v);
  for (uint8_t c : {255, 0, 10}) put(&bin, c);
  put(&bin, 0.75);
  put<uint64_t>(&bin, 2);
  for (uint32_t v : {4u, 12u, 7u, 3u}) put(&bin, v);
  put<uint64_t>(&bin, 9);
  for (double v : {1000.0, 2.0, -3.5}) put(&bin, v);
  for (uint8_t c : {1, 2, 3}) put(&bin, c);
  put(&bin, 0.0);
  put<uint64_t>(&bin, 0);
  REQUIRE(write_file_atomic(tmp.file("points3D.bin"), bin.data(), bin.size()).is_ok());
  auto b = gs::load_colmap_points(tmp.path);  // .bin preferred
  REQUIRE(b.is_ok());
  CHECK(b->source == tmp.file("points3D.bin"));
  CHECK(b->ids == t->ids);
  CHECK(b->xyz == t->xyz);
  CHECK(b->rgb == t->rgb);
  CHECK(b->error == t->error);
  CHECK(b->track_offsets == t->track_offsets);
  CHECK(b->track_image_ids == t->track_image_ids);
  CHECK(b->track_point2d == t->track_point2d);

  // Writer round trip.
  CHECK_FALSE(gs::save_colmap_points_text(*b, tmp.file("out/points3D.txt")).is_ok());  // no folder
  fs::create_directories(tmp.file("out"));
  REQUIRE(gs::save_colmap_points_text(*b, tmp.file("out/points3D.txt")).is_ok());
  auto rt = gs::load_colmap_points(tmp.file("out"));
  REQUIRE(rt.is_ok());
  CHECK(rt->xyz == t->xyz);
  CHECK(rt->track_point2d == t->track_point2d);

  // Errors name the file, the line or point, the field and what was found.
  const auto text_error = [&](const std::string& body) {
    REQUIRE(write_file_atomic(tmp.file("bad.txt"), body).is_ok());
    auto r = gs::load_colmap_points_text(tmp.file("bad.txt"));
    REQUIRE_FALSE(r.is_ok());
    return r.status().message();
  };
  const std::string bad = tmp.file("bad.txt");
  CHECK(text_error("# c\n1 0 0 0 256 0 0 0\n") ==
        bad + " line 2: R: expected an integer 0..255, found '256'");
  CHECK(text_error("1 0 0 0 1 2 3 0 5\n") ==
        bad + " line 1: TRACK[0] POINT2D_IDX: expected an unsigned integer, found 'end of line'");
  CHECK(text_error("1 0 zero 0 1 2 3 0\n") == bad + " line 1: Y: expected a number, found 'zero'");
  CHECK(text_error("1 0 0 0 1 2 3\n") == bad +
                                             " line 1: ERROR: expected a number, found 'end "
                                             "of line'");
  CHECK(text_error("1 0 nan 0 1 2 3 0\n") ==
        bad + ": point 1: X Y Z: expected finite numbers, found a NaN or infinity");
  CHECK(text_error("4 0 0 0 1 2 3 0\n4 1 1 1 1 2 3 0\n") == bad + ": POINT3D_ID 4 appears twice");

  const auto bin_error = [&](const std::vector<uint8_t>& bytes) {
    REQUIRE(write_file_atomic(tmp.file("bad.bin"), bytes.data(), bytes.size()).is_ok());
    auto r = gs::load_colmap_points_binary(tmp.file("bad.bin"));
    REQUIRE_FALSE(r.is_ok());
    return r.status().message();
  };
  std::vector<uint8_t> lying = bin;
  const uint64_t huge = uint64_t(1) << 60;
  std::memcpy(lying.data(), &huge, 8);
  CHECK(bin_error(lying).find("point count 1152921504606846976 needs at least 51 bytes each") !=
        std::string::npos);
  std::vector<uint8_t> long_track = bin;
  std::memcpy(long_track.data() + 8 + 51 - 8, &huge, 8);  // point #0's track length
  CHECK(bin_error(long_track).find("point #0 (id 1): track length 1152921504606846976") !=
        std::string::npos);
  std::vector<uint8_t> cut(bin.begin(), bin.end() - 5);
  CHECK(bin_error(cut).find("point #1: file truncated") != std::string::npos);
  for (size_t len = 0; len < bin.size(); ++len) {  // every truncation is an error, never a crash
    REQUIRE(write_file_atomic(tmp.file("cut.bin"), bin.data(), len).is_ok());
    CHECK_FALSE(gs::load_colmap_points_binary(tmp.file("cut.bin")).is_ok());
  }
  std::vector<uint8_t> extra = bin;
  extra.push_back(0);
  CHECK(bin_error(extra) == tmp.file("bad.bin") + ": 1 unexpected bytes after 2 points");
  CHECK(gs::load_colmap_points(tmp.file("nowhere"))
            .status()
            .message()
            .find("no points3D.bin or points3D.txt") != std::string::npos);
}

// The rig as a COLMAP binary model (cameras.bin, images.bin, points3D.bin) in `folder`, byte
// layouts as in gs/cameras/cameras_colmap_binary.cpp and gs/cameras/colmap_points.h.
void write_rig_binary(const Rig& rig, const std::string& folder) {
  fs::create_directories(folder);
  std::vector<uint8_t> cams, images, points;
  put<uint64_t>(&cams, 1);
  put<uint32_t>(&cams, 1);
  put<int32_t>(&cams, 1);  // PINHOLE
  put<uint64_t>(&cams, 100);
  put<uint64_t>(&cams, 100);
  for (double v : {50.0, 50.0, 50.0, 50.0}) put(&cams, v);
  put<uint64_t>(&images, rig.cameras.cameras.size());
  for (size_t i = 0; i < rig.cameras.cameras.size(); ++i) {
    const gs::Camera& c = rig.cameras.cameras[i];
    put<uint32_t>(&images, uint32_t(i) + 1);
    const Eigen::Vector4d q = gs::quaternion_wxyz_from_rotation(c.R);
    for (int k = 0; k < 4; ++k) put(&images, q[k]);
    for (int k = 0; k < 3; ++k) put(&images, c.t[k]);
    put<uint32_t>(&images, 1);
    images.insert(images.end(), c.name.begin(), c.name.end());
    images.push_back(0);
    put<uint64_t>(&images, 0);
  }
  put<uint64_t>(&points, rig.points.size());
  for (size_t i = 0; i < rig.points.size(); ++i) {
    put<uint64_t>(&points, i + 1);
    for (int k = 0; k < 3; ++k) put(&points, rig.points[i][k]);
    for (uint8_t c : {7, 8, 9}) put(&points, c);
    put(&points, 0.25);
    put<uint64_t>(&points, 1);
    put<uint32_t>(&points, 1);
    put<uint32_t>(&points, uint32_t(i));
  }
  REQUIRE(write_file_atomic(folder + "/cameras.bin", cams.data(), cams.size()).is_ok());
  REQUIRE(write_file_atomic(folder + "/images.bin", images.data(), images.size()).is_ok());
  REQUIRE(write_file_atomic(folder + "/points3D.bin", points.data(), points.size()).is_ok());
}

TEST_CASE("pairs: COLMAP text and binary models give the in-memory construction", "[pairs]") {
  test::TempDir tmp("pairs-colmap");
  const Rig rig = ten_camera_rig();
  write_rig_scene(rig, tmp.file("text"), false);
  write_rig_binary(rig, tmp.file("binary/sparse/0"));
  auto mem = enhance::construct_pairs(rig.cameras, rig.points, quiet_params());
  REQUIRE(mem.is_ok());
  for (const char* kind : {"text", "binary"}) {
    INFO(kind);
    auto folder = gs::find_colmap_model_folder(tmp.file(kind));
    REQUIRE(folder.is_ok());
    CHECK(*folder == tmp.file(std::string(kind) + "/sparse/0"));
    auto cams = gs::load_colmap_sparse(*folder);
    REQUIRE(cams.is_ok());
    auto pts = gs::load_colmap_points(*folder);
    REQUIRE(pts.is_ok());
    REQUIRE(pts->size() == rig.points.size());
    auto disk = enhance::construct_pairs(*cams, pts->xyz, quiet_params());
    REQUIRE(disk.is_ok());
    CHECK(names(*cams, disk->training) == names(rig.cameras, mem->training));
    CHECK(disk->candidates.size() == mem->candidates.size());
    REQUIRE(disk->eval_pairs.size() == mem->eval_pairs.size());
    for (size_t k = 0; k < disk->eval_pairs.size(); ++k) {
      CHECK(pair_name(*cams, disk->eval_pairs[k]) == pair_name(rig.cameras, mem->eval_pairs[k]));
      CHECK(disk->eval_pairs[k].depth_ratio ==
            Approx(mem->eval_pairs[k].depth_ratio).epsilon(1e-12));
      CHECK(disk->eval_pairs[k].angle_deg == Approx(mem->eval_pairs[k].angle_deg).epsilon(1e-9));
    }
    CHECK(disk->score.score == Approx(mem->score.score).epsilon(1e-12));
  }
}

TEST_CASE("macro bench pairs end to end, then bench run reads the split", "[pairs][cli]") {
  test::TempDir tmp("pairs-cli");
  const Rig rig = ten_camera_rig();
  const std::string scene = tmp.file("root/rig");
  write_rig_scene(rig, scene, true);
  const std::string exe = test::macro_exe();
  const auto sh = [&](const std::string& args) {
    return test::run_command(exe + " bench " + args + " > " + tmp.file("out.txt") + " 2>&1");
  };
  const auto out = [&]() { return *read_text_file(tmp.file("out.txt")); };
  REQUIRE(sh("pairs --scene " + scene + "/ --out " + scene + "/split.json --copy-gt --quiet") == 0);
  INFO(out());
  CHECK(out().find("3 training views, 3 close-up pairs") != std::string::npos);
  auto split = gs::load_closeup_split(scene + "/split.json");
  REQUIRE(split.is_ok());
  CHECK(split->scene == "rig");
  CHECK(split->training_frames == std::vector<std::string>{"c8_fC", "c7_fB", "c9_fD"});
  REQUIRE(split->closeup_eval_pairs.size() == 3);
  CHECK(split->closeup_eval_pairs[0].closeup_frame == "c0_cA");
  CHECK(split->closeup_eval_pairs[0].training_frame == "c9_fD");
  CHECK(split->closeup_eval_pairs[0].depth_ratio == Approx(3.5).epsilon(1e-12));
  CHECK(split->closeup_eval_pairs[0].iou == 1.0);
  CHECK(split->closeup_eval_pairs[0].angle_deg == Approx(20).epsilon(1e-9));
  CHECK(split->closeup_eval_pairs[1].training_frame == "c7_fB");
  CHECK(split->closeup_eval_pairs[2].closeup_frame == "c2_cC");
  // Every non-training frame is kept out of the reference pool.
  CHECK(split->closeup_frames.size() == 7);
  // The split's close-up poses are the COLMAP poses.
  REQUIRE(split->closeups.cameras.size() == 3);
  for (const gs::Camera& c : split->closeups.cameras) {
    const gs::Camera& ref = rig.cameras.cameras[size_t(rig.cameras.index_of(c.name))];
    CHECK((c.center() - ref.center()).norm() < 1e-9);
    CHECK((c.R - ref.R).norm() < 1e-9);
    CHECK(c.fx == 50);
  }
  CHECK(file_exists(scene + "/closeup_gt/c1_cB"));

  // bench run scores the three pairs (3dgs).
  REQUIRE(sh("run --root " + tmp.file("root") + " --methods 3dgs --results " + tmp.file("r.jsonl") +
             " --quiet") == 0);
  std::ifstream f(tmp.file("r.jsonl"));
  int ok = 0, lines = 0;
  for (std::string l; std::getline(f, l); ++lines)
    ok += l.find("\"status\":\"ok\"") != std::string::npos;
  CHECK(lines == 3);
  CHECK(ok == 3);

  // Bad input: clear errors, exit code 1.
  CHECK(sh("pairs --scene " + tmp.file("nowhere") + " --out " + tmp.file("x.json")) == 1);
  CHECK(out().find("scene folder not found") != std::string::npos);
  fs::remove(scene + "/sparse/0/points3D.txt");
  CHECK(sh("pairs --scene " + scene + " --out " + tmp.file("x.json") + " --quiet") == 1);
  CHECK(out().find("no points3D.bin or points3D.txt") != std::string::npos);
  write_rig_scene(rig, scene, false);
  CHECK(sh("pairs --scene " + scene + " --out " + tmp.file("x.json") +
           " --min-depth-ratio 4 --quiet") == 1);
  CHECK(out().find("no candidate close-up pair (scene score 0): of 16 pairs (4 close x 4 far): "
                   "depth ratio >= 4 holds for 0") != std::string::npos);
  CHECK(sh("pairs --scene " + scene + " --out " + tmp.file("x.json") + " --angle 60,10") == 1);
  CHECK(out().find("--angle") != std::string::npos);
  CHECK(sh("pairs --scene " + scene + " --out " + tmp.file("x.json") + " --seed -3") == 1);
  CHECK_FALSE(file_exists(tmp.file("x.json")));
}

}  // namespace
}  // namespace macro
