// Plan stability: two plans of one close-up compared (see plan_stability.h).
#include "enhance/macro/plan_stability.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"

namespace macro::enhance {
namespace {

// m: A plane -> B plane (plan_stability.h "Plane matching").
std::vector<int> match_planes(const PlaneResult& a, const PlaneResult& b) {
  const size_t pa = a.planes.size(), pb = b.planes.size();
  std::vector<int> m(pa, 0);
  if (pa == pb) {
    for (size_t p = 0; p < pa; ++p) m[p] = int(p);
    return m;
  }
  for (size_t p = 0; p < pa; ++p) {
    double best = INFINITY;
    for (size_t q = 0; q < pb; ++q) {
      const double d = std::abs(a.planes[p].inv_depth_centroid - b.planes[q].inv_depth_centroid);
      if (d < best) {  // strict: ties keep the farther (lower) B plane
        best = d;
        m[p] = int(q);
      }
    }
  }
  return m;
}

int32_t mapped(int32_t label, const std::vector<int>& m) {
  return label >= 0 && size_t(label) < m.size() ? int32_t(m[size_t(label)]) : label;
}

}  // namespace

Result<PlanStability> compare_plans(const MacroPlan& a, const MacroPlan& b) {
  const int W = a.closeup.width, H = a.closeup.height;
  if (b.closeup.width != W || b.closeup.height != H || a.latent_h != b.latent_h ||
      a.latent_w != b.latent_w)
    return Status::error("plan stability: expected two plans of one close-up, found '" +
                         a.closeup.name + "' " + std::to_string(W) + "x" + std::to_string(H) +
                         " and '" + b.closeup.name + "' " + std::to_string(b.closeup.width) + "x" +
                         std::to_string(b.closeup.height));
  const size_t hw = size_t(W) * size_t(H), lhw = size_t(a.latent_h) * size_t(a.latent_w);
  MACRO_CHECK(a.planes.labels.size() == hw && b.planes.labels.size() == hw);
  MACRO_CHECK(a.latent_planes.size() == lhw && b.latent_planes.size() == lhw);
  PlanStability s;
  s.closeup = a.closeup.name;
  s.width = W;
  s.height = H;
  s.latent_h = a.latent_h;
  s.latent_w = a.latent_w;
  s.planes_a = int(a.planes.planes.size());
  s.planes_b = int(b.planes.planes.size());
  s.planes_by_index = s.planes_a == s.planes_b;
  s.plane_match = match_planes(a.planes, b.planes);

  // Planes: depth of each A plane against its partner's.
  for (int p = 0; p < s.planes_a; ++p) {
    PlaneStability ps;
    ps.plane_a = p;
    ps.plane_b = s.plane_match[size_t(p)];
    ps.depth_a = a.planes.planes[size_t(p)].depth_median;
    ps.depth_b = b.planes.planes[size_t(ps.plane_b)].depth_median;
    ps.depth_error = ps.depth_b > 0 ? std::abs(ps.depth_a / ps.depth_b - 1.0) : INFINITY;
    s.depth_error_mean += ps.depth_error;
    s.depth_error_max = std::max(s.depth_error_max, ps.depth_error);
    s.planes.push_back(ps);
  }
  if (!s.planes.empty()) s.depth_error_mean /= double(s.planes.size());

  // Tokens [h, w] and pixels [H, W].
  s.tokens = int64_t(lhw);
  for (size_t t = 0; t < lhw; ++t)
    s.tokens_moved += mapped(a.latent_planes[t], s.plane_match) != b.latent_planes[t];
  s.tokens_moved_fraction = lhw ? double(s.tokens_moved) / double(lhw) : 0.0;
  s.pixels = int64_t(hw);
  for (size_t k = 0; k < hw; ++k)
    s.pixels_moved += mapped(a.planes.labels[k], s.plane_match) != b.planes.labels[k];
  s.pixels_moved_fraction = hw ? double(s.pixels_moved) / double(hw) : 0.0;

  // References.
  s.candidates_a = a.ref_candidates;
  s.candidates_b = b.ref_candidates;
  for (const SelectedReference& r : a.selection.refs) s.references_a.push_back(r.name);
  for (const SelectedReference& r : b.selection.refs) s.references_b.push_back(r.name);
  s.same_references = s.candidates_a == s.candidates_b;

  // Crops, paired by (m(plane), candidate camera).
  s.crops_a = int(a.crops.size());
  s.crops_b = int(b.crops.size());
  std::vector<uint8_t> b_paired(b.crops.size(), 0);
  for (const Crop& ca : a.crops) {
    const int cand = a.ref_candidates[size_t(ca.ref)];
    const int pb = s.plane_match[size_t(ca.plane)];
    int rb = -1;
    for (size_t r = 0; r < b.ref_candidates.size() && rb < 0; ++r)
      if (b.ref_candidates[r] == cand) rb = int(r);
    const Crop* cb = nullptr;
    for (size_t c = 0; c < b.crops.size() && !cb && rb >= 0; ++c)
      if (b.crops[c].plane == pb && b.crops[c].ref == rb) {
        cb = &b.crops[c];
        b_paired[c] = 1;
      }
    if (!cb) {
      ++s.crops_unpaired_a;
      continue;
    }
    CropStability cs;
    cs.plane_a = ca.plane;
    cs.plane_b = cb->plane;
    cs.ref_a = ca.ref;
    cs.ref_b = cb->ref;
    cs.candidate = cand;
    cs.reference = ca.reference;
    cs.scale_a = ca.scale;
    cs.scale_b = cb->scale;
    cs.scale_error = std::abs(ca.scale / cb->scale - 1.0);  // scale > 0 for every kept crop
    cs.centre_a_u = ca.centre_u;
    cs.centre_a_v = ca.centre_v;
    cs.centre_b_u = cb->centre_u;
    cs.centre_b_v = cb->centre_v;
    cs.centre_error = std::hypot(ca.centre_u - cb->centre_u, ca.centre_v - cb->centre_v);
    s.scale_error_mean += cs.scale_error;
    s.scale_error_max = std::max(s.scale_error_max, cs.scale_error);
    s.centre_error_mean += cs.centre_error;
    s.centre_error_max = std::max(s.centre_error_max, cs.centre_error);
    s.crops.push_back(cs);
  }
  for (uint8_t p : b_paired) s.crops_unpaired_b += !p;
  if (!s.crops.empty()) {
    s.scale_error_mean /= double(s.crops.size());
    s.centre_error_mean /= double(s.crops.size());
  }
  return s;
}

Result<PlanStability> plan_stability(const SceneInputs& in, const PlanOptions& o,
                                     const DepthView& truth) {
  if (truth.camera.width != in.closeup.width || truth.camera.height != in.closeup.height)
    return Status::error(
        "plan stability: true depth: expected the close-up's size " +
        std::to_string(in.closeup.width) + "x" + std::to_string(in.closeup.height) + ", found " +
        std::to_string(truth.camera.width) + "x" + std::to_string(truth.camera.height));
  Result<MacroPlan> a = build_plan(in, o);
  if (!a) return a.status().with_context("plan stability: the reconstruction's plan");
  PlanOptions ob = o;
  ob.closeup_depth = &truth.depth;
  Result<MacroPlan> b = build_plan(in, ob);
  if (!b) return b.status().with_context("plan stability: the true depth's plan");
  return compare_plans(*a, *b);
}

Result<DepthView> render_closeup_depth(const gs::GaussianCloud& cloud, const gs::Camera& closeup,
                                       const PlanOptions& o) {
  ThreadPool& pool = o.pool ? *o.pool : ThreadPool::global();
  gs::Rasterizer raster;
  gs::RenderResult r;
  MACRO_TRY(raster.render_into(cloud, closeup, o.render, &r, pool)
                .with_context("true depth: close-up '" + closeup.name + "'"));
  return DepthView{closeup, macro_depth(r)};
}

std::string plan_stability_to_json(const PlanStability& s) {
  using nlohmann::json;
  json j;
  j["closeup"] = {
      {"name", s.closeup}, {"size", {s.width, s.height}}, {"latent", {s.latent_w, s.latent_h}}};
  json depth = json::array();
  for (const PlaneStability& p : s.planes)
    depth.push_back({{"a", p.plane_a},
                     {"b", p.plane_b},
                     {"depth_a", p.depth_a},
                     {"depth_b", p.depth_b},
                     {"error", p.depth_error}});
  j["planes"] = {{"a", s.planes_a},
                 {"b", s.planes_b},
                 {"by_index", s.planes_by_index},
                 {"match", s.plane_match},
                 {"depth", depth},
                 {"depth_error", {{"mean", s.depth_error_mean}, {"max", s.depth_error_max}}}};
  j["tokens"] = {
      {"total", s.tokens}, {"moved", s.tokens_moved}, {"fraction", s.tokens_moved_fraction}};
  j["pixels"] = {
      {"total", s.pixels}, {"moved", s.pixels_moved}, {"fraction", s.pixels_moved_fraction}};
  json pairs = json::array();
  for (const CropStability& c : s.crops)
    pairs.push_back({{"plane_a", c.plane_a},
                     {"plane_b", c.plane_b},
                     {"ref_a", c.ref_a},
                     {"ref_b", c.ref_b},
                     {"candidate", c.candidate},
                     {"reference", c.reference},
                     {"scale", {c.scale_a, c.scale_b}},
                     {"scale_error", c.scale_error},
                     {"centre_a", {c.centre_a_u, c.centre_a_v}},
                     {"centre_b", {c.centre_b_u, c.centre_b_v}},
                     {"centre_error_px", c.centre_error}});
  j["crops"] = {{"a", s.crops_a},
                {"b", s.crops_b},
                {"unpaired_a", s.crops_unpaired_a},
                {"unpaired_b", s.crops_unpaired_b},
                {"scale_error", {{"mean", s.scale_error_mean}, {"max", s.scale_error_max}}},
                {"centre_error_px", {{"mean", s.centre_error_mean}, {"max", s.centre_error_max}}},
                {"pairs", pairs}};
  j["references"] = {{"same", s.same_references},
                     {"a", s.references_a},
                     {"b", s.references_b},
                     {"candidates_a", s.candidates_a},
                     {"candidates_b", s.candidates_b}};
  return j.dump(2) + "\n";
}

Status write_plan_stability_json(const PlanStability& s, const std::string& path) {
  return write_file_atomic(path, plan_stability_to_json(s)).with_context(path);
}

}  // namespace macro::enhance
