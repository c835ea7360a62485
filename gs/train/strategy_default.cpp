// gsplat's DefaultStrategy (strategy_default.h).
#include "gs/train/strategy_default.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "gs/synth/synth_random.h"

namespace macro::gs::train {
namespace {

// params' rows in the order src gives (every src[i] a valid old row).
SplatParams gather_rows(const SplatParams& p, const std::vector<size_t>& src) {
  SplatParams out;
  out.resize(src.size(), p.sh_degree);
  const size_t R3 = size_t(p.sh_rest()) * 3;
  for (size_t i = 0; i < src.size(); ++i) {
    const size_t r = src[i];
    std::copy_n(p.means.begin() + 3 * r, 3, out.means.begin() + 3 * i);
    std::copy_n(p.scales.begin() + 3 * r, 3, out.scales.begin() + 3 * i);
    std::copy_n(p.quats.begin() + 4 * r, 4, out.quats.begin() + 4 * i);
    out.opacities[i] = p.opacities[r];
    std::copy_n(p.sh0.begin() + 3 * r, 3, out.sh0.begin() + 3 * i);
    std::copy_n(p.shN.begin() + R3 * r, R3, out.shN.begin() + R3 * i);
  }
  return out;
}

template <class T>
std::vector<T> gather(const std::vector<T>& v, const std::vector<size_t>& src) {
  std::vector<T> out(src.size());
  for (size_t i = 0; i < src.size(); ++i) out[i] = v[src[i]];
  return out;
}

void gather_state(DefaultStrategyState* state, const std::vector<size_t>& src, size_t n_old) {
  if (state->grad2d.size() != n_old) state->grad2d.assign(n_old, 0.0);
  if (state->count.size() != n_old) state->count.assign(n_old, 0);
  state->grad2d = gather(state->grad2d, src);
  state->count = gather(state->count, src);
}

double max_scale(const SplatParams& p, size_t g) {
  return std::exp(double(std::max({p.scales[3 * g], p.scales[3 * g + 1], p.scales[3 * g + 2]})));
}

double sigmoid(double x) {
  return 1.0 / (1.0 + std::exp(-x));
}

}  // namespace

double NormalRng::next() {
  if (have_spare_) {
    have_spare_ = false;
    return spare_;
  }
  synth_random::Rng rng{state_};
  double u1;
  do u1 = rng.uniform();
  while (u1 <= 0.0);
  const double u2 = rng.uniform();
  state_ = rng.state;
  const double r = std::sqrt(-2.0 * std::log(u1)), a = 2.0 * M_PI * u2;
  spare_ = r * std::sin(a);
  have_spare_ = true;
  return r * std::cos(a);
}

void accumulate_grad2d(const std::vector<float>& g, const std::vector<uint8_t>& visible, int width,
                       int height, DefaultStrategyState* state) {
  const size_t n = visible.size();
  MACRO_CHECK(g.size() == 2 * n);
  if (state->grad2d.size() != n) state->grad2d.assign(n, 0.0);
  if (state->count.size() != n) state->count.assign(n, 0);
  // gsplat: grads[..., 0] *= width / 2 * n_cameras; grads[..., 1] *= height / 2 * n_cameras
  // (one camera per step here).
  const double sx = width / 2.0, sy = height / 2.0;
  for (size_t i = 0; i < n; ++i) {
    if (!visible[i]) continue;
    const double gx = double(g[2 * i]) * sx, gy = double(g[2 * i + 1]) * sy;
    state->grad2d[i] += std::sqrt(gx * gx + gy * gy);
    state->count[i] += 1;
  }
}

void duplicate_gaussians(const std::vector<uint8_t>& mask, SplatParams* params, SplatAdam* adam,
                         DefaultStrategyState* state) {
  const size_t n = params->size();
  MACRO_CHECK(mask.size() == n);
  std::vector<size_t> src(n);
  for (size_t i = 0; i < n; ++i) src[i] = i;
  for (size_t i = 0; i < n; ++i)
    if (mask[i]) src.push_back(i);
  std::vector<int64_t> opt(src.size(), -1);
  for (size_t i = 0; i < n; ++i) opt[i] = int64_t(i);
  *params = gather_rows(*params, src);
  if (adam) adam->remap_rows(opt);
  if (state) gather_state(state, src, n);
}

void split_gaussians(const std::vector<uint8_t>& mask, NormalRng& rng, SplatParams* params,
                     SplatAdam* adam, DefaultStrategyState* state) {
  const size_t n = params->size();
  MACRO_CHECK(mask.size() == n);
  std::vector<size_t> rest, sel;
  for (size_t i = 0; i < n; ++i) (mask[i] ? sel : rest).push_back(i);
  // z ~ N(0, I) as torch.randn(2, len(sel), 3): child b of selected Gaussian s, axis j.
  std::vector<double> z(2 * sel.size() * 3);
  for (double& v : z) v = rng.next();
  std::vector<size_t> src = rest;
  for (int b = 0; b < 2; ++b) src.insert(src.end(), sel.begin(), sel.end());
  SplatParams out = gather_rows(*params, src);
  for (int b = 0; b < 2; ++b)
    for (size_t s = 0; s < sel.size(); ++s) {
      const size_t g = sel[s], row = rest.size() + size_t(b) * sel.size() + s;
      const float* q = &params->quats[4 * g];
      const double qn = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] +
                                  double(q[3]) * q[3]);
      const double w = q[0] / qn, x = q[1] / qn, y = q[2] / qn, zq = q[3] / qn;
      const double R[3][3] = {
          {1 - 2 * (y * y + zq * zq), 2 * (x * y - w * zq), 2 * (x * zq + w * y)},
          {2 * (x * y + w * zq), 1 - 2 * (x * x + zq * zq), 2 * (y * zq - w * x)},
          {2 * (x * zq - w * y), 2 * (y * zq + w * x), 1 - 2 * (x * x + y * y)}};
      double sz[3];
      for (int j = 0; j < 3; ++j)
        sz[j] =
            std::exp(double(params->scales[3 * g + j])) * z[(size_t(b) * sel.size() + s) * 3 + j];
      for (int i = 0; i < 3; ++i) {
        const double d = R[i][0] * sz[0] + R[i][1] * sz[1] + R[i][2] * sz[2];
        out.means[3 * row + i] = float(double(params->means[3 * g + i]) + d);
        out.scales[3 * row + i] =
            float(std::log(std::exp(double(params->scales[3 * g + i])) / 1.6));
      }
    }
  std::vector<int64_t> opt(src.size(), -1);
  for (size_t i = 0; i < rest.size(); ++i) opt[i] = int64_t(rest[i]);
  *params = std::move(out);
  if (adam) adam->remap_rows(opt);
  if (state) gather_state(state, src, n);
}

