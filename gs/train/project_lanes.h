// The projection kernels of the trainer's float path (train_kernels.h project_forward /
// project_backward), 16 Gaussians per call, one per lane, written once over the 16-lane vectors of
// train_blend_lanes.h and compiled per ISA: included only after it, by train_blend_avx2.cpp and
// train_blend_avx512.cpp. The maths is diff_project.cpp's (its double code is the scalar twin),
// step for step; branches of the twin become per-lane selects. Transcendentals are polynomials:
// exp (relative error ~3e-7) and log (~1e-7); sqrt and division are the hardware's.
//
// Legend (per lane, one Gaussian): p mean, t = W p + t_cam, q raw quaternion, qn = q/|q|, Rq its
// rotation, s = exp(log s) (or s' = sqrt(s^2 + f^2) with the mip 3D filter f), M = Rq diag(s),
// J the clamped Jacobian [2,3] (j00 j02 j11 j12), T = J W, A = T M, Sigma = A A^T,
// Sigma' = Sigma + eps I, conic = Sigma'^-1; m a lane mask (-1 / 0).
#pragma once

// GCC 12's avx512fintrin.h trips -W(maybe-)uninitialized on its own _mm512_undefined_* inside
// _mm512_sqrt_ps (a false positive, as in attention/runtime/conv_avx512.cpp).
#if defined(__AVX512F__)
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

#include <algorithm>
#include <cstring>

#include "gs/train/train_blend_lanes.h"  // the 16-lane vectors and their helpers

