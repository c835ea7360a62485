// Op drivers (splitting work over the pool) and the scalar reference primitives. See ops.h.
#include "attention/runtime/ops.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "attention/runtime/half.h"
#include "attention/runtime/status.h"

namespace macro {

// ---- scalar reference primitives
// -----------------------------------------------------------------
namespace {

inline float act_scalar(float x, Act act) {
  switch (act) {
    case Act::kNone:
      return x;
    case Act::kSilu:
      return x / (1.0f + std::exp(-x));
    case Act::kRelu:
      return x > 0.0f ? x : 0.0f;
    case Act::kGelu:
      return 0.5f * x * (1.0f + std::erf(x * 0.70710678118654752f));
    case Act::kTanh:
      return std::tanh(x);
  }
  return x;
}

void act_ref(float* dst, const float* src, int64_t n, Act act) {
  for (int64_t i = 0; i < n; ++i) dst[i] = act_scalar(src[i], act);
}

void affine_act_ref(float* dst, const float* src, int64_t n, double mean, float a, float b,
                    Act act) {
  for (int64_t i = 0; i < n; ++i) dst[i] = act_scalar(float(double(src[i]) - mean) * a + b, act);
}

void norm_row_ref(float* dst, const float* src, int64_t n, double mean, float rstd,
                  const float* gamma, const float* beta) {
  for (int64_t i = 0; i < n; ++i) {
    float y = float(double(src[i]) - mean) * rstd;
    if (gamma) y *= gamma[i];
    if (beta) y += beta[i];
    dst[i] = y;
  }
}

double sum_ref(const float* x, int64_t n) {
  double s = 0;
  for (int64_t i = 0; i < n; ++i) s += x[i];
  return s;
}

double sum_sq_dev_ref(const float* x, int64_t n, double mean) {
  double s = 0;
  for (int64_t i = 0; i < n; ++i) {
    double d = double(x[i]) - mean;
    s += d * d;
  }
  return s;
}

void softmax_ref(float* dst, const float* src, int64_t n, float scale) {
  if (n == 0) return;
  float m = -INFINITY;
  for (int64_t i = 0; i < n; ++i) m = std::max(m, src[i] * scale);
  double s = 0;
  for (int64_t i = 0; i < n; ++i) {
    float e = std::exp(src[i] * scale - m);
    dst[i] = e;
    s += e;
  }
  const float inv = float(1.0 / s);
  for (int64_t i = 0; i < n; ++i) dst[i] *= inv;
}

void geglu_ref(float* dst, const float* v, const float* g, int64_t n) {
  for (int64_t i = 0; i < n; ++i) dst[i] = v[i] * act_scalar(g[i], Act::kGelu);
}

void axpby_ref(float* dst, float a, const float* x, float b, const float* y, int64_t n) {
  for (int64_t i = 0; i < n; ++i) dst[i] = a * x[i] + b * y[i];
}

void pair_words_ref(uint32_t* dst, const float* lo, const float* hi, int64_t n) {
  for (int64_t i = 0; i < n; ++i)
    dst[i] = uint32_t(f32_to_bf16(lo[i])) | (hi ? uint32_t(f32_to_bf16(hi[i])) << 16 : 0u);
}

void round_bf16_ref(float* x, int64_t n) {
  for (int64_t i = 0; i < n; ++i) x[i] = bf16_to_f32(f32_to_bf16(x[i]));
}

OpsKernels make_table(Isa isa) {
  OpsKernels t;
  t.name = "scalar";
  t.act = act_ref;
  t.affine_act = affine_act_ref;
  t.norm_row = norm_row_ref;
  t.sum = sum_ref;
  t.sum_sq_dev = sum_sq_dev_ref;
  t.softmax = softmax_ref;
  t.geglu = geglu_ref;
  t.axpby = axpby_ref;
  t.pair_words = pair_words_ref;
  t.round_bf16 = round_bf16_ref;
  // Each path overrides what it vectorises; AMX adds nothing for these ops.
  if (isa >= Isa::kAvx2) detail::fill_ops_avx2(t);
  if (isa >= Isa::kAvx512) detail::fill_ops_avx512(t);
  return t;
}

// Run fn(begin, end) over [0, n) in chunks of at least `grain`, on the pool or inline.
template <typename Fn>
void run_range(ThreadPool* pool, int64_t n, int64_t grain, Fn&& fn) {
  if (n <= 0) return;
  if (!pool || pool->size() == 1 || n <= grain) {
    fn(int64_t(0), n);
    return;
  }
  pool->parallel_for(
      size_t(n), [&](size_t b, size_t e, int) { fn(int64_t(b), int64_t(e)); },
      size_t(std::max<int64_t>(1, grain)));
}

constexpr int64_t kElemGrain = 16384;  // elementwise work per task (64 KB of fp32)

}  // namespace

const OpsKernels& ops_kernels_for(Isa isa) {
  static const OpsKernels tables[] = {make_table(Isa::kScalar), make_table(Isa::kAvx2),
                                      make_table(Isa::kAvx512), make_table(Isa::kAvx512Bf16),
                                      make_table(Isa::kAmx)};
  return tables[static_cast<int>(isa)];
}

const OpsKernels& ops_kernels() {
  return ops_kernels_for(active_isa());
}

// ---- normalisation -----------------------------------------------------------------------------

void group_norm(float* dst, const float* src, const float* gamma, const float* beta, int64_t n,
                int64_t c, int64_t hw, const GroupNormParams& p, ThreadPool* pool) {
  MACRO_CHECK(p.groups > 0 && c % p.groups == 0);
  const OpsKernels& k = ops_kernels();
  const int64_t cpg = c / p.groups;
  const int64_t group_len = cpg * hw;
  run_range(pool, n * p.groups, 1, [&](int64_t b, int64_t e) {
    for (int64_t ng = b; ng < e; ++ng) {
      const float* x = src + ng * group_len;
      float* y = dst + ng * group_len;
      const int64_t g = ng % p.groups;
      const double mean = group_len ? k.sum(x, group_len) / double(group_len) : 0.0;
      const double var = group_len ? k.sum_sq_dev(x, group_len, mean) / double(group_len) : 0.0;
      const double rstd = 1.0 / std::sqrt(var + double(p.eps));
      for (int64_t ci = 0; ci < cpg; ++ci) {
        const int64_t ch = g * cpg + ci;
        const float a = float(rstd * (gamma ? gamma[ch] : 1.0f));
        const float bb = beta ? beta[ch] : 0.0f;
        k.affine_act(y + ci * hw, x + ci * hw, hw, mean, a, bb, p.act);
      }
    }
  });
}

void layer_norm(float* dst, const float* src, const float* gamma, const float* beta, int64_t m,
                int64_t d, float eps, ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, m, std::max<int64_t>(1, kElemGrain / std::max<int64_t>(d, 1)),
            [&](int64_t b, int64_t e) {
              for (int64_t r = b; r < e; ++r) {
                const float* x = src + r * d;
                const double mean = d ? k.sum(x, d) / double(d) : 0.0;
                const double var = d ? k.sum_sq_dev(x, d, mean) / double(d) : 0.0;
                const double rstd = 1.0 / std::sqrt(var + double(eps));
                k.norm_row(dst + r * d, x, d, mean, float(rstd), gamma, beta);
              }
            });
}

