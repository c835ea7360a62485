// Synthetic PFT-SR checkpoints (random weights under the state-dict names, written as
// safetensors) and a double-precision PFT-SR forward written literally from the PyTorch module's
// maths (pad by cat/flip, roll, window partition, dense attention maps kept whole, mask built from
// region slices), for tests/test_pft.cpp. Slow and simple: small configs only.
//
// Legend as in attention/nets/pft.h. Weights: state-dict name -> fp32 values (the I64 buffer
// relative_position_index_SA is not read: the index is rebuilt here from coordinates).
// Top-k follows the documented rule of the engine (torch leaves tie order open): larger value
// first, ties to the smaller position in the row; kept entries in ascending position order.
#pragma once

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "attention/nets/pft.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/status.h"

namespace macro::test {

using PftWeights = std::map<std::string, std::vector<float>>;

// ---- synthetic checkpoints ---------------------------------------------------------------------

// Random weights for every tensor of `cfg`, scaled so activations stay O(1) and attention maps
// are far from uniform (the bias tables are wide), so top-k has clear winners.
inline PftWeights random_pft_weights(const nets::PftConfig& cfg, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  PftWeights ws;
  for (const nets::PftTensorSpec& s : nets::pft_tensor_specs(cfg)) {
    if (s.name == "relative_position_index_SA") continue;
    int64_t numel = 1;
    for (int64_t v : s.shape) numel *= v;
    std::vector<float> v(static_cast<size_t>(numel));
    const auto ends = [&](const char* suf) {
      const std::string x(suf);
      return s.name.size() >= x.size() &&
             s.name.compare(s.name.size() - x.size(), x.size(), x) == 0;
    };
    const bool norm = s.name.find("norm") != std::string::npos;
    float scale = 0.1f;
    if (ends("relative_position_bias_table"))
      scale = 2.0f;
    else if (norm && ends(".weight"))
      scale = 0.2f;
    else if (ends(".weight") && s.shape.size() >= 2) {
      int64_t fan_in = 1;
      for (size_t i = 1; i < s.shape.size(); ++i) fan_in *= s.shape[i];
      scale = float(1.5 / std::sqrt(double(fan_in)));
    }
    for (float& x : v) x = u(rng) * scale + (norm && ends(".weight") ? 1.f : 0.f);
    ws[s.name] = std::move(v);
  }
  return ws;
}

// Writes `ws` (+ the I64 index buffer) as a safetensors file; `drop`, `extra`, `reshape` make it
// wrong on purpose.
inline void write_pft_file(const std::string& path, const nets::PftConfig& cfg,
                           const PftWeights& ws, const std::string& drop = "", bool extra = false,
                           const std::string& reshape = "", bool bad_index = false) {
  std::vector<TensorToWrite> t;
  std::vector<int64_t> rpi = nets::pft_relative_position_index(cfg.window);
  if (bad_index) rpi[5] += 1;
  const int64_t n = int64_t(cfg.window) * cfg.window;
  std::vector<std::vector<int64_t>> shapes;
  shapes.reserve(ws.size() + 2);
  for (const nets::PftTensorSpec& s : nets::pft_tensor_specs(cfg)) {
    if (s.name == drop) continue;
    if (s.name == "relative_position_index_SA") {
      t.push_back({s.name, DType::kI64, {n, n}, rpi.data()});
      continue;
    }
    shapes.push_back(s.shape);
    if (s.name == reshape) shapes.back() = {int64_t(ws.at(s.name).size())};
    t.push_back({s.name, DType::kF32, shapes.back(), ws.at(s.name).data()});
  }
  static const float one = 1.f;
  if (extra)
    t.push_back({"layers.0.residual_group.layers.0.attn_win.logit_scale", DType::kF32, {1}, &one});
  MACRO_CHECK(write_safetensors(path, t).is_ok());
}

namespace pft_ref {

using Vec = std::vector<double>;

inline const std::vector<float>& w(const PftWeights& ws, const std::string& name) {
  return ws.at(name);
}

// y [Cout, H, W] = conv k x k pad k/2 (groups = 1 or depthwise) of x [Cin, H, W].
inline Vec conv(const Vec& x, int64_t cin, int64_t h, int64_t wd, const std::vector<float>& wt,
                const std::vector<float>& b, int64_t cout, int k, bool depthwise) {
  Vec y(size_t(cout * h * wd));
  const int r = k / 2;
  for (int64_t co = 0; co < cout; ++co)
    for (int64_t yy = 0; yy < h; ++yy)
      for (int64_t xx = 0; xx < wd; ++xx) {
        double acc = b[size_t(co)];
        const int64_t ci0 = depthwise ? co : 0, ci1 = depthwise ? co + 1 : cin;
        for (int64_t ci = ci0; ci < ci1; ++ci)
          for (int dy = 0; dy < k; ++dy)
            for (int dx = 0; dx < k; ++dx) {
              const int64_t iy = yy + dy - r, ix = xx + dx - r;
              if (iy < 0 || iy >= h || ix < 0 || ix >= wd) continue;
              const int64_t wi =
                  depthwise ? (co * k + dy) * k + dx : ((co * cin + ci) * k + dy) * k + dx;
              acc += double(wt[size_t(wi)]) * x[size_t((ci * h + iy) * wd + ix)];
            }
        y[size_t((co * h + yy) * wd + xx)] = acc;
      }
  return y;
}

inline Vec layer_norm(const Vec& x, int64_t m, int64_t c, const std::vector<float>& g,
                      const std::vector<float>& b, double eps) {
  Vec y(x.size());
  for (int64_t i = 0; i < m; ++i) {
    double mean = 0, var = 0;
    for (int64_t j = 0; j < c; ++j) mean += x[size_t(i * c + j)];
    mean /= double(c);
    for (int64_t j = 0; j < c; ++j)
      var += (x[size_t(i * c + j)] - mean) * (x[size_t(i * c + j)] - mean);
    var /= double(c);
    for (int64_t j = 0; j < c; ++j)
      y[size_t(i * c + j)] =
          (x[size_t(i * c + j)] - mean) / std::sqrt(var + eps) * g[size_t(j)] + b[size_t(j)];
  }
  return y;
}

// y [M, out] = x [M, in] W^T + b
inline Vec linear(const Vec& x, int64_t m, int64_t in, const std::vector<float>& wt,
                  const std::vector<float>& b, int64_t out) {
  Vec y(size_t(m * out));
  for (int64_t i = 0; i < m; ++i)
    for (int64_t o = 0; o < out; ++o) {
      double acc = b[size_t(o)];
      for (int64_t j = 0; j < in; ++j)
        acc += x[size_t(i * in + j)] * double(wt[size_t(o * in + j)]);
      y[size_t(i * out + o)] = acc;
    }
  return y;
}

inline double gelu(double v) {
  return 0.5 * v * (1.0 + std::erf(v / std::sqrt(2.0)));
}

// tokens [N, C] <-> image [C, H, W]
inline Vec to_image(const Vec& t, int64_t n, int64_t c) {
  Vec y(t.size());
  for (int64_t p = 0; p < n; ++p)
    for (int64_t j = 0; j < c; ++j) y[size_t(j * n + p)] = t[size_t(p * c + j)];
  return y;
}
inline Vec to_tokens(const Vec& im, int64_t n, int64_t c) {
  Vec y(im.size());
  for (int64_t p = 0; p < n; ++p)
    for (int64_t j = 0; j < c; ++j) y[size_t(p * c + j)] = im[size_t(j * n + p)];
  return y;
}

// One parity's focusing state: per (window, head, query) row, the values and key positions (an
// empty index list = all keys, dense).
struct State {
  bool has_values = false, has_index = false;
  std::vector<Vec> values;              // [nwin * heads * n] rows
  std::vector<std::vector<int>> index;  // same rows
};

}  // namespace pft_ref

// image [H, W, 3] -> [H s, W s, 3] in double (not clamped). Requires the padding to be at most the
// image side (as the PyTorch module does).
inline std::vector<double> pft_reference_forward(const macro::nets::PftConfig& cfg,
                                                 const PftWeights& W, const std::vector<float>& img,
                                                 int H, int Wd) {
  using namespace pft_ref;
  const int64_t ws = cfg.window, n = ws * ws, C = cfg.embed, F = cfg.mlp_hidden;
  const int heads = cfg.heads;
  const int64_t d = C / heads, s = cfg.upscale;
  const int64_t hp = (H + ws - 1) / ws * ws, wp = (Wd + ws - 1) / ws * ws, N = hp * wp;
  // x = cat([x, flip(x, H)], H)[:hp], then the same along W.
  Vec x(size_t(3 * N));
  for (int64_t c = 0; c < 3; ++c)
    for (int64_t y = 0; y < hp; ++y)
      for (int64_t xx = 0; xx < wp; ++xx) {
        const int64_t sy = y < H ? y : 2 * H - 1 - y, sx = xx < Wd ? xx : 2 * Wd - 1 - xx;
        x[size_t((c * hp + y) * wp + xx)] =
            (double(img[size_t((sy * Wd + sx) * 3 + c)]) - double(cfg.mean[c])) * cfg.img_range;
      }
  const Vec f0 =
      conv(x, 3, hp, wp, w(W, "conv_first.weight"), w(W, "conv_first.bias"), C, 3, false);
  Vec t = layer_norm(to_tokens(f0, N, C), N, C, w(W, "patch_embed.norm.weight"),
                     w(W, "patch_embed.norm.bias"), cfg.ln_eps);

  // Relative position index from coordinates (calculate_rpi_sa).
  std::vector<int> rpi(size_t(n * n));
  for (int64_t i = 0; i < n; ++i)
    for (int64_t j = 0; j < n; ++j) {
      const int64_t dy = i / ws - j / ws + ws - 1, dx = i % ws - j % ws + ws - 1;
      rpi[size_t(i * n + j)] = int(dy * (2 * ws - 1) + dx);
    }
  // Shift mask (calculate_mask): region count per (row slice, column slice), partitioned.
  const int64_t nwy = hp / ws, nwx = wp / ws, nwin = nwy * nwx;
  std::vector<int> img_mask(static_cast<size_t>(N));
  for (int64_t y = 0; y < hp; ++y)
    for (int64_t xx = 0; xx < wp; ++xx) {
      const int hs = y < hp - ws ? 0 : (y < hp - ws / 2 ? 1 : 2);
      const int wsl = xx < wp - ws ? 0 : (xx < wp - ws / 2 ? 1 : 2);
      img_mask[size_t(y * wp + xx)] = hs * 3 + wsl;
    }
  auto win_pos = [&](int64_t win, int64_t i) {  // window-partition position -> (y, x)
    return std::pair<int64_t, int64_t>{(win / nwx) * ws + i / ws, (win % nwx) * ws + i % ws};
  };

  pft_ref::State state[2];
  int layer_id = 0;
  for (size_t g = 0; g < cfg.depths.size(); ++g) {
    const Vec t_group = t;
    for (int li = 0; li < cfg.depths[g]; ++li, ++layer_id) {
      const std::string p =
          "layers." + std::to_string(g) + ".residual_group.layers." + std::to_string(li) + ".";
      const int64_t shift = li % 2 ? ws / 2 : 0;
      const int sp = shift ? 1 : 0;
      const int topk = cfg.topk[size_t(layer_id)];
      const Vec xn =
          layer_norm(t, N, C, w(W, p + "norm1.weight"), w(W, p + "norm1.bias"), cfg.ln_eps);
      const Vec qkv = linear(xn, N, C, w(W, p + "wqkv.weight"), w(W, p + "wqkv.bias"), 3 * C);
      Vec vimg(size_t(C * N));
      for (int64_t q = 0; q < N; ++q)
        for (int64_t j = 0; j < C; ++j)
          vimg[size_t(j * N + q)] = qkv[size_t(q * 3 * C + 2 * C + j)];
      Vec lepe = conv(vimg, C, hp, wp, w(W, p + "v_LePE.depthwise_conv.0.weight"),
                      w(W, p + "v_LePE.depthwise_conv.0.bias"), C, cfg.ffn_kernel, true);
      for (double& v : lepe) v = gelu(v);
      lepe = to_tokens(lepe, N, C);
      const std::vector<float>& table = w(W, p + "attn_win.relative_position_bias_table");
      const int cols = cfg.bias_columns();
      Vec attn_out(size_t(N * C));
      pft_ref::State& st = state[sp];
      pft_ref::State next;
      next.values.resize(size_t(nwin * heads * n));
      next.index.resize(size_t(nwin * heads * n));
      for (int64_t win = 0; win < nwin; ++win)
        for (int h = 0; h < heads; ++h)
          for (int64_t i = 0; i < n; ++i) {
            // the rolled image: shifted[y][x] = orig[(y + shift) % hp][(x + shift) % wp]
            auto orig = [&](int64_t tok) {
              const auto [yy, xx] = win_pos(win, tok);
              return ((yy + shift) % hp) * wp + (xx + shift) % wp;
            };
            const size_t row = size_t((win * heads + h) * n + i);
            const int64_t pi = orig(i);
            const double scale = 1.0 / std::sqrt(double(d));
            std::vector<int> keys;
            if (st.has_index) {
              keys = st.index[row];
            } else {
              keys.resize(size_t(n));
              std::iota(keys.begin(), keys.end(), 0);
            }
            Vec a(keys.size());
            for (size_t jj = 0; jj < keys.size(); ++jj) {
              const int64_t j = keys[jj], pj = orig(j);
              double sdot = 0;
              for (int64_t e = 0; e < d; ++e)
                sdot += qkv[size_t(pi * 3 * C + h * d + e)] * scale *
                        qkv[size_t(pj * 3 * C + C + h * d + e)];
              sdot += table[size_t(rpi[size_t(i * n + j)] * cols + (cols == 1 ? 0 : h))];
              if (shift && !st.has_index) {
                const auto [yi, xi] = win_pos(win, i);
                const auto [yj, xj] = win_pos(win, j);
                if (img_mask[size_t(yi * wp + xi)] != img_mask[size_t(yj * wp + xj)])
                  sdot += -100.0;
              }
              a[jj] = sdot;
            }
            const double mx = *std::max_element(a.begin(), a.end());
            double sum = 0;
            for (double& v : a) sum += (v = std::exp(v - mx));
            for (double& v : a) v /= sum;
            if (st.has_values) {
              double s2 = 0;
              for (size_t jj = 0; jj < a.size(); ++jj) s2 += (a[jj] *= st.values[row][jj]);
              for (double& v : a) v = (v + 1e-20) / (s2 + 1e-20);
            }
            if (topk < n) {
              std::vector<int> order(a.size());
              std::iota(order.begin(), order.end(), 0);
              std::stable_sort(order.begin(), order.end(),
                               [&](int u, int v) { return a[size_t(u)] > a[size_t(v)]; });
              order.resize(size_t(topk));
              std::sort(order.begin(), order.end());
              Vec na;
              std::vector<int> nk;
              for (int o : order) na.push_back(a[size_t(o)]), nk.push_back(keys[size_t(o)]);
              a = na, keys = nk;
              next.has_index = true;
            } else {
              next.has_index = st.has_index;
            }
            next.has_values = true;
            for (int64_t e = 0; e < d; ++e) {
              double acc = 0;
              for (size_t jj = 0; jj < keys.size(); ++jj)
                acc += a[jj] * qkv[size_t(orig(keys[jj]) * 3 * C + 2 * C + h * d + e)];
              attn_out[size_t(pi * C + h * d + e)] = acc + lepe[size_t(pi * C + h * d + e)];
            }
            next.values[row] = a;
            next.index[row] = keys;
          }
      state[sp] = std::move(next);
      const Vec pr = linear(attn_out, N, C, w(W, p + "attn_win.proj.weight"),
                            w(W, p + "attn_win.proj.bias"), C);
      for (size_t q = 0; q < t.size(); ++q) t[q] += pr[q];
      const Vec xn2 =
          layer_norm(t, N, C, w(W, p + "norm2.weight"), w(W, p + "norm2.bias"), cfg.ln_eps);
      Vec a1 = linear(xn2, N, C, w(W, p + "convffn.fc1.weight"), w(W, p + "convffn.fc1.bias"), F);
      for (double& v : a1) v = gelu(v);
      Vec dwo =
          conv(to_image(a1, N, F), F, hp, wp, w(W, p + "convffn.dwconv.depthwise_conv.0.weight"),
               w(W, p + "convffn.dwconv.depthwise_conv.0.bias"), F, cfg.ffn_kernel, true);
      for (double& v : dwo) v = gelu(v);
      dwo = to_tokens(dwo, N, F);
      for (size_t q = 0; q < a1.size(); ++q) a1[q] += dwo[q];
      const Vec f2 =
          linear(a1, N, F, w(W, p + "convffn.fc2.weight"), w(W, p + "convffn.fc2.bias"), C);
      for (size_t q = 0; q < t.size(); ++q) t[q] += f2[q];
    }
    const std::string gp = "layers." + std::to_string(g) + ".conv.";
    const Vec cv =
        conv(to_image(t, N, C), C, hp, wp, w(W, gp + "weight"), w(W, gp + "bias"), C, 3, false);
    t = to_tokens(cv, N, C);
    for (size_t q = 0; q < t.size(); ++q) t[q] += t_group[q];
  }
  t = layer_norm(t, N, C, w(W, "norm.weight"), w(W, "norm.bias"), cfg.ln_eps);
  Vec f = conv(to_image(t, N, C), C, hp, wp, w(W, "conv_after_body.weight"),
               w(W, "conv_after_body.bias"), C, 3, false);
  for (size_t q = 0; q < f.size(); ++q) f[q] += f0[q];
  const Vec up =
      conv(f, C, hp, wp, w(W, "upsample.0.weight"), w(W, "upsample.0.bias"), 3 * s * s, 3, false);
  std::vector<double> out(size_t(H * s * Wd * s * 3));
  for (int64_t y = 0; y < H * s; ++y)
    for (int64_t xx = 0; xx < Wd * s; ++xx)
      for (int64_t c = 0; c < 3; ++c) {
        const int64_t plane = c * s * s + (y % s) * s + xx % s;
        out[size_t((y * Wd * s + xx) * 3 + c)] =
            up[size_t((plane * hp + y / s) * wp + xx / s)] / cfg.img_range + cfg.mean[c];
      }
  return out;
}

}  // namespace macro::test
