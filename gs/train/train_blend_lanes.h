// The float kernels of the trainer (train_kernels.h) written once over 16-lane GCC vectors and
// compiled per ISA: included only by train_blend_avx2.cpp (two 8-lane halves) and
// train_blend_avx512.cpp (one 16-lane vector). Everything is in an unnamed namespace, so each
// ISA file holds its own copy.
//
// Legend: L = 16 lanes = the 16 pixels of a tile row; vf / vi a vector of L floats / int32s
// (comparisons give -1 / 0 per lane); H x W pixels, planes row-major [H,W].
#pragma once

#include <cmath>
#include <cstring>

#if defined(__AVX512F__) || defined(__AVX2__)
#include <immintrin.h>
#endif

#include "gs/train/loss.h"
#include "gs/train/train_kernels.h"

// 16-lane vectors passed between these internal functions on the AVX2 path (no ABI crosses).
#pragma GCC diagnostic ignored "-Wpsabi"

namespace macro::gs::train {
namespace {

constexpr int L = raster::kTile;
typedef float vf __attribute__((vector_size(64)));
typedef int32_t vi __attribute__((vector_size(64)));
typedef float vf8 __attribute__((vector_size(32)));
typedef float vf4 __attribute__((vector_size(16)));
static_assert(L == 16, "one vector per tile row");

inline vf splat(float v) {
  return vf{} + v;
}
inline vi splat_i(int32_t v) {
  return vi{} + v;
}
inline vf load(const float* p) {
  vf v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline void store(float* p, vf v) {
  std::memcpy(p, &v, sizeof v);
}
inline vi load_i(const uint32_t* p) {
  vi v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline void store_i(uint32_t* p, vi v) {
  std::memcpy(p, &v, sizeof v);
}
inline const vf& iota() {
  static const vf v = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
  return v;
}
inline vi lanes_of(uint32_t bits) {
  const vi bit = {1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384, 32768};
  return (splat_i(int32_t(bits)) & bit) != 0;
}
inline uint32_t bits_of(vi m) {
#if defined(__AVX512F__)
  __m512i v;
  std::memcpy(&v, &m, sizeof v);
  return uint32_t(_mm512_movepi32_mask(v));
#elif defined(__AVX2__)
  __m256 lo, hi;
  std::memcpy(&lo, &m, 32);
  std::memcpy(&hi, reinterpret_cast<const char*>(&m) + 32, 32);
  return uint32_t(_mm256_movemask_ps(lo)) | uint32_t(_mm256_movemask_ps(hi)) << 8;
#else
  uint32_t b = 0;
  for (int l = 0; l < L; ++l) b |= uint32_t(m[l] != 0) << l;
  return b;
#endif
}
inline bool any(vi m) {
  return bits_of(m) != 0;
}
inline vf vmin(vf a, vf b) {
  return a < b ? a : b;
}
inline vf vmax(vf a, vf b) {
  return a > b ? a : b;
}
inline vf pick(vi m, vf a) {  // a where m, else 0
  return m ? a : vf{};
}
// The sum of the lanes, always in the same order (halves, then quarters, ...).
inline float hsum(vf v) {
  const vf8 a = __builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7) +
                __builtin_shufflevector(v, v, 8, 9, 10, 11, 12, 13, 14, 15);
  const vf4 b =
      __builtin_shufflevector(a, a, 0, 1, 2, 3) + __builtin_shufflevector(a, a, 4, 5, 6, 7);
  return (b[0] + b[2]) + (b[1] + b[3]);
}

// exp(-s) for s >= 0 (clamped at 87): 2^-n p(r), n = round(s log2 e), r = n ln 2 - s in
// [-ln2/2, ln2/2], p the degree-6 Taylor polynomial (relative error ~2e-7).
inline vf exp_neg(vf s) {
  s = vmin(s, splat(87.f));
  const vi n = __builtin_convertvector(s * 1.44269504f + 0.5f, vi);
  const vf nf = __builtin_convertvector(n, vf);
  const vf r = (nf * 0.693145752f - s) + nf * 1.42860677e-6f;
  vf p = splat(1.f / 720);
  p = p * r + 1.f / 120;
  p = p * r + 1.f / 24;
  p = p * r + 1.f / 6;
  p = p * r + 0.5f;
  p = p * r + 1.f;
  p = p * r + 1.f;
  const vi e = (127 - n) << 23;
  vf scale;
  std::memcpy(&scale, &e, sizeof scale);
  return p * scale;
}

// One Gaussian over the 16 lanes of a row (the forward and the backward call exactly this, so
// both see the same alpha bits). ok: lanes where it is blended (sigma >= 0, alpha >= 1/255).
struct LaneHit {
  vf dx, vis, alpha;
  vi ok, unclamped;
};
inline LaneHit evaluate(const raster::TileSplat& s, vf px, float py) {
  LaneHit h;
  h.dx = s.x - px;
  const float dy = s.y - py;
  const vf sigma = 0.5f * (s.a * h.dx * h.dx + s.c * (dy * dy)) + (s.b * dy) * h.dx;
  h.vis = exp_neg(vmax(sigma, vf{}));
  const vf raw = s.opacity * h.vis;
  h.unclamped = raw <= raster::kMaxAlpha;
  h.alpha = vmin(raw, splat(raster::kMaxAlpha));
  h.ok = (sigma >= 0.f) & (h.alpha >= raster::kMinAlpha);
  return h;
}

void blend_forward_row_lanes(const raster::TileSplat* splats, const uint32_t* idx, int n,
                             uint32_t base, float px0, float py, TrainRowForward* row) {
  if (!row->active) return;
  vi act = lanes_of(row->active);
  vf T = load(row->T), cr = load(row->r), cg = load(row->g), cb = load(row->b);
  vi last = load_i(row->last);
  const vf px = px0 + iota();
  for (int i = 0; i < n; ++i) {
    const raster::TileSplat& s = splats[idx[i]];
    const LaneHit h = evaluate(s, px, py);
    vi ok = h.ok & act;
    if (!any(ok)) continue;
    const vf next = T * (1.f - h.alpha);
    const vi stop = ok & (next <= raster::kTransmittanceStop);
    act &= ~stop;
    ok &= ~stop;
    const vf w = h.alpha * T;
    cr += pick(ok, s.r * w);
    cg += pick(ok, s.g * w);
    cb += pick(ok, s.bl * w);
    T = ok ? next : T;
    last = ok ? splat_i(int32_t(base + idx[i] + 1)) : last;
    if (!any(act)) break;
  }
  store(row->T, T);
  store(row->r, cr);
  store(row->g, cg);
  store(row->b, cb);
  store_i(row->last, last);
  row->active = bits_of(act);
}

void blend_backward_row_lanes(const raster::TileSplat* splats, const uint32_t* idx, int n,
                              uint32_t base, float px0, float py, TrainRowBackward* row,
                              TrainEntryGrad* acc, uint8_t* touched, int width) {
  vf T = load(row->T);
  vf br = load(row->behind_r), bg = load(row->behind_g), bb = load(row->behind_b);
  const vf vr = load(row->v_r), vg = load(row->v_g), vb = load(row->v_b), vaT = load(row->va_T);
  const vi last = load_i(row->last);
  const vf px = px0 + iota();
  for (int i = n; i-- > 0;) {
    const int32_t pos = int32_t(base + idx[i]);
    const vi walked = splat_i(pos) < last;  // the lane walked this entry in the forward
    if (!any(walked)) continue;
    const raster::TileSplat& s = splats[idx[i]];
    const LaneHit h = evaluate(s, px, py);
    const vi ok = h.ok & walked;
    if (!any(ok)) continue;
    const vf ra = 1.f / (1.f - h.alpha);
    const vf Tb = T * ra;  // transmittance before this Gaussian
    const vf w = h.alpha * Tb;
    const vf v_alpha = vaT * ra + vr * (s.r * Tb - br * ra) + vg * (s.g * Tb - bg * ra) +
                       vb * (s.bl * Tb - bb * ra);
    br += pick(ok, s.r * w);
    bg += pick(ok, s.g * w);
    bb += pick(ok, s.bl * w);
    T = ok ? Tb : T;
    const vi live = ok & h.unclamped;
    const vf v_sigma = pick(live, -h.alpha * v_alpha);
    const float dy = s.y - py;
    const vf dxs = h.dx * v_sigma;
    vf g[kPairGradAbs] = {pick(ok, w * vr),
                          pick(ok, w * vg),
                          pick(ok, w * vb),
                          0.5f * h.dx * dxs,
                          dy * dxs,
                          (0.5f * dy * dy) * v_sigma,
                          s.a * dxs + (s.b * dy) * v_sigma,
                          s.b * dxs + (s.c * dy) * v_sigma,
                          pick(live, h.vis * v_alpha)};
    if (width > kPairGrad) {  // absgrad: |per-pixel mean gradient| (sign bit cleared)
      vi bx, by;
      std::memcpy(&bx, &g[6], sizeof bx);
      std::memcpy(&by, &g[7], sizeof by);
      bx &= 0x7fffffff;
      by &= 0x7fffffff;
      std::memcpy(&g[9], &bx, sizeof bx);
      std::memcpy(&g[10], &by, sizeof by);
    }
    float(*a)[L] = acc[idx[i]].v;
    if (!touched[idx[i]]) {
      touched[idx[i]] = 1;
      for (int c = 0; c < width; ++c) store(a[c], g[c]);
    } else {
      for (int c = 0; c < width; ++c) store(a[c], load(a[c]) + g[c]);
    }
  }
  store(row->T, T);
  store(row->behind_r, br);
  store(row->behind_g, bg);
  store(row->behind_b, bb);
}

void flush_batch_lanes(const TrainEntryGrad* acc, const uint8_t* touched, int n, float* pair_grad,
                       int width) {
  for (int k = 0; k < n; ++k) {
    if (!touched[k]) continue;
    float* pg = pair_grad + size_t(k) * size_t(width);
    for (int c = 0; c < width; ++c) pg[c] += hsum(load(acc[k].v[c]));
  }
}

// ---- Loss (loss.h's maths in float; sums of the loss value in double, per row, fixed order) ----

constexpr int kHalf = kSsimWindow / 2;

struct Window {
  float g[kSsimWindow];
  Window() {
    double w[kSsimWindow], sum = 0;
    for (int i = 0; i < kSsimWindow; ++i) {
      const double d = i - kHalf;
      w[i] = std::exp(-d * d / (2 * kSsimSigma * kSsimSigma));
      sum += w[i];
    }
    for (int i = 0; i < kSsimWindow; ++i) g[i] = float(w[i] / sum);
  }
};
inline const Window& window() {
  static const Window w;
  return w;
}

// row[start .. start + 16) with zeros outside [0, W).
inline vf load_range(const float* row, long start, int W) {
  if (start >= 0 && start + L <= W) return load(row + start);
  vf v{};
  for (int l = 0; l < L; ++l) {
    const long j = start + l;
    if (j >= 0 && j < W) v[l] = row[j];
  }
  return v;
}
inline void store_range(float* row, long start, int W, vf v) {
  if (start + L <= W) {
    store(row + start, v);
    return;
  }
  for (int l = 0; l < L && start + l < W; ++l) row[start + l] = v[l];
}

// Horizontal pass of `planes` planes at once: out[p][i][j] = sum_k g[k] in[p][i][j + k - 5].
template <int P>
void blur_rows(const float* const (&in)[P], float* const (&out)[P], int W, size_t i0, size_t i1) {
  const Window& win = window();
  for (size_t i = i0; i < i1; ++i)
    for (long j = 0; j < W; j += L) {
      vf acc[P] = {};
      for (int k = 0; k < kSsimWindow; ++k)
        for (int p = 0; p < P; ++p)
          acc[p] += win.g[k] * load_range(in[p] + i * size_t(W), j + k - kHalf, W);
      for (int p = 0; p < P; ++p) store_range(out[p] + i * size_t(W), j, W, acc[p]);
    }
}
// Vertical pass at row i, columns [j, j + 16): sum_k g[k] in[i + k - 5][j..] (rows outside zero).
inline vf blur_col(const float* in, int W, int H, long i, long j) {
  const Window& win = window();
  vf acc{};
  for (int k = 0; k < kSsimWindow; ++k) {
    const long ii = i + k - kHalf;
    if (ii >= 0 && ii < H) acc += win.g[k] * load_range(in + size_t(ii) * size_t(W), j, W);
  }
  return acc;
}

Result<LossValue> loss_lanes(const float* x, const float* y, int W, int H, float* grad,
                             float* scratch, ThreadPool& pool) {
  if (W < kSsimWindow || H < kSsimWindow)
    return Status::error("loss: image " + std::to_string(W) + "x" + std::to_string(H) +
                         " is smaller than the " + std::to_string(kSsimWindow) + "x" +
                         std::to_string(kSsimWindow) + " SSIM window (the valid crop is empty)");
  const size_t n = size_t(W) * size_t(H);
  const int Wc = W - 2 * kHalf, Hc = H - 2 * kHalf;
  const float l1_grad = float((1 - kSsimLambda) / double(3 * n));
  const float ssim_weight = float(-kSsimLambda / (3.0 * double(Wc) * double(Hc)));
  float* X = scratch;
  float* Y = X + n;
  float* hx[5] = {Y + n, Y + 2 * n, Y + 3 * n, Y + 4 * n, Y + 5 * n};  // mx my exx eyy exy (h)
  float* gp[3] = {Y + 6 * n, Y + 7 * n, Y + 8 * n};                    // w dS/d(mx, exx, exy)
  float* hg[3] = {Y + 9 * n, Y + 10 * n, Y + 11 * n};
  double* row_sum = reinterpret_cast<double*>((reinterpret_cast<uintptr_t>(Y + 12 * n) + 63) &
                                              ~uintptr_t(63));  // [H]

  // L1 and its gradient, per-row partial sums.
  pool.parallel_for(
      size_t(H),
      [&](size_t b, size_t e, int) {
        for (size_t i = b; i < e; ++i) {
          double s = 0;
          for (size_t k = i * size_t(W) * 3; k < (i + 1) * size_t(W) * 3; ++k) {
            const float d = x[k] - y[k];
            s += std::abs(double(d));
            if (grad) grad[k] = l1_grad * float((d > 0) - (d < 0));
          }
          row_sum[i] = s;
        }
      },
      8);
  double l1 = 0;
  for (int i = 0; i < H; ++i) l1 += row_sum[i];
  l1 /= double(3 * n);

  double ssim_sum = 0;
  for (int c = 0; c < 3; ++c) {
    pool.parallel_for(
        size_t(H),
        [&](size_t b, size_t e, int) {
          for (size_t p = b * size_t(W); p < e * size_t(W); ++p) {
            X[p] = x[3 * p + size_t(c)];
            Y[p] = y[3 * p + size_t(c)];
          }
          // The product planes are formed on the fly inside the horizontal pass.
          const Window& win = window();
          for (size_t i = b; i < e; ++i) {
            const float* xr = X + i * size_t(W);
            const float* yr = Y + i * size_t(W);
            for (long j = 0; j < W; j += L) {
              vf a[5] = {};
              for (int k = 0; k < kSsimWindow; ++k) {
                const vf xv = load_range(xr, j + k - kHalf, W),
                         yv = load_range(yr, j + k - kHalf, W);
                const float g = win.g[k];
                a[0] += g * xv;
                a[1] += g * yv;
                a[2] += g * (xv * xv);
                a[3] += g * (yv * yv);
                a[4] += g * (xv * yv);
              }
              for (int q = 0; q < 5; ++q) store_range(hx[q] + i * size_t(W), j, W, a[q]);
            }
          }
        },
        8);
    pool.parallel_for(
        size_t(H),
        [&](size_t b, size_t e, int) {
          for (size_t i = b; i < e; ++i) {
            const bool in_rows = long(i) >= kHalf && long(i) < H - kHalf;
            double s = 0;
            for (long j = 0; j < W; j += L) {
              const vf ux = blur_col(hx[0], W, H, long(i), j),
                       uy = blur_col(hx[1], W, H, long(i), j);
              const vf exx = blur_col(hx[2], W, H, long(i), j),
                       eyy = blur_col(hx[3], W, H, long(i), j),
                       exy = blur_col(hx[4], W, H, long(i), j);
              const vf col = float(j) + iota();
              const vi crop =
                  (col >= float(kHalf)) & (col < float(W - kHalf)) & splat_i(in_rows ? -1 : 0);
              const vf sxx = exx - ux * ux, syy = eyy - uy * uy, sxy = exy - ux * uy;
              const vf A1 = 2.f * ux * uy + float(kSsimC1), A2 = 2.f * sxy + float(kSsimC2);
              const vf B1 = ux * ux + uy * uy + float(kSsimC1), B2 = sxx + syy + float(kSsimC2);
              const vf inv = 1.f / (B1 * B2);
              const vf S = A1 * A2 * inv;
              s += double(hsum(pick(crop, S)));
              if (grad) {
                const vf gm = 2.f * uy * A2 * inv - 2.f * uy * A1 * inv - 2.f * ux * S / B1 +
                              2.f * ux * S / B2;
                store_range(gp[0] + i * size_t(W), j, W, pick(crop, ssim_weight * gm));
                store_range(gp[1] + i * size_t(W), j, W, pick(crop, ssim_weight * (-S / B2)));
                store_range(gp[2] + i * size_t(W), j, W,
                            pick(crop, ssim_weight * (2.f * A1 * inv)));
              }
            }
            row_sum[i] = s;
          }
        },
        8);
    for (int i = 0; i < H; ++i) ssim_sum += row_sum[i];
    if (!grad) continue;
    pool.parallel_for(
        size_t(H),
        [&](size_t b, size_t e, int) {
          blur_rows<3>({gp[0], gp[1], gp[2]}, {hg[0], hg[1], hg[2]}, W, b, e);
        },
        8);
    pool.parallel_for(
        size_t(H),
        [&](size_t b, size_t e, int) {
          for (size_t i = b; i < e; ++i)
            for (long j = 0; j < W; j += L) {
              const vf vm = blur_col(hg[0], W, H, long(i), j),
                       vxx = blur_col(hg[1], W, H, long(i), j),
                       vxy = blur_col(hg[2], W, H, long(i), j);
              const vf xv = load_range(X + i * size_t(W), j, W),
                       yv = load_range(Y + i * size_t(W), j, W);
              const vf d = vm + 2.f * xv * vxx + yv * vxy;
              for (int l = 0; l < L && j + l < W; ++l)
                grad[3 * (i * size_t(W) + size_t(j + l)) + size_t(c)] += d[l];
            }
        },
        8);
  }
  LossValue v;
  v.l1 = l1;
  v.ssim = ssim_sum / (3.0 * double(Wc) * double(Hc));
  v.loss = (1 - kSsimLambda) * l1 + kSsimLambda * (1 - v.ssim);
  return v;
}

}  // namespace
}  // namespace macro::gs::train
