// PSNR, SSIM, the size match and the metric suite (contract in metrics.h; the pair checks are
// metric_value.cpp).
//
// SSIM schedule: per channel, the planes are shifted by -R/2 (variances and covariance are
// shift-invariant; the means are shifted back), which keeps E[x^2] - mu^2 small in float. Pass 1
// filters each row horizontally over the valid columns into five float planes (a, b, a^2, b^2, ab)
// [H, W-10]; pass 2 filters those vertically row by row and sums each valid output row's SSIM in
// double into its own slot, so the final sum has a fixed order whatever the thread count.
#include "enhance/metrics/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "enhance/metrics/feature_metrics.h"
#include "enhance/metrics/lpips.h"
#include "enhance/resample.h"

namespace macro::enhance {
namespace {

// Normalised Gaussian taps (torchmetrics _gaussian: exp(-(d / sigma)^2 / 2), d = -(n-1)/2 ...).
std::vector<double> gaussian_taps(int n, double sigma) {
  std::vector<double> g(static_cast<size_t>(n));
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double d = (i - (n - 1) / 2.0) / sigma;
    g[size_t(i)] = std::exp(-0.5 * d * d);
    sum += g[size_t(i)];
  }
  for (double& v : g) v /= sum;
  return g;
}

Status check_ssim_params(const SsimParams& p) {
  if (p.window < 1 || p.window % 2 == 0)
    return Status::error("ssim: window must be odd and >= 1, found " + std::to_string(p.window));
  if (!(p.sigma > 0) || !(p.data_range > 0))
    return Status::error("ssim: sigma and data_range must be > 0");
  return Status::ok();
}

Status check_ssim_size(const gs::Image& im, int window) {
  if (im.width < window || im.height < window)
    return Status::error("ssim: images must be at least " + std::to_string(window) + "x" +
                         std::to_string(window) + " (the window), found " +
                         std::to_string(im.width) + "x" + std::to_string(im.height));
  return Status::ok();
}

inline double ssim_at(double mu_a, double mu_b, double saa, double sbb, double sab, double c1,
                      double c2) {
  return ((2 * mu_a * mu_b + c1) * (2 * sab + c2)) /
         ((mu_a * mu_a + mu_b * mu_b + c1) * (saa + sbb + c2));
}

// out[x] = sum_t g[t] * in[x + t], x in [0, n): one horizontal 1-D filter (restrict: vectorises).
void filter_row(const float* __restrict in, const float* __restrict g, int taps, int n,
                float* __restrict out) {
  for (int x = 0; x < n; ++x) out[x] = 0.f;
  for (int t = 0; t < taps; ++t) {
    const float w = g[t];
    const float* __restrict src = in + t;
    for (int x = 0; x < n; ++x) out[x] += w * src[x];
  }
}

// dst[x] = a[x] * b[x].
void multiply_row(const float* __restrict a, const float* __restrict b, int n,
                  float* __restrict dst) {
  for (int x = 0; x < n; ++x) dst[x] = a[x] * b[x];
}

// out[x] += w * in[x].
void axpy_row(float w, const float* __restrict in, int n, float* __restrict out) {
  for (int x = 0; x < n; ++x) out[x] += w * in[x];
}

// One row of the SSIM map from the five filtered rows m [5, n] (a, b, aa, bb, ab of the shifted
// planes; `shift` added back to the means), in float so it vectorises.
void ssim_row(const float* __restrict m, int n, float shift, float c1, float c2,
              float* __restrict out) {
  const float* __restrict ma = m;
  const float* __restrict mb = m + n;
  const float* __restrict maa = m + 2 * n;
  const float* __restrict mbb = m + 3 * n;
  const float* __restrict mab = m + 4 * n;
  for (int x = 0; x < n; ++x) {
    const float saa = maa[x] - ma[x] * ma[x];
    const float sbb = mbb[x] - mb[x] * mb[x];
    const float sab = mab[x] - ma[x] * mb[x];
    const float ua = ma[x] + shift, ub = mb[x] + shift;
    out[x] =
        ((2.f * ua * ub + c1) * (2.f * sab + c2)) / ((ua * ua + ub * ub + c1) * (saa + sbb + c2));
  }
}

bool all_u8_levels(const gs::Image& im) {
  for (float v : im.data) {
    const float s = v * 255.0f;
    if (!(s >= 0.0f && s <= 255.0f) || s != std::nearbyint(s)) return false;
  }
  return true;
}

}  // namespace

