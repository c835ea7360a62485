// Appendix D pair construction (see pair_construction.h for the steps and docs/benchmark.md for the
// choices the paper leaves open).
#include "enhance/datasets/pair_construction.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/text.h"
#include "attention/runtime/thread_pool.h"
#include "gs/cameras/colmap_points.h"

namespace macro::enhance {
namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

// floor(fraction * n), robust to 0.3 * 10 = 2.9999999999999996.
int fraction_count(double fraction, size_t n) {
  return int(std::floor(fraction * double(n) + 1e-9));
}

int64_t popcount_and(const uint64_t* a, const uint64_t* b, size_t words) {
  int64_t n = 0;
  for (size_t w = 0; w < words; ++w) n += std::popcount(a[w] & b[w]);
  return n;
}

// Pair measures from the precomputed depths and visibility bitsets.
PairMeasure measure(int close, int far, const std::vector<CameraDepth>& depth,
                    const std::vector<uint64_t>& bits, size_t words, const PairParams& p) {
  PairMeasure m;
  m.close = close;
  m.far = far;
  const CameraDepth& a = depth[size_t(close)];
  const CameraDepth& b = depth[size_t(far)];
  m.depth_ratio = b.median / a.median;
  const int64_t inter =
      popcount_and(&bits[size_t(close) * words], &bits[size_t(far) * words], words);
  const int64_t uni = a.visible + b.visible - inter;
  m.iou = uni > 0 ? double(inter) / double(uni) : 0.0;
  m.angle_deg = std::acos(std::clamp(a.axis.dot(b.axis), -1.0, 1.0)) * kRadToDeg;
  m.ratio_ok = m.depth_ratio >= p.min_depth_ratio;
  m.iou_ok = m.iou >= p.min_iou;
  m.angle_ok = m.angle_deg >= p.min_angle_deg && m.angle_deg <= p.max_angle_deg;
  m.pair_score = pair_score(m.iou, m.depth_ratio);
  return m;
}

}  // namespace

Status check_pair_params(const PairParams& p) {
  auto bad = [](const std::string& what) { return Status::error("pair construction: " + what); };
  if (p.training_views < 1)
    return bad("training views: expected >= 1, found " + std::to_string(p.training_views));
  if (!(p.min_depth_ratio >= 1.0))
    return bad("minimum depth ratio: expected >= 1, found " + format_number(p.min_depth_ratio, 6));
  if (!(p.min_iou >= 0.0 && p.min_iou <= 1.0))
    return bad("minimum IoU: expected a fraction in [0, 1], found " + format_number(p.min_iou, 6));
  if (!(p.min_angle_deg >= 0.0 && p.min_angle_deg <= p.max_angle_deg && p.max_angle_deg <= 180.0))
    return bad("angle range: expected 0 <= min <= max <= 180 degrees, found " +
               format_number(p.min_angle_deg, 6) + "," + format_number(p.max_angle_deg, 6));
  for (double f : {p.close_fraction, p.far_fraction, p.test_fraction, p.train_fraction})
    if (!(f > 0.0 && f <= 1.0))
      return bad("set fractions must be in (0, 1], found " + format_number(f, 6));
  if (p.close_fraction + p.far_fraction > 1.0 + 1e-12 ||
      p.test_fraction + p.train_fraction > 1.0 + 1e-12)
    return bad("close + far and test + train fractions must not exceed 1");
  return Status::ok();
}

void CriteriaCounts::add(const PairMeasure& m) {
  ++pairs;
  depth_ratio += m.ratio_ok;
  iou += m.iou_ok;
  angle += m.angle_ok;
  all += m.accepted();
}

std::string CriteriaCounts::describe(const std::string& what, const PairParams& p) const {
  return "of " + std::to_string(pairs) + " pairs (" + what +
         "): depth ratio >= " + format_number(p.min_depth_ratio, 6) + " holds for " +
         std::to_string(depth_ratio) + ", IoU >= " + format_number(p.min_iou, 6) + " for " +
         std::to_string(iou) + ", angle in [" + format_number(p.min_angle_deg, 6) + ", " +
         format_number(p.max_angle_deg, 6) + "] deg for " + std::to_string(angle) +
         "; all three for " + std::to_string(all);
}

double pair_score(double iou, double depth_ratio) {
  return depth_ratio > 0 ? iou * std::log2(depth_ratio) : 0.0;
}

