// Close-up benchmark pairs from a COLMAP scene: the paper's appendix D (DL3DV-Closeup
// construction), from per-camera depths to a split JSON that `macro bench run` reads.
//
// Legend: N cameras (those of the model), M sparse 3D points, W = ceil(M / 64) bitset words.
//
// Steps (docs/benchmark.md "Pair construction" gives every choice the paper leaves open):
//  1. Visible set V_i (D.2): the points x with <x - c_i, v_i> > 0 and
//     <x - c_i, v_i> / |x - c_i| > cos(theta_i / 2), where c_i is the camera centre, v_i its unit
//     optical axis and theta_i its diagonal field of view, tan(theta_i / 2) =
//     sqrt((w / 2fx)^2 + (h / 2fy)^2). A cone, not the image rectangle; no occlusion, distortion
//     ignored. Cameras with an empty V_i get no depth and take no further part.
//  2. Depths along v_i over V_i: median d_i and the 10th / 90th percentiles (linear interpolation
//     between order statistics, numpy's default), span s_i = d90 / d10.
//  3. Candidate pairs (D.3): close set = the first floor(0.4 n) cameras by d_i, far set = the last
//     floor(0.4 n) (n = cameras with a depth; ties by name). A pair (close i, far j) is a candidate
//     if d_j / d_i >= 2, IoU(V_i, V_j) = |V_i & V_j| / |V_i | V_j| >= 0.4 and the angle between
//     the optical axes is in [10, 60] degrees (bounds inclusive).
//  4. Scene score S (D.4) over the cameras with a depth; S = 0 when there is no candidate.
//  5. Split (D.5): the last floor(0.3 n) by d_i are the training pool, the first floor(0.3 n) the
//     test candidates, the middle is discarded. Training views: farthest-point sampling on camera
//     centres within the pool (start: the pool camera farthest from the pool's centroid, or, given
//     a seed, a seeded random one).
//  6. Evaluation pairs: each test candidate is paired with the training view that passes the three
//     criteria and has the highest pair_score = IoU * log2(depth ratio); a test candidate with no
//     such view is left out. At most one pair per close-up frame.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"