// ---- activations -------------------------------------------------------------------------------

void activation(float* dst, const float* src, int64_t n, Act act, ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, n, kElemGrain,
            [&](int64_t b, int64_t e) { k.act(dst + b, src + b, e - b, act); });
}

void geglu(float* dst, const float* src, int64_t m, int64_t d, ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, m, std::max<int64_t>(1, kElemGrain / std::max<int64_t>(d, 1)),
            [&](int64_t b, int64_t e) {
              for (int64_t r = b; r < e; ++r)
                k.geglu(dst + r * d, src + r * 2 * d, src + r * 2 * d + d, d);
            });
}

void softmax_rows(float* dst, const float* src, int64_t m, int64_t d, float scale,
                  ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, m, std::max<int64_t>(1, kElemGrain / std::max<int64_t>(d, 1)),
            [&](int64_t b, int64_t e) {
              for (int64_t r = b; r < e; ++r) k.softmax(dst + r * d, src + r * d, d, scale);
            });
}

// ---- resampling --------------------------------------------------------------------------------

void upsample_nearest(float* dst, const float* src, int64_t nc, int64_t h, int64_t w, int64_t oh,
                      int64_t ow, ThreadPool* pool) {
  MACRO_CHECK(h > 0 && w > 0 && oh >= 0 && ow >= 0);
  // Source index floor(x * w / ow) in exact integer arithmetic (no allocation in the op).
  const bool twice = ow == 2 * w;
  run_range(pool, nc * oh, std::max<int64_t>(1, kElemGrain / std::max<int64_t>(ow, 1)),
            [&](int64_t b, int64_t e) {
              for (int64_t r = b; r < e; ++r) {
                const int64_t plane = r / oh, y = r % oh;
                const int64_t syy = std::min(h - 1, y * h / oh);
                const float* s = src + (plane * h + syy) * w;
                float* d = dst + r * ow;
                if (twice) {
                  for (int64_t x = 0; x < w; ++x) d[2 * x] = d[2 * x + 1] = s[x];
                } else {
                  for (int64_t x = 0; x < ow; ++x) d[x] = s[std::min(w - 1, x * w / ow)];
                }
              }
            });
}