double percentile_linear(std::vector<double>& v, double p) {
  MACRO_CHECK(!v.empty() && p >= 0.0 && p <= 100.0);
  const double pos = p / 100.0 * double(v.size() - 1);
  const size_t lo = size_t(std::floor(pos));
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(lo), v.end());
  const double a = v[lo];
  if (lo + 1 >= v.size()) return a;
  const double b = *std::min_element(v.begin() + std::ptrdiff_t(lo) + 1, v.end());
  return a + (pos - double(lo)) * (b - a);
}

CameraDepth camera_depth(const gs::Camera& cam, const std::vector<Eigen::Vector3d>& points,
                         std::vector<uint64_t>* bits) {
  CameraDepth d;
  d.center = cam.center();
  d.axis = cam.R.row(2).transpose().normalized();  // camera +z in world coordinates
  const double tx = 0.5 * cam.width / cam.fx, ty = 0.5 * cam.height / cam.fy;
  const double half = std::atan(std::sqrt(tx * tx + ty * ty));
  d.half_fov_deg = half * kRadToDeg;
  // z > cos(half) |r| with z > 0  <=>  z > 0 and z^2 > cos^2(half) |r|^2: no square root, and
  // the loop is branch-free (visible depths are compacted by a conditional index).
  const double cos2 = std::cos(half) * std::cos(half);
  const Eigen::Vector3d c = d.center, v = d.axis;
  std::vector<double> depths(points.size());
  size_t count = 0;
  for (size_t base = 0; base < points.size(); base += 64) {
    const size_t end = std::min(points.size(), base + 64);
    uint64_t word = 0;
    for (size_t m = base; m < end; ++m) {
      const double rx = points[m].x() - c.x(), ry = points[m].y() - c.y(),
                   rz = points[m].z() - c.z();
      const double z = rx * v.x() + ry * v.y() + rz * v.z();
      const double r2 = rx * rx + ry * ry + rz * rz;
      const bool in = z > 0.0 && z * z > cos2 * r2;
      depths[count] = z;
      count += in;
      word |= uint64_t(in) << (m - base);
    }
    if (bits) (*bits)[base >> 6] = word;
  }
  depths.resize(count);
  d.visible = int64_t(depths.size());
  if (depths.empty()) return d;
  d.p10 = percentile_linear(depths, 10.0);
  d.median = percentile_linear(depths, 50.0);
  d.p90 = percentile_linear(depths, 90.0);
  d.span = d.p90 / d.p10;
  return d;
}

std::vector<int> farthest_point_sampling(const std::vector<Eigen::Vector3d>& pos, int count,
                                         std::optional<uint64_t> seed) {
  const size_t n = pos.size();
  std::vector<int> out;
  if (n == 0 || count <= 0) return out;
  count = std::min<int>(count, int(n));
  size_t start = 0;
  if (seed) {
    std::mt19937_64 rng(*seed);  // the engine's output sequence is fixed by the standard
    start = size_t(rng() % n);
  } else {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& p : pos) centroid += p;
    centroid /= double(n);
    double best = -1;
    for (size_t i = 0; i < n; ++i) {
      const double dist = (pos[i] - centroid).squaredNorm();
      if (dist > best) best = dist, start = i;  // strict: ties keep the first
    }
  }
  std::vector<double> nearest(n, INFINITY);
  std::vector<bool> taken(n, false);
  size_t next = start;
  for (int k = 0; k < count; ++k) {
    out.push_back(int(next));
    taken[next] = true;
    double best = -1;
    size_t arg = 0;
    for (size_t i = 0; i < n; ++i) {
      nearest[i] = std::min(nearest[i], (pos[i] - pos[next]).squaredNorm());
      if (!taken[i] && nearest[i] > best) best = nearest[i], arg = i;
    }
    next = arg;
  }
  return out;
}