namespace macro::gs::train {
namespace {

inline vf vsqrt(vf x) {
#if defined(__AVX512F__)
  __m512 v;
  std::memcpy(&v, &x, sizeof v);
  v = _mm512_sqrt_ps(v);
  std::memcpy(&x, &v, sizeof v);
  return x;
#elif defined(__AVX2__)
  __m256 lo, hi;
  std::memcpy(&lo, &x, 32);
  std::memcpy(&hi, reinterpret_cast<const char*>(&x) + 32, 32);
  lo = _mm256_sqrt_ps(lo);
  hi = _mm256_sqrt_ps(hi);
  std::memcpy(&x, &lo, 32);
  std::memcpy(reinterpret_cast<char*>(&x) + 32, &hi, 32);
  return x;
#else
  for (int l = 0; l < L; ++l) x[l] = std::sqrt(x[l]);
  return x;
#endif
}
inline vi finite(vf x) {  // neither inf nor NaN
  vi b;
  std::memcpy(&b, &x, sizeof b);
  return (b & 0x7f800000) != 0x7f800000;
}
inline vf sel(vi m, vf a, vf b) {
  return m ? a : b;
}
// exp(x), x clamped to [-87, 87]: exp_neg for x <= 0, its reciprocal above.
inline vf exp_any(vf x) {
  const vi neg = x <= 0.f;
  const vf e = exp_neg(sel(neg, -x, x));
  return sel(neg, e, 1.f / e);
}
// log(x) for finite x > 0 (no denormals): x = 2^e m, m in [sqrt(1/2), sqrt(2)), log m = 2 atanh(u),
// u = (m - 1) / (m + 1), |u| <= 0.172, the series to u^9.
inline vf log_pos(vf x) {
  vi b;
  std::memcpy(&b, &x, sizeof b);
  vi e = ((b >> 23) & 0xff) - 127;
  const vi mb = (b & 0x7fffff) | 0x3f800000;
  vf m;
  std::memcpy(&m, &mb, sizeof m);
  const vi big = m > 1.41421356f;
  m = sel(big, m * 0.5f, m);
  e = e - big;  // big is -1 where true
  const vf u = (m - 1.f) / (m + 1.f), u2 = u * u;
  const vf s = 1.f + u2 * (1.f / 3 + u2 * (1.f / 5 + u2 * (1.f / 7 + u2 * (1.f / 9))));
  return __builtin_convertvector(e, vf) * 0.693147181f + 2.f * u * s;
}

constexpr float kLC0 = 0.28209479177387814f;
constexpr float kLC1 = 0.4886025119029199f;
constexpr float kLC2[5] = {1.0925484305920792f, -1.0925484305920792f, 0.31539156525252005f,
                           -1.0925484305920792f, 0.5462742152960396f};
constexpr float kLC3[7] = {-0.5900435899266435f, 2.890611442640554f,   -0.4570457994644658f,
                           0.3731763325901154f,  -0.4570457994644658f, 1.445305721320277f,
                           -0.5900435899266435f};

// SH basis (diff_project.cpp sh_basis) at unit directions; with d, its partials d[k][0..2].
inline int sh_basis_lanes(int degree, vf x, vf y, vf z, vf* b, vf (*d)[3]) {
  const vf zero{};
  b[0] = splat(kLC0);
  if (d) d[0][0] = d[0][1] = d[0][2] = zero;
  if (degree < 1) return 1;
  b[1] = -kLC1 * y;
  b[2] = kLC1 * z;
  b[3] = -kLC1 * x;
  if (d) {
    d[1][0] = zero, d[1][1] = splat(-kLC1), d[1][2] = zero;
    d[2][0] = zero, d[2][1] = zero, d[2][2] = splat(kLC1);
    d[3][0] = splat(-kLC1), d[3][1] = zero, d[3][2] = zero;
  }
  if (degree < 2) return 4;
  const vf xx = x * x, yy = y * y, zz = z * z;
  b[4] = kLC2[0] * x * y;
  b[5] = kLC2[1] * y * z;
  b[6] = kLC2[2] * (2 * zz - xx - yy);
  b[7] = kLC2[3] * x * z;
  b[8] = kLC2[4] * (xx - yy);
  if (d) {
    d[4][0] = kLC2[0] * y, d[4][1] = kLC2[0] * x, d[4][2] = zero;
    d[5][0] = zero, d[5][1] = kLC2[1] * z, d[5][2] = kLC2[1] * y;
    d[6][0] = -2 * kLC2[2] * x, d[6][1] = -2 * kLC2[2] * y, d[6][2] = 4 * kLC2[2] * z;
    d[7][0] = kLC2[3] * z, d[7][1] = zero, d[7][2] = kLC2[3] * x;
    d[8][0] = 2 * kLC2[4] * x, d[8][1] = -2 * kLC2[4] * y, d[8][2] = zero;
  }
  if (degree < 3) return 9;
  b[9] = kLC3[0] * y * (3 * xx - yy);
  b[10] = kLC3[1] * x * y * z;
  b[11] = kLC3[2] * y * (4 * zz - xx - yy);
  b[12] = kLC3[3] * z * (2 * zz - 3 * xx - 3 * yy);
  b[13] = kLC3[4] * x * (4 * zz - xx - yy);
  b[14] = kLC3[5] * z * (xx - yy);
  b[15] = kLC3[6] * x * (xx - 3 * yy);
  if (d) {
    d[9][0] = kLC3[0] * 6 * x * y, d[9][1] = kLC3[0] * (3 * xx - 3 * yy), d[9][2] = zero;
    d[10][0] = kLC3[1] * y * z, d[10][1] = kLC3[1] * x * z, d[10][2] = kLC3[1] * x * y;
    d[11][0] = kLC3[2] * -2 * x * y, d[11][1] = kLC3[2] * (4 * zz - xx - 3 * yy),
    d[11][2] = kLC3[2] * 8 * y * z;
    d[12][0] = kLC3[3] * -6 * x * z, d[12][1] = kLC3[3] * -6 * y * z,
    d[12][2] = kLC3[3] * (6 * zz - 3 * xx - 3 * yy);
    d[13][0] = kLC3[4] * (4 * zz - 3 * xx - yy), d[13][1] = kLC3[4] * -2 * x * y,
    d[13][2] = kLC3[4] * 8 * x * z;
    d[14][0] = kLC3[5] * 2 * x * z, d[14][1] = kLC3[5] * -2 * y * z, d[14][2] = kLC3[5] * (xx - yy);
    d[15][0] = kLC3[6] * (3 * xx - 3 * yy), d[15][1] = kLC3[6] * -6 * x * y, d[15][2] = zero;
  }
  return 16;
}

// The forward intermediates of 16 Gaussians (diff_project.cpp Forward, per lane).
struct ForwardLanes {
  vf p[3], t[3], qn[4], q_norm, Rq[9], s_raw[3], s[3], M[9], f2;
  vi clamp_x, clamp_y;
  vf txc, tyc, J[4], T[6], A[6], sxx, sxy, syy, det0, det, conic[3];
  vf sig, o3, c2;
  vi c2_active;
  vf opacity, dir[3], dir_norm, basis[16];
  int K;
  vf rgb_raw[3];
  vf sh[15][3];  // shN coefficients of the lanes (K - 1 used)
};

// The rows g0 .. g0 + n - 1 of a [N, stride] array, transposed: dst[j][l] = value j of Gaussian
// g0 + l; lanes l >= n repeat Gaussian g0 (their results are dropped). A scalar copy through
// memory: on the CPUs measured it beats hardware gathers, whose 16 loads each stall the pipe.
inline void load_lanes(const float* base, size_t g0, int n, size_t stride, float (*dst)[L]) {
  const float* p = base + g0 * stride;
  for (int l = 0; l < L; ++l) {
    const float* row = p + size_t(l < n ? l : 0) * stride;
    for (size_t j = 0; j < stride; ++j) dst[j][l] = row[j];
  }
}
inline vf row_of(const float (*src)[L], size_t j) {
  return load(src[j]);
}

// Fills f; the mask of lanes not culled for depth nor invalid (non-finite, zero quaternion,
// det <= 0), as forward_one.
inline vi forward_lanes(const ProjectInput& in, size_t g0, int n, bool clip_depth,
                        ForwardLanes* f) {
  const ProjectCameraF& cam = in.cam;
  const float* R = cam.R;
  alignas(64) float buf[48][L];  // the values of one parameter array, transposed
  load_lanes(in.means, g0, n, 3, buf);
  for (int a = 0; a < 3; ++a) f->p[a] = row_of(buf, size_t(a));
  for (int r = 0; r < 3; ++r)
    f->t[r] = R[3 * r] * f->p[0] + R[3 * r + 1] * f->p[1] + R[3 * r + 2] * f->p[2] + cam.t[r];
  const vf tx = f->t[0], ty = f->t[1], tz = f->t[2];
  vi ok = finite(tx) & finite(ty) & finite(tz);
  if (clip_depth) ok &= (tz > in.near_plane) & (tz < in.far_plane);

  vf q[4];
  load_lanes(in.quats, g0, n, 4, buf);
  for (int a = 0; a < 4; ++a) q[a] = row_of(buf, size_t(a));
  f->q_norm = vsqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  ok &= (f->q_norm > 0.f) & finite(f->q_norm);
  const vf qinv = 1.f / sel(f->q_norm > 0.f, f->q_norm, splat(1.f));
  for (int a = 0; a < 4; ++a) f->qn[a] = q[a] * qinv;
  const vf w = f->qn[0], x = f->qn[1], y = f->qn[2], z = f->qn[3];
  const vf Rq[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                    2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                    2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
  const bool mip = in.mode == RasterMode::kMip;
  f->f2 = vf{};
  if (mip && in.filter_3d) {
    load_lanes(in.filter_3d, g0, n, 1, buf);
    const vf fl = row_of(buf, 0);
    f->f2 = fl * fl;
  }
  const vi has_f = f->f2 > 0.f;
  f->o3 = splat(1.f);
  load_lanes(in.scales, g0, n, 3, buf);
  for (int a = 0; a < 3; ++a) {
    f->s_raw[a] = exp_any(row_of(buf, size_t(a)));
    f->s[a] = sel(has_f, vsqrt(f->s_raw[a] * f->s_raw[a] + f->f2), f->s_raw[a]);
    f->o3 = f->o3 * sel(has_f, f->s_raw[a] / f->s[a], splat(1.f));
  }
  for (int i = 0; i < 9; ++i) {
    f->Rq[i] = Rq[i];
    f->M[i] = Rq[i] * f->s[i % 3];
  }

  // Jacobian at the clamped position.
  const vf safe_z = sel(tz != 0.f, tz, splat(1.f));
  const vf rz = 1.f / safe_z, rz2 = rz * rz;
  const vf rx = tx * rz, ry = ty * rz;
  f->clamp_x = (rx < -cam.lim_x_neg) | (rx > cam.lim_x_pos);
  f->clamp_y = (ry < -cam.lim_y_neg) | (ry > cam.lim_y_pos);
  f->txc = tz * vmin(splat(cam.lim_x_pos), vmax(splat(-cam.lim_x_neg), rx));
  f->tyc = tz * vmin(splat(cam.lim_y_pos), vmax(splat(-cam.lim_y_neg), ry));
  f->J[0] = cam.fx * rz;
  f->J[1] = -cam.fx * f->txc * rz2;
  f->J[2] = cam.fy * rz;
  f->J[3] = -cam.fy * f->tyc * rz2;
  for (int k = 0; k < 3; ++k) {
    f->T[k] = f->J[0] * R[k] + f->J[1] * R[6 + k];
    f->T[3 + k] = f->J[2] * R[3 + k] + f->J[3] * R[6 + k];
  }
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 3; ++k)
      f->A[3 * r + k] =
          f->T[3 * r] * f->M[k] + f->T[3 * r + 1] * f->M[3 + k] + f->T[3 * r + 2] * f->M[6 + k];
  const vf* A = f->A;
  const float eps = mip ? raster::kMipKernelSize : raster::kEps2d;
  const vf sxx0 = A[0] * A[0] + A[1] * A[1] + A[2] * A[2];
  f->sxy = A[0] * A[3] + A[1] * A[4] + A[2] * A[5];
  const vf syy0 = A[3] * A[3] + A[4] * A[4] + A[5] * A[5];
  f->det0 = sxx0 * syy0 - f->sxy * f->sxy;
  f->sxx = sxx0 + eps;
  f->syy = syy0 + eps;
  f->det = f->sxx * f->syy - f->sxy * f->sxy;
  ok &= (f->det > 0.f) & finite(f->det);
  const vf rdet = 1.f / sel(f->det > 0.f, f->det, splat(1.f));
  f->conic[0] = f->syy * rdet;
  f->conic[1] = -f->sxy * rdet;
  f->conic[2] = f->sxx * rdet;
  load_lanes(in.opacities, g0, n, 1, buf);
  f->sig = 1.f / (1.f + exp_any(-row_of(buf, 0)));
  f->c2 = splat(1.f);
  f->c2_active = vi{};
  if (in.mode == RasterMode::kAntialiased) {
    const vf r = f->det0 * rdet;
    f->c2_active = r > raster::kAaCompFloor;
    f->c2 = vsqrt(vmax(splat(raster::kAaCompFloor), r));
  } else if (mip) {
    const float e = raster::kMipDetEps;
    const vf d0 = vmax(splat(e), f->det0), d1 = vmax(splat(e), f->det);
    f->c2_active = (d0 > e) & (d1 > e);
    f->c2 = pick(f->c2_active, vsqrt(d0 / (d1 + e) + e));
  }
  f->opacity = f->sig * f->o3 * f->c2;

  // Colour of the direction from the camera centre to the mean.
  vf dir[3];
  for (int a = 0; a < 3; ++a) dir[a] = f->p[a] - cam.center[a];
  f->dir_norm = vsqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  const vf inv = pick(f->dir_norm > 0.f, 1.f / sel(f->dir_norm > 0.f, f->dir_norm, splat(1.f)));
  for (int a = 0; a < 3; ++a) f->dir[a] = dir[a] * inv;
  f->K = sh_basis_lanes(in.sh_degree, f->dir[0], f->dir[1], f->dir[2], f->basis, nullptr);
  const size_t R1 = in.sh_rest;
  if (f->K > 1) {
    load_lanes(in.shN, g0, n, R1 * 3, buf);  // R1 <= 15 (SH degree <= 3)
    for (int k = 1; k < f->K; ++k)
      for (int c = 0; c < 3; ++c) f->sh[k - 1][c] = row_of(buf, size_t(k - 1) * 3 + size_t(c));
  }
  load_lanes(in.sh0, g0, n, 3, buf);
  for (int c = 0; c < 3; ++c) {
    vf v = f->basis[0] * row_of(buf, size_t(c));
    for (int k = 1; k < f->K; ++k) v += f->basis[k] * f->sh[k - 1][c];
    f->rgb_raw[c] = v + raster::kShOffset;
  }
  for (int c = 0; c < 3; ++c) ok &= finite(f->conic[c]) & finite(f->rgb_raw[c]);
  return ok & finite(f->opacity);
}

// train_kernels.h TrainProjectForwardFn (diff_project.cpp project_forward per lane).
void project_forward_lanes(const ProjectInput& in, size_t g0, int n, raster::TileSplat* splats,
                           uint8_t* visible) {
  ForwardLanes f;
  vi ok = forward_lanes(in, g0, n, true, &f);
  ok &= f.opacity >= raster::kMinAlpha;
  const ProjectCameraF& cam = in.cam;
  const vf rz = 1.f / sel(f.t[2] != 0.f, f.t[2], splat(1.f));
  const vf x = cam.fx * f.t[0] * rz + cam.cx;
  const vf y = cam.fy * f.t[1] * rz + cam.cy;
  // Outside d^2 = 2 ln(255 o) alpha < 1/255 (the same margins as gs/raster).
  const vf lg = log_pos(vmax(f.opacity * (1.f / raster::kMinAlpha), splat(1.f)));
  const vf cutoff = 2.f * lg * (1.f + raster::kCutoffRelMargin) + raster::kCutoffAbsMargin;
  const vf ext_x = vsqrt(cutoff * f.sxx), ext_y = vsqrt(cutoff * f.syy);
  ok &= finite(x) & finite(y) & finite(ext_x) & finite(ext_y);
  ok &= ~((x + ext_x < 0.5f) | (x - ext_x > cam.width - 0.5f) | (y + ext_y < 0.5f) |
          (y - ext_y > cam.height - 0.5f));
  const vf rsyy = 1.f / f.syy;  // syy >= eps > 0
  const vf row_k = f.sxy * rsyy, row_a0 = cutoff * f.det * rsyy, row_a1 = f.det * rsyy * rsyy;
  const uint32_t keep = bits_of(ok);
  for (int l = 0; l < n; ++l) {
    visible[l] = uint8_t(keep >> l & 1u);
    if (!visible[l]) continue;
    raster::TileSplat& t = splats[l];
    t.x = x[l];
    t.y = y[l];
    t.a = f.conic[0][l];
    t.b = f.conic[1][l];
    t.c = f.conic[2][l];
    t.opacity = f.opacity[l];
    t.r = std::max(0.f, f.rgb_raw[0][l]);
    t.g = std::max(0.f, f.rgb_raw[1][l]);
    t.bl = std::max(0.f, f.rgb_raw[2][l]);
    t.z = f.t[2][l];
    const uint32_t id = uint32_t(g0 + size_t(l));
    std::memcpy(&t.inv_z, &id, sizeof id);
    t.ext_x = ext_x[l];
    t.ext_y = ext_y[l];
    t.row_k = row_k[l];
    t.row_a0 = row_a0[l];
    t.row_a1 = row_a1[l];
  }
}

// train_kernels.h TrainProjectBackwardFn (diff_project.cpp project_backward per lane).
void project_backward_lanes(const ProjectInput& in, size_t g0, int n, const double* sums,
                            size_t stride, const uint8_t* has_pairs, const ProjectGradOut& out) {
  ForwardLanes f;
  const vi ok = forward_lanes(in, g0, n, false, &f);
  static_assert(sizeof(f.sh) / sizeof(f.sh[0]) == 15, "SH degree <= 3");
  uint32_t live = bits_of(ok);
  vf up[kPairGrad];
  for (int c = 0; c < kPairGrad; ++c)
    for (int l = 0; l < L; ++l)
      up[c][l] = l < n ? float(sums[size_t(l) * stride + size_t(c)]) : 0.f;
  for (int l = 0; l < n; ++l)
    if (!has_pairs[l]) live &= ~(1u << l);
  const vf* up_rgb = up;
  const vf* up_conic = up + 3;
  const vf up_x = up[6], up_y = up[7], up_o = up[8];
  const ProjectCameraF& cam = in.cam;
  const float* R = cam.R;
  const vf tx = f.t[0], ty = f.t[1], tz = f.t[2];
  const vf rz = 1.f / sel(tz != 0.f, tz, splat(1.f)), rz2 = rz * rz;
  vf v_t[3] = {}, v_p[3] = {};

  // Opacity: o = sig o3 c2.
  const vf g_opacity = up_o * f.o3 * f.c2 * f.sig * (1.f - f.sig);
  const vf v_c2 = up_o * f.sig * f.o3, v_o3 = up_o * f.sig * f.c2;

  // Colour: rgb = max(0, SH(dir) + 0.5).
  vf v_raw[3];
  for (int c = 0; c < 3; ++c) v_raw[c] = pick(f.rgb_raw[c] >= 0.f, up_rgb[c]);
  vf g_sh0[3], g_shN[15][3];
  for (int c = 0; c < 3; ++c) g_sh0[c] = f.basis[0] * v_raw[c];
  for (int k = 1; k < f.K; ++k)
    for (int c = 0; c < 3; ++c) g_shN[k - 1][c] = f.basis[k] * v_raw[c];
  if (f.K > 1) {
    vf b[16], db[16][3];
    sh_basis_lanes(in.sh_degree, f.dir[0], f.dir[1], f.dir[2], b, db);
    vf v_d[3] = {};
    for (int k = 1; k < f.K; ++k) {
      const vf vb =
          v_raw[0] * f.sh[k - 1][0] + v_raw[1] * f.sh[k - 1][1] + v_raw[2] * f.sh[k - 1][2];
      for (int a = 0; a < 3; ++a) v_d[a] += vb * db[k][a];
    }
    const vi has_dir = f.dir_norm > 0.f;
    const vf rn = 1.f / sel(has_dir, f.dir_norm, splat(1.f));
    const vf dot = v_d[0] * f.dir[0] + v_d[1] * f.dir[1] + v_d[2] * f.dir[2];
    for (int a = 0; a < 3; ++a) v_p[a] += pick(has_dir, (v_d[a] - dot * f.dir[a]) * rn);
  }

  // Pixel position of the mean (unclamped t).
  v_t[0] += cam.fx * rz * up_x;
  v_t[1] += cam.fy * rz * up_y;
  v_t[2] += -cam.fx * tx * rz2 * up_x - cam.fy * ty * rz2 * up_y;

  // Conic = Sigma'^-1: dL/dSigma' = -C G C.
  const vf ca = f.conic[0], cb = f.conic[1], cc = f.conic[2];
  const vf ga = up_conic[0], gb = 0.5f * up_conic[1], gc = up_conic[2];
  const vf cg00 = ca * ga + cb * gb, cg01 = ca * gb + cb * gc;
  const vf cg10 = cb * ga + cc * gb, cg11 = cb * gb + cc * gc;
  vf V00 = -(cg00 * ca + cg01 * cb);
  vf V01 = -(cg00 * cb + cg01 * cc);
  vf V11 = -(cg10 * cb + cg11 * cc);
  // The compensation c2 = sqrt(r) (antialiased r = det0 / det; mip r = det0 / (det + 1e-6) +
  // 1e-6): the twin's v_det0 d det0 + v_det d det (diff_project.cpp), with D the denominator,
  // e2 = D - det and k = v_r / D^2, rearranged so that no difference of near-equal terms is left
  // (for a Gaussian many pixels wide, det0 / D is 1 - O(eps / size^2) and float would lose it):
  //   V00 += k (eps (syy0^2 + eps syy0 + sxy^2) + e2 syy0)
  //   V11 += k (eps (sxx0^2 + eps sxx0 + sxy^2) + e2 sxx0)
  //   V01 -= k sxy (eps (sxx0 + syy0 + eps) + e2)
  if (in.mode != RasterMode::kClassic) {
    const bool mip = in.mode == RasterMode::kMip;
    const vi act = f.c2_active & (v_c2 != 0.f);
    const float eps = mip ? raster::kMipKernelSize : raster::kEps2d;
    const float e2 = mip ? raster::kMipDetEps : 0.f;
    const vf sxx0 = f.sxx - eps, syy0 = f.syy - eps, sxy2 = f.sxy * f.sxy;
    const vf D = f.det + e2;
    const vf v_r = v_c2 * 0.5f / sel(act, f.c2, splat(1.f));
    const vf k = v_r / (D * D);
    V00 += pick(act, k * (eps * (syy0 * syy0 + eps * syy0 + sxy2) + e2 * syy0));
    V11 += pick(act, k * (eps * (sxx0 * sxx0 + eps * sxx0 + sxy2) + e2 * sxx0));
    V01 -= pick(act, k * f.sxy * (eps * (sxx0 + syy0 + eps) + e2));
  }
  vf vA[6];
  for (int k = 0; k < 3; ++k) {
    vA[k] = 2.f * (V00 * f.A[k] + V01 * f.A[3 + k]);
    vA[3 + k] = 2.f * (V01 * f.A[k] + V11 * f.A[3 + k]);
  }
  vf vT[6], vM[9];
  for (int r = 0; r < 2; ++r)
    for (int j = 0; j < 3; ++j)
      vT[3 * r + j] =
          vA[3 * r] * f.M[3 * j] + vA[3 * r + 1] * f.M[3 * j + 1] + vA[3 * r + 2] * f.M[3 * j + 2];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) vM[3 * i + k] = f.T[i] * vA[k] + f.T[3 + i] * vA[3 + k];
  vf vR[9];
  for (int i = 0; i < 9; ++i) vR[i] = vM[i] * f.s[i % 3];
  const vi has_f = f.f2 > 0.f;
  vf g_scales[3];
  for (int k = 0; k < 3; ++k) {
    const vf vs = f.Rq[k] * vM[k] + f.Rq[3 + k] * vM[3 + k] + f.Rq[6 + k] * vM[6 + k];
    const vf rs = 1.f / f.s[k];
    g_scales[k] =
        sel(has_f, vs * f.s_raw[k] * f.s_raw[k] * rs + v_o3 * f.o3 * f.f2 * rs * rs, vs * f.s[k]);
  }
  vf vJ[6];
  for (int r = 0; r < 2; ++r)
    for (int j = 0; j < 3; ++j)
      vJ[3 * r + j] =
          vT[3 * r] * R[3 * j] + vT[3 * r + 1] * R[3 * j + 1] + vT[3 * r + 2] * R[3 * j + 2];
  const vf vj00 = vJ[0], vj02 = vJ[2], vj11 = vJ[4], vj12 = vJ[5];
  v_t[2] += vj00 * (-cam.fx * rz2) + vj02 * (2.f * cam.fx * f.txc * rz2 * rz) +
            vj11 * (-cam.fy * rz2) + vj12 * (2.f * cam.fy * f.tyc * rz2 * rz);
  const vf v_txc = vj02 * (-cam.fx * rz2), v_tyc = vj12 * (-cam.fy * rz2);
  v_t[2] += pick(f.clamp_x, v_txc * (f.txc * rz)) + pick(f.clamp_y, v_tyc * (f.tyc * rz));
  v_t[0] += pick(~f.clamp_x, v_txc);
  v_t[1] += pick(~f.clamp_y, v_tyc);
  vf g_means[3];
  for (int a = 0; a < 3; ++a)
    g_means[a] = v_p[a] + (R[a] * v_t[0] + R[3 + a] * v_t[1] + R[6 + a] * v_t[2]);

