// gsplat's MCMCStrategy (strategy_mcmc.h).
#include "gs/train/strategy_mcmc.h"

#include <algorithm>
#include <cfloat>
#include <cmath>

#include "gs/synth/synth_random.h"

namespace macro::gs::train {
namespace {

constexpr int kMaxRatio = 51;  // gsplat's n_max (binomial table 51 x 51)

double sigmoid(double x) {
  return 1 / (1 + std::exp(-x));
}

void copy_row(SplatParams* p, size_t dst, size_t src) {
  const size_t R = size_t(p->sh_rest()) * 3;
  for (int a = 0; a < 3; ++a) p->means[dst * 3 + a] = p->means[src * 3 + a];
  for (int a = 0; a < 3; ++a) p->scales[dst * 3 + a] = p->scales[src * 3 + a];
  for (int a = 0; a < 4; ++a) p->quats[dst * 4 + a] = p->quats[src * 4 + a];
  p->opacities[dst] = p->opacities[src];
  for (int a = 0; a < 3; ++a) p->sh0[dst * 3 + a] = p->sh0[src * 3 + a];
  for (size_t k = 0; k < R; ++k) p->shN[dst * R + k] = p->shN[src * R + k];
}

void grow_rows(SplatParams* p, size_t n) {
  const size_t R = size_t(p->sh_rest()) * 3;
  p->means.resize(n * 3);
  p->scales.resize(n * 3);
  p->quats.resize(n * 4);
  p->opacities.resize(n);
  p->sh0.resize(n * 3);
  p->shN.resize(n * R);
}

// The drawn rows get their relocated opacity and scales (gsplat: p[sampled_idxs] = ...; every
// occurrence of a row carries the same count, so the values do not depend on the order).
void apply_relocation(const McmcStrategyOptions& options, const std::vector<size_t>& drawn,
                      SplatParams* p) {
  std::vector<int> count(p->size(), 0);
  for (size_t j : drawn) ++count[j];
  for (size_t j = 0; j < p->size(); ++j) {
    if (count[j] == 0) continue;
    const double o = sigmoid(double(p->opacities[j]));
    const Relocation rel = compute_relocation(o, count[j] + 1);
    const double o_new = std::clamp(rel.opacity, options.min_opacity, 1.0 - double(FLT_EPSILON));
    p->opacities[j] = float(std::log(o_new / (1 - o_new)));
    for (int a = 0; a < 3; ++a)
      p->scales[j * 3 + a] =
          float(std::log(std::exp(double(p->scales[j * 3 + a])) * rel.scale_factor));
  }
}

std::vector<double> opacities_of(const SplatParams& p) {
  std::vector<double> o(p.size());
  for (size_t i = 0; i < p.size(); ++i) o[i] = sigmoid(double(p.opacities[i]));
  return o;
}

}  // namespace

McmcState McmcState::seeded(uint64_t seed) {
  McmcState s;
  s.sample_state = seed ^ 0x2545F4914F6CDD1Dull;
  s.noise = NormalRng(seed ^ 0x9E3779B97F4A7C15ull);
  return s;
}

Relocation compute_relocation(double opacity, int ratio) {
  const int n = std::clamp(ratio, 1, kMaxRatio);
  const double o_new = 1 - std::pow(1 - opacity, 1.0 / n);
  double denom = 0;
  for (int i = 1; i <= n; ++i) {
    double binom = 1;  // C(i-1, k), built up along k
    for (int k = 0; k <= i - 1; ++k) {
      if (k > 0) binom = binom * double(i - k) / double(k);
      const double sign = (k & 1) ? -1.0 : 1.0;
      denom += binom * sign / std::sqrt(double(k + 1)) * std::pow(o_new, k + 1);
    }
  }
  return {o_new, opacity / denom};
}

std::vector<size_t> multinomial_draw(const std::vector<double>& weights,
                                     const std::vector<size_t>& candidates, size_t n,
                                     uint64_t* state) {
  std::vector<double> cdf(candidates.size());
  double total = 0;
  for (size_t i = 0; i < candidates.size(); ++i) cdf[i] = total += weights[candidates[i]];
  std::vector<size_t> out;
  if (candidates.empty() || !(total > 0)) return out;
  synth_random::Rng rng{*state};
  out.reserve(n);
  for (size_t k = 0; k < n; ++k) {
    const double u = rng.uniform() * total;
    size_t i = size_t(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin());
    if (i >= candidates.size()) i = candidates.size() - 1;
    while (weights[candidates[i]] <= 0 && i > 0) --i;  // never a zero-weight entry
    out.push_back(candidates[i]);
  }
  *state = rng.state;
  return out;
}

size_t mcmc_relocate(const McmcStrategyOptions& options, McmcState* state, SplatParams* params,
                     SplatAdam* adam) {
  const std::vector<double> o = opacities_of(*params);
  std::vector<size_t> dead, alive;
  for (size_t i = 0; i < o.size(); ++i) (o[i] <= options.min_opacity ? dead : alive).push_back(i);
  if (dead.empty() || alive.empty()) return 0;  // gsplat: nothing to do / nothing to draw from
  const std::vector<size_t> drawn = multinomial_draw(o, alive, dead.size(), &state->sample_state);
  if (drawn.size() != dead.size()) return 0;
  apply_relocation(options, drawn, params);
  for (size_t i = 0; i < dead.size(); ++i) copy_row(params, dead[i], drawn[i]);
  std::vector<size_t> rows = drawn;
  std::sort(rows.begin(), rows.end());
  rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
  adam->zero_rows(rows);
  return dead.size();
}

size_t mcmc_add(const McmcStrategyOptions& options, McmcState* state, SplatParams* params,
                SplatAdam* adam) {
  const size_t n = params->size();
  const size_t target = std::min(options.cap_max, size_t(1.05 * double(n)));
  if (target <= n) return 0;
  const std::vector<double> o = opacities_of(*params);
  std::vector<size_t> all(n);
  for (size_t i = 0; i < n; ++i) all[i] = i;
  const std::vector<size_t> drawn = multinomial_draw(o, all, target - n, &state->sample_state);
  if (drawn.empty()) return 0;
  apply_relocation(options, drawn, params);
  grow_rows(params, n + drawn.size());
  for (size_t i = 0; i < drawn.size(); ++i) copy_row(params, n + i, drawn[i]);
  std::vector<int64_t> src(n + drawn.size(), -1);
  for (size_t i = 0; i < n; ++i) src[i] = int64_t(i);
  adam->remap_rows(src);
  return drawn.size();
}

void mcmc_inject_noise(double scaler, McmcState* state, SplatParams* params) {
  const size_t n = params->size();
  for (size_t g = 0; g < n; ++g) {
    const float* q = &params->quats[g * 4];
    const double qn = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] +
                                double(q[3]) * q[3]);
    // Three draws per Gaussian whatever it is, so the stream does not depend on the values.
    const double z[3] = {state->noise.next(), state->noise.next(), state->noise.next()};
    if (!(qn > 0) || !std::isfinite(qn)) continue;
    const double w = q[0] / qn, x = q[1] / qn, y = q[2] / qn, zq = q[3] / qn;
    const double R[9] = {
        1 - 2 * (y * y + zq * zq), 2 * (x * y - w * zq),      2 * (x * zq + w * y),
        2 * (x * y + w * zq),      1 - 2 * (x * x + zq * zq), 2 * (y * zq - w * x),
        2 * (x * zq - w * y),      2 * (y * zq + w * x),      1 - 2 * (x * x + y * y)};
    double s2[3];
    for (int a = 0; a < 3; ++a) {
      const double s = std::exp(double(params->scales[g * 3 + a]));
      s2[a] = s * s;
    }
    const double o = sigmoid(double(params->opacities[g]));
    const double gate = 1 / (1 + std::exp(-100 * ((1 - o) - 0.995)));
    double v[3];
    for (int a = 0; a < 3; ++a) v[a] = z[a] * gate * scaler;
    // Sigma v = R diag(s^2) R^T v.
    double rt[3];
    for (int k = 0; k < 3; ++k) rt[k] = (R[k] * v[0] + R[3 + k] * v[1] + R[6 + k] * v[2]) * s2[k];
    for (int a = 0; a < 3; ++a)
      params->means[g * 3 + a] =
          float(double(params->means[g * 3 + a]) +
                (R[3 * a] * rt[0] + R[3 * a + 1] * rt[1] + R[3 * a + 2] * rt[2]));
  }
}

McmcReport mcmc_strategy_step(const McmcStrategyOptions& options, int step, double means_lr,
                              McmcState* state, SplatParams* params, SplatAdam* adam) {
  McmcReport rep;
  if (step < options.refine_stop_iter && step > options.refine_start_iter &&
      step % options.refine_every == 0) {
    rep.refined = true;
    rep.relocated = mcmc_relocate(options, state, params, adam);
    rep.added = mcmc_add(options, state, params, adam);
  }
  mcmc_inject_noise(means_lr * options.noise_lr, state, params);
  return rep;
}

}  // namespace macro::gs::train