Result<PairConstruction> construct_pairs(const gs::CameraSet& cameras,
                                         const std::vector<Eigen::Vector3d>& points,
                                         const PairParams& p) {
  MACRO_TRY(check_pair_params(p));
  const size_t n_cam = cameras.cameras.size();
  const size_t words = (points.size() + 63) / 64;  // W
  PairConstruction pc;
  pc.depth.resize(n_cam);
  std::vector<uint64_t> bits(n_cam * words, 0);  // [N, W] visible-point bitsets

  {  // 1-2. Visibility and depths, one camera per task.
    std::optional<Progress> progress;
    if (p.progress) progress.emplace("pairs: depths", n_cam);
    ThreadPool::global().parallel_for(
        n_cam,
        [&](size_t begin, size_t end, int) {
          for (size_t i = begin; i < end; ++i) {
            std::vector<uint64_t> row(words, 0);
            pc.depth[i] = camera_depth(cameras.cameras[i], points, &row);
            std::copy(row.begin(), row.end(), bits.begin() + std::ptrdiff_t(i * words));
            if (progress) progress->advance();
          }
        },
        1);
    if (progress) progress->finish();
  }
  for (size_t i = 0; i < n_cam; ++i)
    (pc.depth[i].visible > 0 ? pc.by_depth : pc.no_depth).push_back(int(i));
  std::stable_sort(pc.by_depth.begin(), pc.by_depth.end(), [&](int a, int b) {
    const double da = pc.depth[size_t(a)].median, db = pc.depth[size_t(b)].median;
    if (da != db) return da < db;
    return cameras.cameras[size_t(a)].name < cameras.cameras[size_t(b)].name;
  });
  const size_t n = pc.by_depth.size();
  const int n_test = fraction_count(p.test_fraction, n);
  const int n_train = fraction_count(p.train_fraction, n);
  if (n_test < 1 || n_train < 1)
    return Status::error(
        "pair construction: " + std::to_string(n) + " of " + std::to_string(n_cam) +
        " cameras see any 3D point; the " + format_number(100 * p.test_fraction, 6) + "/" +
        format_number(100 * p.train_fraction, 6) + " test/training split needs at least " +
        std::to_string(int(std::ceil(1.0 / std::min(p.test_fraction, p.train_fraction)))) +
        " of them");

  // 3. Close and far sets, candidate pairs.
  const int n_close = fraction_count(p.close_fraction, n);
  const int n_far = fraction_count(p.far_fraction, n);
  pc.close_set.assign(pc.by_depth.begin(), pc.by_depth.begin() + n_close);
  pc.far_set.assign(pc.by_depth.end() - n_far, pc.by_depth.end());
  {
    std::vector<PairMeasure> all(pc.close_set.size() * pc.far_set.size());
    std::optional<Progress> progress;
    if (p.progress) progress.emplace("pairs: close x far", pc.close_set.size());
    ThreadPool::global().parallel_for(
        pc.close_set.size(),
        [&](size_t begin, size_t end, int) {
          for (size_t a = begin; a < end; ++a) {
            for (size_t b = 0; b < pc.far_set.size(); ++b)
              all[a * pc.far_set.size() + b] =
                  measure(pc.close_set[a], pc.far_set[b], pc.depth, bits, words, p);
            if (progress) progress->advance();
          }
        },
        1);
    if (progress) progress->finish();
    for (const PairMeasure& m : all) {
      pc.candidate_counts.add(m);
      if (m.accepted()) pc.candidates.push_back(m);
    }
  }

  // 4. Scene score.
  {
    SceneScore& s = pc.score;
    double sum = 0, sum_span = 0, min_d = INFINITY, min10 = INFINITY, max10 = 0;
    for (int i : pc.by_depth) {
      const CameraDepth& d = pc.depth[size_t(i)];
      sum += d.median;
      sum_span += d.span;
      min_d = std::min(min_d, d.median);
      min10 = std::min(min10, d.p10);
      max10 = std::max(max10, d.p10);
    }
    const double mu = sum / double(n);
    double var = 0;
    for (int i : pc.by_depth) var += std::pow(pc.depth[size_t(i)].median - mu, 2);
    s.depth_cv = std::sqrt(var / double(n)) / mu;
    s.mean_span = sum_span / double(n);
    s.near_ratio = max10 / min10;
    s.closeness = 1.0 / min_d;
    s.candidates = int64_t(pc.candidates.size());
    s.score = s.candidates == 0
                  ? 0.0
                  : s.depth_cv * (1 + std::log1p(s.mean_span)) * (1 + std::log1p(s.near_ratio)) *
                        (1 + std::log1p(s.closeness)) * std::log1p(double(s.candidates));
  }

  // 5. Split and training views.
  pc.test_pool.assign(pc.by_depth.begin(), pc.by_depth.begin() + n_test);
  pc.train_pool.assign(pc.by_depth.end() - n_train, pc.by_depth.end());
  pc.discarded.assign(pc.by_depth.begin() + n_test, pc.by_depth.end() - n_train);
  {
    std::vector<Eigen::Vector3d> centres;
    for (int i : pc.train_pool) centres.push_back(pc.depth[size_t(i)].center);
    for (int k : farthest_point_sampling(centres, p.training_views, p.seed))
      pc.training.push_back(pc.train_pool[size_t(k)]);
  }

  // 6. Evaluation pairs: the best accepted training view per test candidate.
  for (int i : pc.test_pool) {
    std::optional<PairMeasure> best;
    for (int j : pc.training) {
      const PairMeasure m = measure(i, j, pc.depth, bits, words, p);
      pc.eval_counts.add(m);
      if (!m.accepted()) continue;
      const auto key = [&](const PairMeasure& x) {
        return std::make_tuple(x.pair_score, -x.angle_deg);
      };
      if (!best || key(m) > key(*best) ||
          (key(m) == key(*best) &&
           cameras.cameras[size_t(j)].name < cameras.cameras[size_t(best->far)].name))
        best = m;
    }
    if (best)
      pc.eval_pairs.push_back(*best);
    else
      pc.unpaired_tests.push_back(i);
  }
  std::sort(pc.eval_pairs.begin(), pc.eval_pairs.end(),
            [&](const PairMeasure& a, const PairMeasure& b) {
              return cameras.cameras[size_t(a.close)].name < cameras.cameras[size_t(b.close)].name;
            });
  return pc;
}