// ---- PSNR --------------------------------------------------------------------------------------

Result<double> psnr(const gs::Image& pred, const gs::Image& gt, double data_range) {
  MACRO_TRY(check_pair(pred, gt));
  if (!(data_range > 0)) return Status::error("psnr: data_range must be > 0");
  double se = 0;
  for (size_t i = 0; i < pred.data.size(); ++i) {
    const double d = double(pred.data[i]) - double(gt.data[i]);
    se += d * d;
  }
  const double mse = se / double(pred.data.size());
  if (mse == 0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(data_range * data_range / mse);
}

// ---- SSIM --------------------------------------------------------------------------------------

Result<double> ssim(const gs::Image& pred, const gs::Image& gt, const SsimParams& params,
                    ThreadPool& pool) {
  MACRO_TRY(check_pair(pred, gt));
  MACRO_TRY(check_ssim_params(params));
  MACRO_TRY(check_ssim_size(gt, params.window));
  const int n = params.window, H = gt.height, W = gt.width, C = gt.channels;
  const int Hv = H - n + 1, Wv = W - n + 1;
  const std::vector<double> gd = gaussian_taps(n, params.sigma);
  const std::vector<float> g(gd.begin(), gd.end());
  const double c1 = (params.k1 * params.data_range) * (params.k1 * params.data_range);
  const double c2 = (params.k2 * params.data_range) * (params.k2 * params.data_range);
  const float shift = float(params.data_range * 0.5);

  const size_t plane = size_t(H) * size_t(W), hplane = size_t(H) * size_t(Wv);
  std::vector<float> a(plane), b(plane);  // one channel, shifted by -R/2   [H, W]
  std::vector<float> hf(5 * hplane);      // horizontal pass: a, b, aa, bb, ab   [5, H, Wv]
  std::vector<double> row_sum(size_t(C) * size_t(Hv));

  for (int c = 0; c < C; ++c) {
    for (size_t p = 0; p < plane; ++p) {
      a[p] = pred.data[p * size_t(C) + size_t(c)] - shift;
      b[p] = gt.data[p * size_t(C) + size_t(c)] - shift;
    }
    // Pass 1: rows [H], each to five [Wv] rows.
    pool.parallel_for(
        size_t(H),
        [&](size_t r0, size_t r1, int) {
          std::vector<float> prod(static_cast<size_t>(W));
          for (size_t r = r0; r < r1; ++r) {
            const float* ar = a.data() + r * size_t(W);
            const float* br = b.data() + r * size_t(W);
            float* o = hf.data() + r * size_t(Wv);
            filter_row(ar, g.data(), n, Wv, o + 0 * hplane);
            filter_row(br, g.data(), n, Wv, o + 1 * hplane);
            multiply_row(ar, ar, W, prod.data());
            filter_row(prod.data(), g.data(), n, Wv, o + 2 * hplane);
            multiply_row(br, br, W, prod.data());
            filter_row(prod.data(), g.data(), n, Wv, o + 3 * hplane);
            multiply_row(ar, br, W, prod.data());
            filter_row(prod.data(), g.data(), n, Wv, o + 4 * hplane);
          }
        },
        8);
    // Pass 2: valid output rows [Hv].
    pool.parallel_for(
        size_t(Hv),
        [&](size_t r0, size_t r1, int) {
          std::vector<float> m(6 * size_t(Wv));  // five means, then the SSIM row
          for (size_t r = r0; r < r1; ++r) {
            std::fill(m.begin(), m.end(), 0.f);
            for (int k = 0; k < 5; ++k)
              for (int t = 0; t < n; ++t)
                axpy_row(g[size_t(t)],
                         hf.data() + size_t(k) * hplane + (r + size_t(t)) * size_t(Wv), Wv,
                         m.data() + size_t(k) * size_t(Wv));
            float* map = m.data() + 5 * size_t(Wv);
            ssim_row(m.data(), Wv, shift, float(c1), float(c2), map);
            double sum = 0;
            for (int x = 0; x < Wv; ++x) sum += map[x];
            row_sum[size_t(c) * size_t(Hv) + r] = sum;
          }
        },
        4);
  }
  double total = 0;
  for (double s : row_sum) total += s;
  return total / (double(C) * double(Hv) * double(Wv));
}

Result<double> ssim_reference(const gs::Image& pred, const gs::Image& gt,
                              const SsimParams& params) {
  MACRO_TRY(check_pair(pred, gt));
  MACRO_TRY(check_ssim_params(params));
  MACRO_TRY(check_ssim_size(gt, params.window));
  const int n = params.window, H = gt.height, W = gt.width, C = gt.channels;
  const std::vector<double> g = gaussian_taps(n, params.sigma);
  const double c1 = (params.k1 * params.data_range) * (params.k1 * params.data_range);
  const double c2 = (params.k2 * params.data_range) * (params.k2 * params.data_range);
  double total = 0;
  for (int c = 0; c < C; ++c)
    for (int i = 0; i + n <= H; ++i)
      for (int j = 0; j + n <= W; ++j) {
        double ma = 0, mb = 0, aa = 0, bb = 0, ab = 0;
        for (int u = 0; u < n; ++u)
          for (int v = 0; v < n; ++v) {
            const double w = g[size_t(u)] * g[size_t(v)];
            const double x = pred.at(i + u, j + v, c), y = gt.at(i + u, j + v, c);
            ma += w * x, mb += w * y, aa += w * x * x, bb += w * y * y, ab += w * x * y;
          }
        total += ssim_at(ma, mb, aa - ma * ma, bb - mb * mb, ab - ma * mb, c1, c2);
      }
  return total / (double(C) * double(H - n + 1) * double(W - n + 1));
}

// ---- size match --------------------------------------------------------------------------------

Result<gs::Image> match_size(const gs::Image& pred, int width, int height, ThreadPool& pool) {
  MACRO_TRY(check_image(pred, "pred"));
  if (width <= 0 || height <= 0)
    return Status::error("match_size: target size must be positive, found " +
                         std::to_string(width) + "x" + std::to_string(height));
  if (pred.width == width && pred.height == height) return pred;
  if (!all_u8_levels(pred)) return resize_lanczos(pred, width, height, pool);
  std::vector<uint8_t> u8(pred.data.size());
  for (size_t i = 0; i < u8.size(); ++i) u8[i] = uint8_t(std::lrint(pred.data[i] * 255.0f));
  const std::vector<uint8_t> out =
      resize_lanczos_u8(u8.data(), pred.width, pred.height, pred.channels, width, height, pool);
  gs::Image r(width, height, pred.channels);
  for (size_t i = 0; i < out.size(); ++i) r.data[i] = float(out[i]) / 255.0f;
  return r;
}

// ---- sharpness ---------------------------------------------------------------------------------

double gradient_energy(const gs::Image& im) {
  const int W = im.width, H = im.height, C = im.channels;
  if (W < 2 || H < 2 || C < 1 || im.data.size() != im.pixels() * size_t(C)) return 0.0;
  auto lum = [&](int y, int x) {
    const float* p = &im.data[(size_t(y) * W + x) * C];
    return C >= 3 ? 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2] : double(p[0]);
  };
  double sum = 0;
  for (int y = 0; y + 1 < H; ++y)
    for (int x = 0; x + 1 < W; ++x) {
      const double v = lum(y, x), dx = lum(y, x + 1) - v, dy = lum(y + 1, x) - v;
      sum += dx * dx + dy * dy;
    }
  return sum / (double(W - 1) * double(H - 1));
}

