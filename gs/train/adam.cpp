// Adam per parameter group (adam.h).
#include "gs/train/adam.h"

#include <cmath>

namespace macro::gs::train {
namespace {

// p[i] -= step_size m / (sqrt(v) / bias2_sqrt + eps), element-wise; each element alone, so the
// thread count cannot change the result.
void adam_update(std::vector<double>& m, std::vector<double>& v, const std::vector<float>& g,
                 std::vector<float>& p, double lr, const AdamOptions& o, int t, ThreadPool& pool) {
  MACRO_CHECK(g.size() == p.size() && m.size() == p.size() && v.size() == p.size());
  const double bias1 = 1 - std::pow(o.beta1, t), bias2 = 1 - std::pow(o.beta2, t);
  const double step_size = lr / bias1, bias2_sqrt = std::sqrt(bias2);
  pool.parallel_for(
      p.size(),
      [&](size_t b, size_t e, int) {
        for (size_t i = b; i < e; ++i) {
          const double gi = g[i];
          m[i] = o.beta1 * m[i] + (1 - o.beta1) * gi;
          v[i] = o.beta2 * v[i] + (1 - o.beta2) * gi * gi;
          const double denom = std::sqrt(v[i]) / bias2_sqrt + o.eps;
          p[i] = float(double(p[i]) - step_size * m[i] / denom);
        }
      },
      4096);
}

}  // namespace

SplatAdam::SplatAdam(const SplatParams& params, const AdamOptions& options) : options_(options) {
  auto init = [](Group& grp, size_t n, double lr) {
    grp.m.assign(n, 0.0);
    grp.v.assign(n, 0.0);
    grp.lr = lr;
  };
  init(means_, params.means.size(), options.lr.means * options.scene_scale);
  init(scales_, params.scales.size(), options.lr.scales);
  init(quats_, params.quats.size(), options.lr.quats);
  init(opacities_, params.opacities.size(), options.lr.opacities);
  init(sh0_, params.sh0.size(), options.lr.sh0);
  init(shN_, params.shN.size(), options.lr.shN);
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

}  // namespace macro::gs::train