Status check_pairs_found(const PairConstruction& pc, const PairParams& p) {
  if (pc.candidates.empty())
    return Status::error(
        "no candidate close-up pair (scene score 0): " +
        pc.candidate_counts.describe(std::to_string(pc.close_set.size()) + " close x " +
                                         std::to_string(pc.far_set.size()) + " far",
                                     p));
  if (pc.eval_pairs.empty())
    return Status::error(std::to_string(pc.candidates.size()) +
                         " candidate pairs, but no evaluation pair between the " +
                         std::to_string(pc.test_pool.size()) + " test candidates and the " +
                         std::to_string(pc.training.size()) + " training views: " +
                         pc.eval_counts.describe(std::to_string(pc.test_pool.size()) + " test x " +
                                                     std::to_string(pc.training.size()) +
                                                     " training",
                                                 p));
  return Status::ok();
}

std::string split_json(const gs::CameraSet& cameras, const PairConstruction& pc,
                       const PairParams& p, const std::string& scene_name, int64_t num_points) {
  using Json = nlohmann::ordered_json;
  const auto name = [&](int i) { return cameras.cameras[size_t(i)].name; };
  // Intrinsics of the first evaluation close-up (else the first training view).
  const gs::Camera& k = cameras.cameras[size_t(!pc.eval_pairs.empty() ? pc.eval_pairs.front().close
                                                                      : pc.training.front())];
  Json intr = {{"w", k.width}, {"h", k.height}, {"fl_x", k.fx},
               {"fl_y", k.fy}, {"cx", k.cx},    {"cy", k.cy}};
  if (k.model == gs::CameraModel::kOpenCV || k.model == gs::CameraModel::kOpenCVFisheye) {
    static const char* const kOpenCV[] = {"k1", "k2", "p1", "p2"};
    static const char* const kFisheye[] = {"k1", "k2", "k3", "k4"};
    const bool fish = k.model == gs::CameraModel::kOpenCVFisheye;
    for (size_t q = 0; q < 4 && q < k.distortion.size(); ++q)
      intr[(fish ? kFisheye : kOpenCV)[q]] = k.distortion[q];
  }
  intr["camera_model"] = gs::camera_model_name(k.model);

  Json training = Json::array(), closeup_frames = Json::array(), pairs = Json::array();
  Json poses = Json::object();
  std::vector<bool> is_training(cameras.cameras.size(), false);
  for (int i : pc.training) {
    training.push_back(name(i));
    is_training[size_t(i)] = true;
  }
  for (size_t i = 0; i < cameras.cameras.size(); ++i)
    if (!is_training[i]) closeup_frames.push_back(name(int(i)));
  for (const PairMeasure& m : pc.eval_pairs) {
    pairs.push_back({{"training_frame", name(m.far)},
                     {"closeup_frame", name(m.close)},
                     {"depth_ratio", m.depth_ratio},
                     {"iou", m.iou},
                     {"angle_deg", m.angle_deg},
                     {"pair_score", m.pair_score}});
    const Eigen::Matrix4d gl =
        gs::opengl_c2w_from_opencv_w2c(cameras.cameras[size_t(m.close)].world_to_camera());
    Json rows = Json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({gl(r, 0), gl(r, 1), gl(r, 2), gl(r, 3)});
    poses[name(m.close)] = rows;
  }
  const SceneScore& s = pc.score;
  Json record = {
      {"method", "appendix D (docs/benchmark.md, Pair construction)"},
      {"num_cameras", cameras.cameras.size()},
      {"num_points", num_points},
      {"cameras_without_points", pc.no_depth.size()},
      {"params",
       {{"training_views", p.training_views},
        {"min_depth_ratio", p.min_depth_ratio},
        {"min_iou", p.min_iou},
        {"angle_deg", {p.min_angle_deg, p.max_angle_deg}},
        {"close_far_fractions", {p.close_fraction, p.far_fraction}},
        {"test_train_fractions", {p.test_fraction, p.train_fraction}},
        {"fps_start", p.seed ? "seed " + std::to_string(*p.seed) : "farthest from centroid"}}},
      {"sets",
       {{"close", pc.close_set.size()},
        {"far", pc.far_set.size()},
        {"test_pool", pc.test_pool.size()},
        {"discarded", pc.discarded.size()},
        {"train_pool", pc.train_pool.size()},
        {"unpaired_test_frames", pc.unpaired_tests.size()}}},
      {"candidate_pairs",
       {{"considered", pc.candidate_counts.pairs},
        {"depth_ratio_ok", pc.candidate_counts.depth_ratio},
        {"iou_ok", pc.candidate_counts.iou},
        {"angle_ok", pc.candidate_counts.angle},
        {"accepted", pc.candidate_counts.all}}},
      {"scene_score",
       {{"score", s.score},
        {"depth_cv", s.depth_cv},
        {"mean_span", s.mean_span},
        {"near_ratio", s.near_ratio},
        {"closeness", s.closeness},
        {"candidates", s.candidates}}}};
  Json split = {{"scene", scene_name},
                {"data_factor", 1},
                {"intrinsics", intr},
                {"training_frames", training},
                {"closeup_frames", closeup_frames},
                {"closeup_eval_pairs", pairs},
                {"closeup_poses", poses},
                {"num_training_frames", training.size()},
                {"num_closeup_pairs", pairs.size()},
                {"pair_construction", record}};
  return split.dump(2) + "\n";
}

