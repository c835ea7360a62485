// Adam per parameter group (adam.h).
#include "gs/train/adam.h"

#include <cmath>

#include "gs/train/adam_kernels.h"

namespace macro::gs::train {

// Each operation rounded on its own: this file is built with the baseline x86-64 flags (no FMA),
// so nothing is contracted.
void adam_rows_scalar(float* m, float* v, const float* g, float* p, size_t n,
                      const AdamCoefficients& c) {
  const float neg_step = -c.step_size;
  for (size_t i = 0; i < n; ++i) {
    const float gi = g[i];
    m[i] = m[i] + c.one_minus_beta1 * (gi - m[i]);
    v[i] = c.beta2 * v[i] + (c.one_minus_beta2 * gi) * gi;
    const float denom = std::sqrt(v[i]) / c.bias2_sqrt + c.eps;
    p[i] = p[i] + (neg_step * m[i]) / denom;
  }
}

AdamRowsFn adam_rows_for(Isa isa) {
  return isa >= Isa::kAvx512 && isa_supported(isa) ? adam_rows_avx512 : adam_rows_scalar;
}

namespace {

// p[i] -= step_size m / (sqrt(v) / bias2_sqrt + eps), element-wise (adam_kernels.h); each
// element alone, so the thread count cannot change the result, nor the ISA path.
void adam_update(std::vector<float>& m, std::vector<float>& v, const std::vector<float>& g,
                 std::vector<float>& p, double lr, const AdamOptions& o, int t, ThreadPool& pool) {
  MACRO_CHECK(g.size() == p.size() && m.size() == p.size() && v.size() == p.size());
  const double bias1 = 1 - std::pow(o.beta1, t), bias2 = 1 - std::pow(o.beta2, t);
  const AdamCoefficients c{float(1 - o.beta1), float(o.beta2),          float(1 - o.beta2),
                           float(lr / bias1),  float(std::sqrt(bias2)), float(o.eps)};
  const AdamRowsFn rows = adam_rows_for(active_isa());
  pool.parallel_for(
      p.size(), [&](size_t b, size_t e, int) { rows(&m[b], &v[b], &g[b], &p[b], e - b, c); }, 4096);
}

}  // namespace

SplatAdam::SplatAdam(const SplatParams& params, const AdamOptions& options) : options_(options) {
  const size_t N = params.size();
  auto init = [N](Group& grp, size_t width, double lr) {
    grp.width = width;
    grp.m.assign(N * width, 0.f);
    grp.v.assign(N * width, 0.f);
    grp.lr = lr;
  };
  init(means_, 3, options.lr.means * options.scene_scale);
  init(scales_, 3, options.lr.scales);
  init(quats_, 4, options.lr.quats);
  init(opacities_, 1, options.lr.opacities);
  init(sh0_, 3, options.lr.sh0);
  init(shN_, size_t(params.sh_rest()) * 3, options.lr.shN);
}

void SplatAdam::step(const SplatGrads& g, SplatParams* p, ThreadPool& pool) {
  ++t_;
  adam_update(means_.m, means_.v, g.means, p->means, means_.lr, options_, t_, pool);
  adam_update(scales_.m, scales_.v, g.scales, p->scales, scales_.lr, options_, t_, pool);
  adam_update(quats_.m, quats_.v, g.quats, p->quats, quats_.lr, options_, t_, pool);
  adam_update(opacities_.m, opacities_.v, g.opacities, p->opacities, opacities_.lr, options_, t_,
              pool);
  adam_update(sh0_.m, sh0_.v, g.sh0, p->sh0, sh0_.lr, options_, t_, pool);
  adam_update(shN_.m, shN_.v, g.shN, p->shN, shN_.lr, options_, t_, pool);
}

namespace {

void remap_group(std::vector<float>& m, std::vector<float>& v, const std::vector<int64_t>& src,
                 size_t n_old, size_t width) {
  std::vector<float> nm(src.size() * width, 0.f), nv(src.size() * width, 0.f);
  for (size_t i = 0; i < src.size(); ++i) {
    if (src[i] < 0) continue;
    const size_t r = size_t(src[i]);
    MACRO_CHECK(r < n_old);
    std::copy(m.begin() + r * width, m.begin() + (r + 1) * width, nm.begin() + i * width);
    std::copy(v.begin() + r * width, v.begin() + (r + 1) * width, nv.begin() + i * width);
  }
  m.swap(nm);
  v.swap(nv);
}

}  // namespace

void SplatAdam::remap_rows(const std::vector<int64_t>& src) {
  const size_t n_old = opacities_.m.size();
  for (Group* g : {&means_, &scales_, &quats_, &opacities_, &sh0_, &shN_})
    remap_group(g->m, g->v, src, n_old, g->width);
}

void SplatAdam::zero_rows(const std::vector<size_t>& rows) {
  for (Group* g : {&means_, &scales_, &quats_, &opacities_, &sh0_, &shN_})
    for (size_t r : rows)
      for (size_t k = 0; k < g->width; ++k) g->m[r * g->width + k] = g->v[r * g->width + k] = 0.f;
}

std::vector<SplatAdam::GroupState> SplatAdam::state() {
  std::vector<GroupState> out;
  const char* names[6] = {"means", "scales", "quats", "opacities", "sh0", "shN"};
  Group* groups[6] = {&means_, &scales_, &quats_, &opacities_, &sh0_, &shN_};
  for (int i = 0; i < 6; ++i)
    out.push_back({names[i], &groups[i]->m, &groups[i]->v, &groups[i]->lr, groups[i]->width});
  return out;
}

void SplatAdam::zero_opacity_state() {
  std::fill(opacities_.m.begin(), opacities_.m.end(), 0.f);
  std::fill(opacities_.v.begin(), opacities_.v.end(), 0.f);
}

const SplatAdam::Group* SplatAdam::group(const std::string& name) const {
  if (name == "means") return &means_;
  if (name == "scales") return &scales_;
  if (name == "quats") return &quats_;
  if (name == "opacities") return &opacities_;
  if (name == "sh0") return &sh0_;
  if (name == "shN") return &shN_;
  return nullptr;
}
const std::vector<float>* SplatAdam::exp_avg(const std::string& name) const {
  const Group* g = group(name);
  return g ? &g->m : nullptr;
}
const std::vector<float>* SplatAdam::exp_avg_sq(const std::string& name) const {
  const Group* g = group(name);
  return g ? &g->v : nullptr;
}

}  // namespace macro::gs::train