// ---- timestep embedding ------------------------------------------------------------------------

void timestep_embedding(float* dst, const float* t, int64_t count,
                        const TimestepEmbeddingParams& p) {
  const int half = p.dim / 2;
  MACRO_CHECK(half > 0 && double(half) - p.freq_shift != 0.0);
  // diffusers: exponent = -log(max_period) * arange(half) / (half - shift), computed in fp32,
  // emb = exp(exponent); a = t[:, None] * emb; the products and sin/cos are fp32 too.
  for (int64_t r = 0; r < count; ++r) {
    float* row = dst + r * p.dim;
    for (int i = 0; i < half; ++i) {
      const float exponent = -std::log(p.max_period) * float(i) / (float(half) - p.freq_shift);
      const float a = p.scale * (t[r] * std::exp(exponent));
      const float s = std::sin(a), c = std::cos(a);
      row[i] = p.flip_sin_to_cos ? c : s;
      row[half + i] = p.flip_sin_to_cos ? s : c;
    }
    if (p.dim % 2) row[p.dim - 1] = 0.0f;
  }
}

// ---- elementwise -------------------------------------------------------------------------------

void add(float* dst, const float* a, const float* b, int64_t n, ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, n, kElemGrain,
            [&](int64_t s, int64_t e) { k.axpby(dst + s, 1.0f, a + s, 1.0f, b + s, e - s); });
}

void scale(float* dst, const float* src, float s, int64_t n, ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, n, kElemGrain, [&](int64_t b, int64_t e) {
    k.affine_act(dst + b, src + b, e - b, 0.0, s, 0.0f, Act::kNone);
  });
}

void axpby(float* dst, float alpha, const float* x, float beta, const float* y, int64_t n,
           ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, n, kElemGrain,
            [&](int64_t b, int64_t e) { k.axpby(dst + b, alpha, x + b, beta, y + b, e - b); });
}

void add_row_broadcast(float* dst, const float* src, const float* row, int64_t m, int64_t d,
                       ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, m, std::max<int64_t>(1, kElemGrain / std::max<int64_t>(d, 1)),
            [&](int64_t b, int64_t e) {
              for (int64_t r = b; r < e; ++r) k.axpby(dst + r * d, 1.0f, src + r * d, 1.0f, row, d);
            });
}

void add_channel_broadcast(float* dst, const float* src, const float* v, int64_t nc, int64_t hw,
                           ThreadPool* pool) {
  const OpsKernels& k = ops_kernels();
  run_range(pool, nc, std::max<int64_t>(1, kElemGrain / std::max<int64_t>(hw, 1)),
            [&](int64_t b, int64_t e) {
              for (int64_t r = b; r < e; ++r)
                k.affine_act(dst + r * hw, src + r * hw, hw, 0.0, 1.0f, v[r], Act::kNone);
            });
}

}  // namespace macro