namespace macro::enhance {

// Tuning constants of appendix D, named once.
struct PairParams {
  int training_views = 16;                            // N of D.5
  double min_depth_ratio = 2.0;                       // d_far / d_close
  double min_iou = 0.4;                               // of the visible point sets
  double min_angle_deg = 10.0, max_angle_deg = 60.0;  // between optical axes, inclusive
  double close_fraction = 0.4, far_fraction = 0.4;    // candidate sets (D.3)
  double test_fraction = 0.3, train_fraction = 0.3;   // split (D.5); the middle is discarded
  std::optional<uint64_t> seed;  // farthest-point sampling start (none: farthest from centroid)
  bool progress = true;          // progress lines on stderr for big scenes
};

struct CameraDepth {
  int64_t visible = 0;                            // |V_i|
  double median = 0, p10 = 0, p90 = 0, span = 0;  // d_i, d_i^10, d_i^90, s_i (0 when visible == 0)
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit optical axis v_i (world)
  double half_fov_deg = 0;                          // theta_i / 2 (diagonal)
};

struct PairMeasure {
  int close = -1, far = -1;  // camera indices
  double depth_ratio = 0, iou = 0, angle_deg = 0, pair_score = 0;
  bool ratio_ok = false, iou_ok = false, angle_ok = false;
  bool accepted() const { return ratio_ok && iou_ok && angle_ok; }
};

// How many of `pairs` pairs meet each criterion on its own, and all three together.
struct CriteriaCounts {
  int64_t pairs = 0, depth_ratio = 0, iou = 0, angle = 0, all = 0;
  void add(const PairMeasure& m);
  // "of 16 pairs (4 close x 4 far): depth ratio >= 2 holds for 10, IoU >= 0.4 for 3, angle in
  // [10, 60] deg for 16; all three for 0"
  std::string describe(const std::string& what, const PairParams& p) const;
};

struct SceneScore {
  double depth_cv = 0;     // sigma(d) / mu(d), population sigma
  double mean_span = 0;    // s-bar
  double near_ratio = 0;   // max d10 / min d10
  double closeness = 0;    // 1 / min d (scene units)
  int64_t candidates = 0;  // N_cand
  double score = 0;        // S
};

struct PairConstruction {
  std::vector<CameraDepth> depth;       // [N] in camera order
  std::vector<int> by_depth;            // cameras with a depth, ascending d_i (ties by name)
  std::vector<int> no_depth;            // cameras that see no point
  std::vector<int> close_set, far_set;  // D.3
  std::vector<PairMeasure> candidates;  // accepted close x far pairs, (close, far) order
  CriteriaCounts candidate_counts;      // over close x far
  SceneScore score;
  std::vector<int> test_pool, discarded, train_pool;  // D.5, each ascending d_i
  std::vector<int> training;                          // farthest-point order
  std::vector<PairMeasure> eval_pairs;                // one per kept close-up, by close-up name
  CriteriaCounts eval_counts;                         // over test candidates x training views
  std::vector<int> unpaired_tests;  // test candidates with no accepted training view
};

// The whole construction. `points` are world positions (gs::ColmapPoints::xyz). Errors: too few
// cameras with a depth for the split (the message gives the counts), invalid params. Finding no
// candidate or no evaluation pair is not an error here (see check_pairs_found).
Result<PairConstruction> construct_pairs(const gs::CameraSet& cameras,
                                         const std::vector<Eigen::Vector3d>& points,
                                         const PairParams& params);

// An error naming the parameter, what was expected and what was found, for invalid params.
Status check_pair_params(const PairParams& params);

// An error naming the criterion counts when there is no candidate pair or no evaluation pair.
Status check_pairs_found(const PairConstruction& pc, const PairParams& params);

// Pieces, exposed for tests.
CameraDepth camera_depth(const gs::Camera& camera, const std::vector<Eigen::Vector3d>& points,
                         std::vector<uint64_t>* visible_bits /* [W], may be null */);
double percentile_linear(std::vector<double>& values, double p);  // reorders values; p in [0,100]
// Indices into `positions` in selection order; `count` clamped to positions.size().
std::vector<int> farthest_point_sampling(const std::vector<Eigen::Vector3d>& positions, int count,
                                         std::optional<uint64_t> seed);
double pair_score(double iou, double depth_ratio);  // iou * log2(depth_ratio)

// The split JSON (docs/spec/macro-method.md §7 fields plus "closeup_frames" and
// "pair_construction"): scene, data_factor 1, intrinsics (of the first close-up, see docs),
// training_frames (sampling order), closeup_frames (every camera that is not a training view, so
// `bench run` draws references from the training views only), closeup_eval_pairs, closeup_poses
// (OpenGL c2w), counts, and a pair_construction record (parameters, counts, scene score).
std::string split_json(const gs::CameraSet& cameras, const PairConstruction& pc,
                       const PairParams& params, const std::string& scene_name, int64_t num_points);

// ---- One scene from disk (many scenes ranked by S: enhance/datasets/scene_ranking.h) ----------

// A scene folder loaded and constructed (not yet checked for pairs, not written).
struct SceneSplit {
  std::string name;    // the split's "scene"
  std::string folder;  // the scene folder given
  std::string model;   // its COLMAP model folder (., sparse/0, sparse, colmap/sparse/0)
  gs::CameraSet cameras;
  int64_t num_points = 0;
  PairConstruction pc;
};

// Finds the COLMAP model in `folder`, reads cameras, images and points3D (text or binary) and
// runs construct_pairs. Errors name the file (no model, bad file, no points, too few cameras).
Result<SceneSplit> load_and_construct(const std::string& folder, const std::string& name,
                                      const PairParams& params);

// Writes split_json atomically to `out_path`; with `copy_gt`, also copies each evaluation
// close-up FOLDER/images/<frame> to closeup_gt/<frame> beside the split (atomically).
Status write_scene_split(const SceneSplit& scene, const PairParams& params,
                         const std::string& out_path, bool copy_gt);

}  // namespace macro::enhance