Result<double> gradient_energy_ratio(const gs::Image& pred, const gs::Image& gt) {
  MACRO_TRY(check_pair(pred, gt));
  const double g = gradient_energy(gt), p = gradient_energy(pred);
  if (g <= 0) return p <= 0 ? 1.0 : std::numeric_limits<double>::infinity();
  return p / g;
}

// ---- suite -------------------------------------------------------------------------------------

Result<std::vector<MetricValue>> compute_metrics(const gs::Image& pred_in, const gs::Image& gt,
                                                 const MetricOptions& options, ThreadPool& pool) {
  MACRO_TRY(check_image(gt, "gt"));
  MACRO_TRY(check_image(pred_in, "pred"));
  gs::Image pred;
  if (options.resize_pred && (pred_in.width != gt.width || pred_in.height != gt.height)) {
    MACRO_ASSIGN_OR_RETURN(pred, match_size(pred_in, gt.width, gt.height, pool));
  } else {
    pred = pred_in;
  }
  MACRO_TRY(check_pair(pred, gt));
  std::vector<MetricValue> out;
  {
    MACRO_ASSIGN_OR_RETURN(double v, psnr(pred, gt));
    out.push_back({"psnr", true, v, "dB", ""});
  }
  {
    MACRO_ASSIGN_OR_RETURN(double v, ssim(pred, gt, SsimParams{}, pool));
    out.push_back({"ssim", true, v, "", ""});
  }
  {
    MetricValue m{"lpips_alex", false, 0.0, "", ""};
    if (gt.channels != 3) {
      m.reason = "LPIPS needs RGB images, found " + std::to_string(gt.channels) + " channels";
    } else if (gt.width < kLpipsMinSide || gt.height < kLpipsMinSide) {
      m.reason = "LPIPS-Alex needs images of at least " + std::to_string(kLpipsMinSide) + "x" +
                 std::to_string(kLpipsMinSide);
    } else {
      Result<LpipsAlex> net = LpipsAlex::load(options.lpips_backbone, options.lpips_heads);
      if (!net) {
        m.reason = net.status().message();
      } else {
        MACRO_ASSIGN_OR_RETURN(LpipsResult r, net->distance(pred, gt, pool));
        m.computed = true;
        m.value = r.value;
      }
    }
    out.push_back(std::move(m));
  }
  if (options.feature_metrics) {
    out.push_back(dinov2_distance(pred, gt, options.dinov2_weights, &pool));
    out.push_back(dreamsim_distance(pred, gt, options.dreamsim_weights, &pool));
  }
  return out;
}

