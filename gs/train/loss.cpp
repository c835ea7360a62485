// L1 + valid SSIM and its gradient (loss.h).
//
// Legend: H x W pixels, one channel plane at a time [H,W]; G the separable 11x11 window.
// Forward per channel: the five blurred planes mx, my, exx, eyy, exy (G * x, G * y, G * x^2,
// G * y^2, G * xy) and the map S. Backward: with w = dloss/dS (-lambda / (3 Hc Wc) inside the
// crop, 0 outside), the three planes w dS/dmx, w dS/dexx, w dS/dexy are blurred again (the adjoint
// of a zero-padded convolution with a symmetric kernel is the same convolution) and
//   dloss/dx = G*(w dS/dmx) + 2 x G*(w dS/dexx) + y G*(w dS/dexy).
#include "gs/train/loss.h"

#include <array>
#include <cmath>
#include <string>

namespace macro::gs::train {
namespace {

constexpr int kHalf = kSsimWindow / 2;

std::array<double, kSsimWindow> window() {
  std::array<double, kSsimWindow> g{};
  double sum = 0;
  for (int i = 0; i < kSsimWindow; ++i) {
    const double d = i - kHalf;
    g[size_t(i)] = std::exp(-d * d / (2 * kSsimSigma * kSsimSigma));
    sum += g[size_t(i)];
  }
  for (double& v : g) v /= sum;
  return g;
}

// out = G * in, zero padding, same size. tmp holds W*H doubles.
void blur(const double* in, double* out, double* tmp, int W, int H, ThreadPool& pool) {
  static const std::array<double, kSsimWindow> g = window();
  pool.parallel_for(
      size_t(H),
      [&](size_t b, size_t e, int) {
        for (size_t i = b; i < e; ++i)
          for (int j = 0; j < W; ++j) {
            double s = 0;
            for (int k = -kHalf; k <= kHalf; ++k) {
              const int jj = j + k;
              if (jj >= 0 && jj < W) s += g[size_t(k + kHalf)] * in[i * size_t(W) + size_t(jj)];
            }
            tmp[i * size_t(W) + size_t(j)] = s;
          }
      },
      4);
  pool.parallel_for(
      size_t(H),
      [&](size_t b, size_t e, int) {
        for (size_t i = b; i < e; ++i)
          for (int j = 0; j < W; ++j) {
            double s = 0;
            for (int k = -kHalf; k <= kHalf; ++k) {
              const long ii = long(i) + k;
              if (ii >= 0 && ii < H)
                s += g[size_t(k + kHalf)] * tmp[size_t(ii) * size_t(W) + size_t(j)];
            }
            out[i * size_t(W) + size_t(j)] = s;
          }
      },
      4);
}

}  // namespace

Result<LossValue> photometric_loss(const double* x, const float* y, int W, int H,
                                   std::vector<double>* grad, ThreadPool& pool) {
  if (W < kSsimWindow || H < kSsimWindow)
    return Status::error("loss: image " + std::to_string(W) + "x" + std::to_string(H) +
                         " is smaller than the " + std::to_string(kSsimWindow) + "x" +
                         std::to_string(kSsimWindow) + " SSIM window (the valid crop is empty)");
  const size_t n = size_t(W) * size_t(H);
  const int Wc = W - 2 * kHalf, Hc = H - 2 * kHalf;
  const double l1_scale = 1.0 / double(3 * n);
  const double ssim_weight = -kSsimLambda / (3.0 * double(Wc) * double(Hc));
  if (grad) grad->assign(3 * n, 0.0);

  // L1, per-row partial sums.
  std::vector<double> row_sum(size_t(H), 0.0);
  pool.parallel_for(
      size_t(H),
      [&](size_t b, size_t e, int) {
        for (size_t i = b; i < e; ++i) {
          double s = 0;
          for (size_t k = i * size_t(W) * 3; k < (i + 1) * size_t(W) * 3; ++k) {
            const double d = x[k] - double(y[k]);
            s += std::abs(d);
            if (grad) (*grad)[k] = (1 - kSsimLambda) * l1_scale * double((d > 0) - (d < 0));
          }
          row_sum[i] = s;
        }
      },
      4);
  double l1 = 0;
  for (double v : row_sum) l1 += v;
  l1 *= l1_scale;

  // SSIM per channel.
  std::vector<double> X(n), Y(n), XX(n), YY(n), XY(n), mx(n), my(n), exx(n), eyy(n), exy(n), tmp(n),
      gm(n), gxx(n), gxy(n);
  double ssim_sum = 0;
  for (int c = 0; c < 3; ++c) {
    for (size_t p = 0; p < n; ++p) {
      X[p] = x[3 * p + c];
      Y[p] = double(y[3 * p + c]);
      XX[p] = X[p] * X[p];
      YY[p] = Y[p] * Y[p];
      XY[p] = X[p] * Y[p];
    }
    blur(X.data(), mx.data(), tmp.data(), W, H, pool);
    blur(Y.data(), my.data(), tmp.data(), W, H, pool);
    blur(XX.data(), exx.data(), tmp.data(), W, H, pool);
    blur(YY.data(), eyy.data(), tmp.data(), W, H, pool);
    blur(XY.data(), exy.data(), tmp.data(), W, H, pool);
    std::fill(row_sum.begin(), row_sum.end(), 0.0);
    std::fill(gm.begin(), gm.end(), 0.0);
    std::fill(gxx.begin(), gxx.end(), 0.0);
    std::fill(gxy.begin(), gxy.end(), 0.0);
    pool.parallel_for(
        size_t(Hc),
        [&](size_t b, size_t e, int) {
          for (size_t r = b; r < e; ++r) {
            const size_t i = r + kHalf;
            double s = 0;
            for (int j = kHalf; j < W - kHalf; ++j) {
              const size_t p = i * size_t(W) + size_t(j);
              const double ux = mx[p], uy = my[p];
              const double sxx = exx[p] - ux * ux, syy = eyy[p] - uy * uy, sxy = exy[p] - ux * uy;
              const double A1 = 2 * ux * uy + kSsimC1, A2 = 2 * sxy + kSsimC2;
              const double B1 = ux * ux + uy * uy + kSsimC1, B2 = sxx + syy + kSsimC2;
              const double S = A1 * A2 / (B1 * B2);
              s += S;
              if (grad) {
                const double inv = 1 / (B1 * B2);
                gm[p] = ssim_weight *
                        (2 * uy * A2 * inv - 2 * uy * A1 * inv - 2 * ux * S / B1 + 2 * ux * S / B2);
                gxx[p] = ssim_weight * (-S / B2);
                gxy[p] = ssim_weight * (2 * A1 * inv);
              }
            }
            row_sum[r] = s;
          }
        },
        4);
    for (int r = 0; r < Hc; ++r) ssim_sum += row_sum[size_t(r)];
    if (grad) {
      blur(gm.data(), mx.data(), tmp.data(), W, H, pool);
      blur(gxx.data(), exx.data(), tmp.data(), W, H, pool);
      blur(gxy.data(), exy.data(), tmp.data(), W, H, pool);
      for (size_t p = 0; p < n; ++p)
        (*grad)[3 * p + c] += mx[p] + 2 * X[p] * exx[p] + Y[p] * exy[p];
    }
  }
  LossValue v;
  v.l1 = l1;
  v.ssim = ssim_sum / (3.0 * double(Wc) * double(Hc));
  v.loss = (1 - kSsimLambda) * l1 + kSsimLambda * (1 - v.ssim);
  return v;
}

}  // namespace macro::gs::train
