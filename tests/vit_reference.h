// A double-precision Vision Transformer written from the maths of attention/nets/vit.h: the
// reference the ViT tests (test_vit.cpp) and the DreamSim tests (test_dreamsim.cpp) compare
// against. Legend: D width, T tokens, p patch, gh x gw token grid.
#pragma once

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "attention/nets/vit.h"

namespace macro::test {

// The fp32 values of a tensor by its full name (the config's prefix included).
using VitTensorFn = std::function<const std::vector<float>&(const std::string&)>;

// y [M, out] = x [M, in] W^T (+ b); W [out, in].
inline std::vector<double> vit_ref_linear(const std::vector<double>& x, int64_t m, int64_t in,
                                          int64_t out, const std::vector<float>& wt,
                                          const std::vector<float>* b) {
  std::vector<double> y(size_t(m * out));
  for (int64_t i = 0; i < m; ++i)
    for (int64_t o = 0; o < out; ++o) {
      double s = b ? double((*b)[size_t(o)]) : 0.0;
      for (int64_t k = 0; k < in; ++k) s += x[size_t(i * in + k)] * double(wt[size_t(o * in + k)]);
      y[size_t(i * out + o)] = s;
    }
  return y;
}

inline std::vector<double> vit_ref_layer_norm(const std::vector<double>& x, int64_t m, int64_t d,
                                              const std::vector<float>& g,
                                              const std::vector<float>& b, double eps) {
  std::vector<double> y(x.size());
  for (int64_t i = 0; i < m; ++i) {
    double mean = 0, var = 0;
    for (int64_t k = 0; k < d; ++k) mean += x[size_t(i * d + k)];
    mean /= double(d);
    for (int64_t k = 0; k < d; ++k) var += std::pow(x[size_t(i * d + k)] - mean, 2);
    var /= double(d);
    const double inv = 1.0 / std::sqrt(var + eps);
    for (int64_t k = 0; k < d; ++k)
      y[size_t(i * d + k)] = (x[size_t(i * d + k)] - mean) * inv * g[size_t(k)] + b[size_t(k)];
  }
  return y;
}

struct VitRefOut {
  std::vector<double> tokens;  // [T, D] after the final norm
  std::vector<double> cls;     // [out_dim]
};

// The ViT of vit.h in double precision. pos: the (resampled) pos_embed [T, D] to add.
inline VitRefOut vit_reference_forward(const nets::VitConfig& cfg, const VitTensorFn& w,
                                       const std::vector<double>& image, int64_t h, int64_t wd,
                                       const std::vector<float>& pos) {
  const std::string& pre = cfg.prefix;
  const int64_t d = cfg.width, p = cfg.patch, gh = h / p, gw = wd / p, t = 1 + gh * gw;
  const int64_t ff = cfg.mlp_hidden, dh = d / cfg.heads;
  const double eps = cfg.ln_eps;
  std::vector<double> x(size_t(t * d));
  const auto& cls = w(pre + "cls_token");
  const auto& pw = w(pre + "patch_embed.proj.weight");
  for (int64_t c = 0; c < d; ++c) x[size_t(c)] = double(cls[size_t(c)]) + pos[size_t(c)];
  for (int64_t py = 0; py < gh; ++py)
    for (int64_t px = 0; px < gw; ++px)
      for (int64_t o = 0; o < d; ++o) {
        double s = cfg.patch_bias ? double(w(pre + "patch_embed.proj.bias")[size_t(o)]) : 0.0;
        for (int64_t ch = 0; ch < 3; ++ch)
          for (int64_t ky = 0; ky < p; ++ky)
            for (int64_t kx = 0; kx < p; ++kx)
              s += double(pw[size_t(((o * 3 + ch) * p + ky) * p + kx)]) *
                   image[size_t((ch * h + py * p + ky) * wd + px * p + kx)];
        const int64_t tok = 1 + py * gw + px;
        x[size_t(tok * d + o)] = s + pos[size_t(tok * d + o)];
      }
  if (cfg.norm_pre)
    x = vit_ref_layer_norm(x, t, d, w(pre + "norm_pre.weight"), w(pre + "norm_pre.bias"), eps);
  for (int i = 0; i < cfg.depth; ++i) {
    const std::string b = pre + "blocks." + std::to_string(i) + ".";
    auto n = vit_ref_layer_norm(x, t, d, w(b + "norm1.weight"), w(b + "norm1.bias"), eps);
    auto qkv = vit_ref_linear(n, t, d, 3 * d, w(b + "attn.qkv.weight"),
                              cfg.qkv_bias ? &w(b + "attn.qkv.bias") : nullptr);
    std::vector<double> att(size_t(t * d));
    for (int hd = 0; hd < cfg.heads; ++hd)
      for (int64_t qi = 0; qi < t; ++qi) {
        std::vector<double> s(static_cast<size_t>(t));
        double mx = -1e300;
        for (int64_t kj = 0; kj < t; ++kj) {
          double dot = 0;
          for (int64_t c = 0; c < dh; ++c)
            dot +=
                qkv[size_t(qi * 3 * d + hd * dh + c)] * qkv[size_t(kj * 3 * d + d + hd * dh + c)];
          s[size_t(kj)] = dot / std::sqrt(double(dh));
          mx = std::max(mx, s[size_t(kj)]);
        }
        double sum = 0;
        for (double& v : s) sum += (v = std::exp(v - mx));
        for (int64_t c = 0; c < dh; ++c) {
          double a = 0;
          for (int64_t kj = 0; kj < t; ++kj)
            a += s[size_t(kj)] * qkv[size_t(kj * 3 * d + 2 * d + hd * dh + c)];
          att[size_t(qi * d + hd * dh + c)] = a / sum;
        }
      }
    auto o = vit_ref_linear(att, t, d, d, w(b + "attn.proj.weight"), &w(b + "attn.proj.bias"));
    for (int64_t k = 0; k < t * d; ++k)
      x[size_t(k)] +=
          (cfg.layer_scale ? double(w(b + "ls1.gamma")[size_t(k % d)]) : 1.0) * o[size_t(k)];
    n = vit_ref_layer_norm(x, t, d, w(b + "norm2.weight"), w(b + "norm2.bias"), eps);
    auto hid = vit_ref_linear(n, t, d, ff, w(b + "mlp.fc1.weight"), &w(b + "mlp.fc1.bias"));
    for (double& v : hid)
      v = cfg.act == nets::VitAct::kQuickGelu ? v / (1.0 + std::exp(-1.702 * v))
                                              : 0.5 * v * (1.0 + std::erf(v / std::sqrt(2.0)));
    auto y = vit_ref_linear(hid, t, ff, d, w(b + "mlp.fc2.weight"), &w(b + "mlp.fc2.bias"));
    for (int64_t k = 0; k < t * d; ++k)
      x[size_t(k)] +=
          (cfg.layer_scale ? double(w(b + "ls2.gamma")[size_t(k % d)]) : 1.0) * y[size_t(k)];
  }
  VitRefOut r;
  r.tokens = cfg.final_norm
                 ? vit_ref_layer_norm(x, t, d, w(pre + "norm.weight"), w(pre + "norm.bias"), eps)
                 : x;
  if (cfg.proj_dim > 0) {
    const auto& pj = w(pre + "proj");  // [D, P]
    r.cls.assign(size_t(cfg.proj_dim), 0.0);
    for (int64_t j = 0; j < cfg.proj_dim; ++j)
      for (int64_t k = 0; k < d; ++k)
        r.cls[size_t(j)] += r.tokens[size_t(k)] * double(pj[size_t(k * cfg.proj_dim + j)]);
  } else {
    r.cls.assign(r.tokens.begin(), r.tokens.begin() + d);
  }
  return r;
}

}  // namespace macro::test