std::string format_metrics_text(const std::vector<MetricValue>& values) {
  std::string s;
  char buf[64];
  for (const MetricValue& m : values) {
    s += m.name + ": ";
    if (!m.computed) {
      s += "not computed: " + m.reason + "\n";
      continue;
    }
    if (std::isinf(m.value))
      std::snprintf(buf, sizeof(buf), "inf");
    else
      std::snprintf(buf, sizeof(buf), m.unit.empty() ? "%.6f" : "%.4f", m.value);
    s += buf;
    if (!m.unit.empty()) s += " " + m.unit;
    s += "\n";
  }
  return s;
}

namespace {
std::string json_string(const std::string& v) {
  std::string s = "\"";
  for (char ch : v) {
    const unsigned char u = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') {
      s += '\\';
      s += ch;
    } else if (u < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\u%04x", u);
      s += buf;
    } else {
      s += ch;
    }
  }
  return s + "\"";
}
}  // namespace

std::string format_metrics_json(const std::vector<MetricValue>& values) {
  // Not-computed metrics are null and listed with their reasons; +inf PSNR is the string "inf"
  // (JSON has no infinity), as in the goldens' JSON.
  std::string s = "{\n";
  std::string reasons;
  char buf[64];
  for (const MetricValue& m : values) {
    s += "  " + json_string(m.name) + ": ";
    if (!m.computed) {
      s += "null";
      if (!reasons.empty()) reasons += ",\n";
      reasons += "    " + json_string(m.name) + ": " + json_string(m.reason);
    } else if (std::isinf(m.value)) {
      s += "\"inf\"";
    } else {
      std::snprintf(buf, sizeof(buf), "%.17g", m.value);
      s += buf;
    }
    s += ",\n";
  }
  s += "  \"not_computed\": {" + (reasons.empty() ? std::string() : "\n" + reasons + "\n  ") +
       "}\n}\n";
  return s;
}

}  // namespace macro::enhance
