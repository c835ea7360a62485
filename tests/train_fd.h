// Central differences of a training loss for the gradient tests (test_train.cpp,
// test_train_modes.cpp): the estimates of one parameter array at two step sizes, and an analytic
// gradient checked against them.
#pragma once

#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "attention/runtime/cpu.h"
#include "gs/formats/splat_params.h"
#include "gs/train/diff_render.h"
#include "gs/train/train_kernels.h"
#include "tests/test_support.h"

namespace macro::test {

// Per entry of p.*field: {(L(x + h) - L(x - h)) / 2h at h = 1e-4 max(1, |x|), the same at a
// quarter of that step}, with `loss` evaluated in double.
inline std::vector<std::array<double, 2>> fd_estimates(
    gs::SplatParams p, std::vector<float> gs::SplatParams::*field,
    const std::function<double(const gs::SplatParams&)>& loss) {
  std::vector<float>& x = p.*field;
  std::vector<std::array<double, 2>> out(x.size());
  for (size_t i = 0; i < x.size(); ++i) {
    const float x0 = x[i];
    for (int k = 0; k < 2; ++k) {
      const double h = (k == 0 ? 1e-4 : 2.5e-5) * std::max(1.0, std::abs(double(x0)));
      const float xp = float(x0 + h), xm = float(x0 - h);
      x[i] = xp;
      const double lp = loss(p);
      x[i] = xm;
      const double lm = loss(p);
      x[i] = x0;
      out[i][size_t(k)] = (lp - lm) / (double(xp) - double(xm));
    }
  }
  return out;
}

// The analytic gradient against the estimates, relative error <= 5e-3. A step that straddles a
// discontinuity (a pixel's alpha crossing 1/255 or T crossing 1e-4) shows as the two step sizes
// disagreeing; such entries are skipped, and at most 10% may be. Returns the worst relative error.
inline double check_fd(const std::vector<float>& analytic,
                       const std::vector<std::array<double, 2>>& est, const char* name) {
  REQUIRE(est.size() == analytic.size());
  size_t checked = 0, skipped = 0, nonzero = 0;
  double worst = 0;
  for (size_t i = 0; i < est.size(); ++i) {
    const double scale = std::max({std::abs(est[i][0]), std::abs(est[i][1]), 1e-6});
    if (std::abs(est[i][0] - est[i][1]) > 2e-3 * scale) {
      ++skipped;
      continue;
    }
    ++checked;
    nonzero += analytic[i] != 0.f;
    const double err = std::abs(double(analytic[i]) - est[i][1]) /
                       std::max({std::abs(est[i][1]), std::abs(double(analytic[i])), 1e-6});
    worst = std::max(worst, err);
    INFO(name << "[" << i << "]: analytic " << analytic[i] << ", central difference " << est[i][1]
              << " (" << est[i][0] << " at 4x the step)");
    CHECK(err <= 5e-3);
  }
  INFO(name << ": " << checked << " checked, " << skipped << " skipped, worst relative error "
            << worst);
  CHECK(skipped * 10 <= est.size());
  CHECK(nonzero * 2 >= checked);
  return worst;
}

// The gradient paths to check: the double reference ("scalar") and each float table this
// machine has (AVX512-BF16 and AMX machines run the AVX-512 one: each table once).
inline std::vector<std::pair<std::string, Isa>> train_gradient_paths() {
  std::vector<std::pair<std::string, Isa>> paths = {{"scalar", Isa::kScalar}};
  std::vector<const gs::train::TrainKernels*> seen;
  for (Isa isa : supported_isas()) {
    const gs::train::TrainKernels* k = gs::train::train_kernels_for(isa);
    if (k == nullptr || std::find(seen.begin(), seen.end(), k) != seen.end()) continue;
    seen.push_back(k);
    paths.push_back({k->name, isa});
  }
  return paths;
}

// Every parameter kind with its gradient (shN only above SH degree 0).
struct ParamKind {
  const char* name;
  std::vector<float> gs::SplatParams::*field;
  std::vector<float> gs::train::SplatGrads::*grad;
};
inline std::vector<ParamKind> param_kinds(int degree) {
  using gs::SplatParams;
  using gs::train::SplatGrads;
  std::vector<ParamKind> kinds = {{"means", &SplatParams::means, &SplatGrads::means},
                                  {"scales", &SplatParams::scales, &SplatGrads::scales},
                                  {"quats", &SplatParams::quats, &SplatGrads::quats},
                                  {"opacities", &SplatParams::opacities, &SplatGrads::opacities},
                                  {"sh0", &SplatParams::sh0, &SplatGrads::sh0}};
  if (degree > 0) kinds.push_back({"shN", &SplatParams::shN, &SplatGrads::shN});
  return kinds;
}

}  // namespace macro::test