  const vf w = f.qn[0], x = f.qn[1], y = f.qn[2], z = f.qn[3];
  const vf zero{};
  const vf dw[9] = {zero, -2 * z, 2 * y, 2 * z, zero, -2 * x, -2 * y, 2 * x, zero};
  const vf dx[9] = {zero, 2 * y, 2 * z, 2 * y, -4 * x, -2 * w, 2 * z, 2 * w, -4 * x};
  const vf dy[9] = {-4 * y, 2 * x, 2 * w, 2 * x, zero, 2 * z, -2 * w, 2 * z, -4 * y};
  const vf dz[9] = {-4 * z, -2 * w, 2 * x, 2 * w, -4 * z, 2 * y, 2 * x, 2 * y, zero};
  vf vq[4] = {};
  for (int i = 0; i < 9; ++i) {
    vq[0] += vR[i] * dw[i];
    vq[1] += vR[i] * dx[i];
    vq[2] += vR[i] * dy[i];
    vq[3] += vR[i] * dz[i];
  }
  const vf qdot = vq[0] * w + vq[1] * x + vq[2] * y + vq[3] * z;
  const vf rq = 1.f / sel(f.q_norm > 0.f, f.q_norm, splat(1.f));
  vf g_quats[4];
  for (int a = 0; a < 4; ++a) g_quats[a] = (vq[a] - qdot * f.qn[a]) * rq;