void remove_gaussians(const std::vector<uint8_t>& mask, SplatParams* params, SplatAdam* adam,
                      DefaultStrategyState* state) {
  const size_t n = params->size();
  MACRO_CHECK(mask.size() == n);
  std::vector<size_t> keep;
  for (size_t i = 0; i < n; ++i)
    if (!mask[i]) keep.push_back(i);
  std::vector<int64_t> opt(keep.begin(), keep.end());
  *params = gather_rows(*params, keep);
  if (adam) adam->remap_rows(opt);
  if (state) gather_state(state, keep, n);
}

void reset_opacities(double value, SplatParams* params, SplatAdam* adam) {
  const float cap = float(std::log(value / (1.0 - value)));
  for (float& o : params->opacities) o = std::min(o, cap);
  if (adam) adam->zero_opacity_state();
}

Result<std::pair<size_t, size_t>> grow_gaussians(const DefaultStrategyOptions& o,
                                                 double scene_scale, NormalRng& rng,
                                                 SplatParams* params, SplatAdam* adam,
                                                 DefaultStrategyState* state) {
  const size_t n = params->size();
  if (state->grad2d.size() != n) state->grad2d.assign(n, 0.0);
  if (state->count.size() != n) state->count.assign(n, 0);
  std::vector<uint8_t> dupli(n, 0), split(n, 0);
  size_t n_dupli = 0, n_split = 0;
  for (size_t i = 0; i < n; ++i) {
    const double avg = state->grad2d[i] / double(std::max(state->count[i], 1));
    const bool high = avg > o.grow_grad2d;
    const bool small = max_scale(*params, i) <= o.grow_scale3d * scene_scale;
    dupli[i] = high && small;
    split[i] = high && !small;
    n_dupli += dupli[i];
    n_split += split[i];
  }
  if (o.max_gaussians > 0 && n + n_dupli + n_split > o.max_gaussians)
    return Status::error("--max-gaussians " + std::to_string(o.max_gaussians) +
                         ": densification would grow " + std::to_string(n) + " Gaussians to " +
                         std::to_string(n + n_dupli + n_split) + " (" + std::to_string(n_dupli) +
                         " duplicated, " + std::to_string(n_split) + " split); raise the limit");
  if (n_dupli > 0) duplicate_gaussians(dupli, params, adam, state);
  split.resize(params->size(), 0);  // the copies are not split
  if (n_split > 0) split_gaussians(split, rng, params, adam, state);
  return std::make_pair(n_dupli, n_split);
}

size_t prune_gaussians(const DefaultStrategyOptions& o, int step, double scene_scale,
                       SplatParams* params, SplatAdam* adam, DefaultStrategyState* state) {
  const size_t n = params->size();
  std::vector<uint8_t> prune(n, 0);
  size_t count = 0;
  for (size_t i = 0; i < n; ++i) {
    bool p = sigmoid(double(params->opacities[i])) < o.prune_opa;
    if (step > o.reset_every) p = p || max_scale(*params, i) > o.prune_scale3d * scene_scale;
    prune[i] = p;
    count += p;
  }
  if (count > 0) remove_gaussians(prune, params, adam, state);
  return count;
}

Result<RefineReport> default_strategy_step(const DefaultStrategyOptions& o, int step,
                                           double scene_scale,
                                           const std::vector<float>& means2d_grad,
                                           const std::vector<uint8_t>& visible, int width,
                                           int height, NormalRng& rng, SplatParams* params,
                                           SplatAdam* adam, DefaultStrategyState* state) {
  RefineReport rep;
  if (step >= o.refine_stop_iter) return rep;
  accumulate_grad2d(means2d_grad, visible, width, height, state);
  if (step > o.refine_start_iter && o.refine_every > 0 && step % o.refine_every == 0 &&
      (o.reset_every <= 0 || step % o.reset_every >= o.pause_refine_after_reset)) {
    MACRO_ASSIGN_OR_RETURN(auto grown, grow_gaussians(o, scene_scale, rng, params, adam, state));
    rep.duplicated = grown.first;
    rep.split = grown.second;
    rep.pruned = prune_gaussians(o, step, scene_scale, params, adam, state);
    std::fill(state->grad2d.begin(), state->grad2d.end(), 0.0);
    std::fill(state->count.begin(), state->count.end(), 0);
    rep.refined = true;
  }
  if (o.reset_every > 0 && step % o.reset_every == 0 && step > 0) {
    reset_opacities(o.prune_opa * 2.0, params, adam);
    rep.reset = true;
  }
  return rep;
}

}  // namespace macro::gs::train