// ---- One scene from disk ------------------------------------------------------------------------

Result<SceneSplit> load_and_construct(const std::string& folder, const std::string& name,
                                      const PairParams& params) {
  SceneSplit s;
  s.name = name;
  s.folder = folder;
  MACRO_ASSIGN_OR_RETURN(s.model, gs::find_colmap_model_folder(folder));
  MACRO_ASSIGN_OR_RETURN(s.cameras, gs::load_colmap_sparse(s.model));
  MACRO_ASSIGN_OR_RETURN(gs::ColmapPoints points, gs::load_colmap_points(s.model));
  if (points.size() == 0)
    return Status::error(points.source + ": holds no 3D points (the pair depths come from them)");
  s.num_points = int64_t(points.size());
  auto pc = construct_pairs(s.cameras, points.xyz, params);
  if (!pc) return pc.status().with_context(s.model);
  s.pc = std::move(*pc);
  return s;
}

Status write_scene_split(const SceneSplit& scene, const PairParams& params,
                         const std::string& out_path, bool copy_gt) {
  namespace fs = std::filesystem;
  // The close-ups first: a missing image leaves no split behind.
  const fs::path out_dir = fs::absolute(out_path).parent_path();
  for (size_t k = 0; copy_gt && k < scene.pc.eval_pairs.size(); ++k) {
    const PairMeasure& m = scene.pc.eval_pairs[k];
    const std::string& frame = scene.cameras.cameras[size_t(m.close)].name;
    const fs::path src = fs::path(scene.folder) / "images" / frame;
    const fs::path dst = out_dir / "closeup_gt" / frame;
    if (!file_exists(src.string()))
      return Status::error(src.string() + ": close-up image not found (--copy-gt)");
    std::error_code ec;
    fs::create_directories(dst.parent_path(), ec);
    if (ec)
      return Status::error(dst.parent_path().string() + ": cannot create folder: " + ec.message());
    MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(src.string()));
    MACRO_TRY(write_file_atomic(dst.string(), bytes.data(), bytes.size()));
  }
  return write_file_atomic(
      out_path, split_json(scene.cameras, scene.pc, params, scene.name, scene.num_points));
}

}  // namespace macro::enhance