  // Every row of the n Gaussians: the lane's values, or zeros (lanes culled or without pairs).
  const vi on = lanes_of(live);
  alignas(64) float buf[48][L];
  auto store_rows = [&](const vf* v, size_t stride, float* base) {
    for (size_t j = 0; j < stride; ++j) store(buf[j], pick(on, v[j]));
    float* p = base + g0 * stride;
    for (int l = 0; l < n; ++l)
      for (size_t j = 0; j < stride; ++j) p[size_t(l) * stride + j] = buf[j][l];
  };
  store_rows(g_means, 3, out.means);
  store_rows(g_scales, 3, out.scales);
  store_rows(g_quats, 4, out.quats);
  store_rows(&g_opacity, 1, out.opacities);
  store_rows(g_sh0, 3, out.sh0);
  const size_t R1 = in.sh_rest;
  if (R1 > 0) {
    vf rows[45];
    for (size_t j = 0; j < R1 * 3; ++j) rows[j] = vf{};
    for (int k = 1; k < f.K; ++k)
      for (int c = 0; c < 3; ++c) rows[size_t(k - 1) * 3 + size_t(c)] = g_shN[k - 1][c];
    store_rows(rows, R1 * 3, out.shN);
  }
}

}  // namespace
}  // namespace macro::gs::train
