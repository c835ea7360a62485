// The stages of the transfer enhancer (declared, with the data they share, in transfer_stages.h)
// and the image helpers they use: luminance, separable Gaussian blur, the sampled gradient energy
// of step 1, integral images, window descriptors, the tent weight.
#include "enhance/transfer/transfer_stages.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "attention/runtime/attention.h"
#include "attention/runtime/attention_mask.h"

namespace macro::enhance::transfer_stages {
namespace {

constexpr int kFeatures = 19;            // 16 block means + 3 mean colours
constexpr int kSlotValues = 5;           // per source slot: [1, x, y, x^2, y^2]
constexpr int kSigmaRowStep = 8;         // step 1 samples every 8th row pair
constexpr double kResidualEps = 0.01;    // luminance floor of the refinement's normalisation
constexpr double kStructureEps = 0.002;  // luminance rms per block below which structure fades
// Step 1's blur grid (pixels); values above max_sigma are dropped.
constexpr double kSigmaGrid[] = {0, 0.25, 0.5, 0.75, 1, 1.25, 1.5, 2, 2.5, 3, 3.5, 4, 5, 6, 8};

float luma(const float* rgb) {
  return 0.299f * rgb[0] + 0.587f * rgb[1] + 0.114f * rgb[2];
}

std::vector<float> luminance(const gs::Image& im, ThreadPool& pool) {
  std::vector<float> y(im.pixels());
  pool.parallel_for(size_t(im.height), [&](size_t b, size_t e, int) {
    for (size_t r = b; r < e; ++r)
      for (size_t x = 0; x < size_t(im.width); ++x) {
        const size_t p = r * size_t(im.width) + x;
        y[p] = luma(&im.data[p * 3]);
      }
  });
  return y;
}

// Normalised Gaussian taps, radius ceil(3 sigma); sigma < 0.05 is the identity.
std::vector<float> gaussian_taps(double sigma) {
  if (sigma < 0.05) return {1.f};
  const int r = int(std::ceil(3.0 * sigma));
  std::vector<double> w(size_t(2 * r + 1));
  double sum = 0;
  for (int k = -r; k <= r; ++k) sum += w[size_t(k + r)] = std::exp(-0.5 * k * k / (sigma * sigma));
  std::vector<float> out(w.size());
  for (size_t i = 0; i < w.size(); ++i) out[i] = float(w[i] / sum);
  return out;
}

// Separable Gaussian of an interleaved [H, W, C] buffer, edges clamped; rows threaded, each output
// element summed in a fixed order.
std::vector<float> blur(const std::vector<float>& src, int W, int H, int C,
                        const std::vector<float>& taps, ThreadPool& pool) {
  const int r = int(taps.size() / 2);
  if (r == 0) return src;
  const size_t row = size_t(W) * C;
  std::vector<float> tmp(src.size()), dst(src.size());
  pool.parallel_for(size_t(H), [&](size_t b, size_t e, int) {
    for (size_t y = b; y < e; ++y) {
      float* o = &tmp[y * row];
      std::fill(o, o + row, 0.f);
      for (int k = 0; k < int(taps.size()); ++k) {
        const int sy = std::clamp(int(y) + k - r, 0, H - 1);
        const float* s = &src[size_t(sy) * row];
        const float t = taps[size_t(k)];
        for (size_t i = 0; i < row; ++i) o[i] += t * s[i];
      }
    }
  });
  pool.parallel_for(size_t(H), [&](size_t b, size_t e, int) {
    std::vector<float> pad((size_t(W) + 2 * size_t(r)) * C);
    for (size_t y = b; y < e; ++y) {
      const float* t = &tmp[y * row];
      for (int x = -r; x < W + r; ++x) {
        const int sx = std::clamp(x, 0, W - 1);
        for (int c = 0; c < C; ++c) pad[size_t(x + r) * C + c] = t[size_t(sx) * C + c];
      }
      float* o = &dst[y * row];
      std::fill(o, o + row, 0.f);
      for (int k = 0; k < int(taps.size()); ++k) {
        const float* s = &pad[size_t(k) * C];
        const float w = taps[size_t(k)];
        for (size_t i = 0; i < row; ++i) o[i] += w * s[i];
      }
    }
  });
  return dst;
}

// Sum of squared forward differences over one row pair (y0 above y1, W pixels each) at pixels
// whose right and lower neighbours are in the masks too; adds the pixels used to *count.
double masked_grad_energy(const float* y0, const float* y1, const uint8_t* m0, const uint8_t* m1,
                          int W, double* count) {
  double sum = 0;
  for (int x = 0; x + 1 < W; ++x) {
    if (!m0[x] || !m0[x + 1] || !m1[x]) continue;
    const double dx = double(y0[x + 1]) - y0[x], dy = double(y1[x]) - y0[x];
    sum += dx * dx + dy * dy;
    *count += 1;
  }
  return sum;
}

// The blurred luminance rows y and y+1 (2 x W) of the full-image blur, computed directly.
void blurred_row_pair(const std::vector<float>& Y, int W, int H, int y,
                      const std::vector<float>& taps, float* out /* [2, W] */) {
  const int r = int(taps.size() / 2);
  std::vector<float> v(static_cast<size_t>(W)), pad(static_cast<size_t>(W + 2 * r));
  for (int q = 0; q < 2; ++q) {
    std::fill(v.begin(), v.end(), 0.f);
    for (int k = 0; k < int(taps.size()); ++k) {
      const int sy = std::clamp(y + q + k - r, 0, H - 1);
      const float* s = &Y[size_t(sy) * W];
      for (int x = 0; x < W; ++x) v[size_t(x)] += taps[size_t(k)] * s[x];
    }
    for (int x = -r; x < W + r; ++x) pad[size_t(x + r)] = v[size_t(std::clamp(x, 0, W - 1))];
    float* o = out + size_t(q) * W;
    std::fill(o, o + W, 0.f);
    for (int k = 0; k < int(taps.size()); ++k)
      for (int x = 0; x < W; ++x) o[x] += taps[size_t(k)] * pad[size_t(x + k)];
  }
}

double sampled_energy(const std::vector<float>& Y, const std::vector<uint8_t>& mask, int W, int H,
                      const std::vector<float>& taps) {
  std::vector<float> rows(2 * size_t(W));
  double sum = 0, count = 0;
  for (int y = 0; y + 1 < H; y += kSigmaRowStep) {
    blurred_row_pair(Y, W, H, y, taps, rows.data());
    sum += masked_grad_energy(rows.data(), rows.data() + W, &mask[size_t(y) * W],
                              &mask[size_t(y + 1) * W], W, &count);
  }
  return count > 0 ? sum / count : 0.0;
}

// Integral image (double) of one plane, [(H+1) * (W+1)].
std::vector<double> integral(const float* v, int W, int H, int stride, int channel) {
  std::vector<double> I((size_t(H) + 1) * (size_t(W) + 1), 0.0);
  for (int y = 0; y < H; ++y) {
    double row = 0;
    for (int x = 0; x < W; ++x) {
      row += v[(size_t(y) * W + x) * stride + channel];
      I[(size_t(y) + 1) * (W + 1) + x + 1] = I[size_t(y) * (W + 1) + x + 1] + row;
    }
  }
  return I;
}
std::vector<int32_t> integral_count(const std::vector<uint8_t>& bad, int W, int H) {
  std::vector<int32_t> I((size_t(H) + 1) * (size_t(W) + 1), 0);
  for (int y = 0; y < H; ++y) {
    int32_t row = 0;
    for (int x = 0; x < W; ++x) {
      row += bad[size_t(y) * W + x];
      I[(size_t(y) + 1) * (W + 1) + x + 1] = I[size_t(y) * (W + 1) + x + 1] + row;
    }
  }
  return I;
}
template <typename T>
T box_sum(const std::vector<T>& I, int W, int y0, int x0, int y1, int x1) {
  const size_t s = size_t(W) + 1;
  return I[size_t(y1) * s + x1] - I[size_t(y0) * s + x1] - I[size_t(y1) * s + x0] +
         I[size_t(y0) * s + x0];
}

// Integral images of a degraded image's luminance and colour, for the descriptors.
struct DescriptorSource {
  int W = 0, H = 0;
  std::vector<double> iy, ir, ig, ib;
};
DescriptorSource descriptor_source(const std::vector<float>& Y, const std::vector<float>& rgb,
                                   int W, int H) {
  DescriptorSource d;
  d.W = W, d.H = H;
  d.iy = integral(Y.data(), W, H, 1, 0);
  d.ir = integral(rgb.data(), W, H, 3, 0);
  d.ig = integral(rgb.data(), W, H, 3, 1);
  d.ib = integral(rgb.data(), W, H, 3, 2);
  return d;
}

// The features of the 16 x 16 window centred at (cy, cx) (window [cy-8, cy+8)), clamped to the
// image; returns false when the clamped window is empty.
bool window_features(const DescriptorSource& s, int cy, int cx, double match_sigma,
                     double colour_sigma, float* f /* [kFeatures] */) {
  const int h = kTransferWindow / 2, b = kTransferWindow / 4;
  const int wy0 = std::max(cy - h, 0), wy1 = std::min(cy + h, s.H);
  const int wx0 = std::max(cx - h, 0), wx1 = std::min(cx + h, s.W);
  if (wy0 >= wy1 || wx0 >= wx1) return false;
  const double n = double(wy1 - wy0) * (wx1 - wx0);
  const double mean = box_sum(s.iy, s.W, wy0, wx0, wy1, wx1) / n;
  double st[16], n2 = 0;
  for (int bi = 0; bi < 4; ++bi)
    for (int bj = 0; bj < 4; ++bj) {
      const int y0 = std::clamp(cy - h + bi * b, 0, s.H),
                y1 = std::clamp(cy - h + bi * b + b, 0, s.H);
      const int x0 = std::clamp(cx - h + bj * b, 0, s.W),
                x1 = std::clamp(cx - h + bj * b + b, 0, s.W);
      const double cnt = double(y1 - y0) * (x1 - x0);
      const double d = cnt > 0 ? box_sum(s.iy, s.W, y0, x0, y1, x1) / cnt - mean : 0.0;
      st[bi * 4 + bj] = d;
      n2 += d * d;
    }
  // Structure: unit norm (contrast-invariant), softened below kStructureEps rms per block.
  const double norm = std::sqrt(n2 + 16.0 * kStructureEps * kStructureEps);
  for (int k = 0; k < 16; ++k) f[k] = float(st[k] / norm / match_sigma);
  f[16] = float(box_sum(s.ir, s.W, wy0, wx0, wy1, wx1) / n / colour_sigma);
  f[17] = float(box_sum(s.ig, s.W, wy0, wx0, wy1, wx1) / n / colour_sigma);
  f[18] = float(box_sum(s.ib, s.W, wy0, wx0, wy1, wx1) / n / colour_sigma);
  return true;
}

// Tent weight of pixel offset u in [0, 16) inside a token window (pairs of overlapping windows at
// stride 8 sum to 1).
float tent(int u) {
  return u < kTransferToken ? (float(u) + 0.5f) / kTransferToken
                            : (float(kTransferWindow - u) - 0.5f) / kTransferToken;
}

}  // namespace

void init_result(TransferWork& work) {
  const gs::Image& render = work.render;
  TransferResult& res = work.res;
  work.W = render.width, work.H = render.height;
  work.n = int(work.sources.size());
  work.th = (work.H + kTransferToken - 1) / kTransferToken;
  work.tw = (work.W + kTransferToken - 1) / kTransferToken;
  work.nq = work.th * work.tw;
  res.token_h = work.th, res.token_w = work.tw;
  res.image = render;
  res.confidence.assign(size_t(work.nq), 0.f);
  res.chosen.assign(size_t(work.nq), -1);
  res.sigma.assign(size_t(work.n), 0.0);
}

Status assign_source_slots(TransferWork& work) {
  const std::vector<TransferSourceImage>& sources = work.sources;
  const int n = work.n, planes = work.planes;
  std::vector<PerSource>& ps = work.ps;
  std::vector<std::vector<int>>& slot_source = work.slot_source;
  // Source slots: whole sources (plane -1) first, then each plane's crops, by index.
  int whole = 0;
  for (const auto& s : sources) whole += s.plane < 0;
  std::vector<int> per_plane(size_t(planes), 0);
  ps.resize(static_cast<size_t>(n));
  slot_source.resize(static_cast<size_t>(planes));
  for (int s = 0, w = 0; s < n; ++s)
    if (sources[size_t(s)].plane < 0) ps[size_t(s)].slot = w++;
  for (int s = 0; s < n; ++s)
    if (sources[size_t(s)].plane >= 0)
      ps[size_t(s)].slot = whole + per_plane[size_t(sources[size_t(s)].plane)]++;
  int slots = 0;
  for (int p = 0; p < planes; ++p) {
    slot_source[size_t(p)].assign(size_t(whole + per_plane[size_t(p)]), -1);
    slots = std::max(slots, whole + per_plane[size_t(p)]);
  }
  for (int s = 0; s < n; ++s)
    for (int p = 0; p < planes; ++p)
      if (sources[size_t(s)].plane < 0 || sources[size_t(s)].plane == p)
        slot_source[size_t(p)][size_t(ps[size_t(s)].slot)] = s;
  work.slots = slots;
  const int D = std::max(16, ((std::max(kFeatures + 1, kSlotValues * slots) + 15) / 16) * 16);
  work.D = D;
  if (D > attention_detail::kMaxHeadDim)
    return Status::error("transfer: " + std::to_string(slots) +
                         " sources per plane need a head width of " + std::to_string(D) +
                         ", above the kernel's " + std::to_string(attention_detail::kMaxHeadDim));
  return Status::ok();
}

// 1. Usable pixels per source (valid and `margin` away from padding); the luminances.
void usable_pixels(TransferWork& work) {
  const gs::Image& render = work.render;
  const std::vector<TransferSourceImage>& sources = work.sources;
  const int W = work.W, H = work.H, n = work.n;
  ThreadPool& pool = work.pool;
  std::vector<PerSource>& ps = work.ps;
  work.Yr = luminance(render, pool);
  std::vector<std::vector<float>>& Ys = work.Ys;
  Ys.resize(static_cast<size_t>(n));
  pool.parallel_for(size_t(n), [&](size_t b, size_t e, int) {
    for (size_t s = b; s < e; ++s) {
      const TransferSourceImage& src = sources[s];
      std::vector<uint8_t> bad(render.pixels());
      for (size_t p = 0; p < bad.size(); ++p) bad[p] = src.valid[p] == 0;
      const std::vector<int32_t> ib = integral_count(bad, W, H);
      PerSource& d = ps[s];
      d.ok.assign(render.pixels(), 0);
      const int m = src.margin;
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const int y0 = std::max(y - m, 0), y1 = std::min(y + m + 1, H);
          const int x0 = std::max(x - m, 0), x1 = std::min(x + m + 1, W);
          d.ok[size_t(y) * W + x] = box_sum(ib, W, y0, x0, y1, x1) == 0;
        }
      for (size_t p = 0; p < bad.size(); ++p) bad[p] = !d.ok[p];
      d.bad = integral_count(bad, W, H);
      Ys[s].resize(render.pixels());
      for (size_t p = 0; p < render.pixels(); ++p) Ys[s][p] = luma(&src.image.data[p * 3]);
    }
  });
}

// 1. The blur estimate per source, then the degraded colour and luminance of every source.
void estimate_blur(TransferWork& work) {
  const gs::Image& render = work.render;
  const std::vector<int32_t>& labels = work.labels;
  const std::vector<TransferSourceImage>& sources = work.sources;
  const TransferParams& prm = work.prm;
  const int W = work.W, H = work.H, n = work.n, planes = work.planes;
  ThreadPool& pool = work.pool;
  std::vector<PerSource>& ps = work.ps;
  const std::vector<float>& Yr = work.Yr;
  std::vector<std::vector<float>>& Ys = work.Ys;
  TransferResult& res = work.res;
  std::vector<double> grid;
  for (double g : kSigmaGrid)
    if (g <= prm.max_sigma + 1e-9) grid.push_back(g);
  std::vector<std::vector<float>> grid_taps;
  for (double g : grid) grid_taps.push_back(gaussian_taps(g));
  // Render energy per plane (index P = every labelled pixel).
  std::vector<double> target(size_t(planes) + 1, 0.0);
  for (int p = 0; p <= planes; ++p) {
    std::vector<uint8_t> m(render.pixels());
    for (size_t i = 0; i < m.size(); ++i) m[i] = p == planes ? labels[i] >= 0 : labels[i] == p;
    target[size_t(p)] = sampled_energy(Yr, m, W, H, {1.f});
  }
  std::vector<double> energy(size_t(n) * grid.size());
  pool.parallel_for(
      energy.size(),
      [&](size_t b, size_t e, int) {
        for (size_t i = b; i < e; ++i) {
          const size_t s = i / grid.size(), g = i % grid.size();
          energy[i] = sampled_energy(Ys[s], ps[s].ok, W, H, grid_taps[g]);
        }
      },
      1);
  for (int s = 0; s < n; ++s) {
    const int p = sources[size_t(s)].plane;
    const double goal = target[size_t(p < 0 ? planes : p)];
    const double* E = &energy[size_t(s) * grid.size()];
    double sigma = 0;
    if (E[0] <= goal) {
      sigma = 0;
    } else if (E[grid.size() - 1] > goal) {
      sigma = grid.back();
    } else {
      for (size_t g = 1; g < grid.size(); ++g)
        if (E[g] <= goal) {
          const double f = (E[g - 1] - goal) / std::max(E[g - 1] - E[g], 1e-30);
          sigma = grid[g - 1] + f * (grid[g] - grid[g - 1]);
          break;
        }
    }
    res.sigma[size_t(s)] = sigma;
  }
  // Degraded colour and luminance of every source.
  for (int s = 0; s < n; ++s) {
    PerSource& d = ps[size_t(s)];
    d.rgb_deg =
        blur(sources[size_t(s)].image.data, W, H, 3, gaussian_taps(res.sigma[size_t(s)]), pool);
    d.y_deg.resize(render.pixels());
    for (size_t p = 0; p < render.pixels(); ++p) d.y_deg[p] = luma(&d.rgb_deg[p * 3]);
    Ys[size_t(s)] = {};
  }
}

// 2. Descriptors: queries on the render, keys on the degraded sources.
void build_descriptors(TransferWork& work) {
  const gs::Image& render = work.render;
  const std::vector<int32_t>& labels = work.labels;
  const std::vector<TransferSourceImage>& sources = work.sources;
  const TransferParams& prm = work.prm;
  const int W = work.W, H = work.H, n = work.n, planes = work.planes, tw = work.tw, nq = work.nq,
            D = work.D;
  ThreadPool& pool = work.pool;
  const std::vector<PerSource>& ps = work.ps;
  const std::vector<float>& Yr = work.Yr;
  TransferResult& res = work.res;
  const int ks = prm.key_stride;
  const int kh = (H + ks - 1) / ks, kw = (W + ks - 1) / ks, nk_per = kh * kw;
  const int nk = nk_per * n;
  work.ks = ks, work.kh = kh, work.kw = kw, work.nk_per = nk_per, work.nk = nk;
  std::vector<float>& q = work.q;  // [nq, D]
  std::vector<float>& k = work.k;  // [nk, D]
  std::vector<float>& v = work.v;  // [nk, D]
  q.assign(size_t(nq) * D, 0.f);
  k.assign(size_t(nk) * D, 0.f);
  v.assign(size_t(nk) * D, 0.f);
  std::vector<int32_t>& qgroup = work.qgroup;
  std::vector<int32_t>& kgroup = work.kgroup;
  qgroup.resize(static_cast<size_t>(nq));
  kgroup.resize(static_cast<size_t>(nk));
  {
    const DescriptorSource rs = descriptor_source(Yr, render.data, W, H);
    pool.parallel_for(size_t(nq), [&](size_t b, size_t e, int) {
      for (size_t t = b; t < e; ++t) {
        const int i = int(t) / tw, j = int(t) % tw;
        // Plane of the token: the mode of its 8 x 8 core's labels (ties -> the smaller label,
        // as the MACRO latent map), -1 when none is labelled.
        int votes[65] = {0};
        for (int y = i * kTransferToken; y < std::min(H, (i + 1) * kTransferToken); ++y)
          for (int x = j * kTransferToken; x < std::min(W, (j + 1) * kTransferToken); ++x) {
            const int l = labels[size_t(y) * W + x];
            if (l >= 0) ++votes[l];
          }
        int best = -1;
        for (int p = 0; p < planes; ++p)
          if (votes[p] > 0 && (best < 0 || votes[p] > votes[best])) best = p;
        float* row = &q[t * D];
        const int cy = i * kTransferToken + kTransferToken / 2,
                  cx = j * kTransferToken + kTransferToken / 2;
        if (best >= 0 && !window_features(rs, cy, cx, prm.match_sigma, prm.colour_sigma, row))
          best = -1;
        row[kFeatures] = 1.f;
        qgroup[t] = best < 0 ? planes : best;
      }
    });
  }
  std::vector<int> key_valid_count(size_t(n), 0);
  for (int s = 0; s < n; ++s) {
    const PerSource& d = ps[size_t(s)];
    const DescriptorSource ds = descriptor_source(d.y_deg, d.rgb_deg, W, H);
    const int group = sources[size_t(s)].plane < 0 ? planes : sources[size_t(s)].plane;
    pool.parallel_for(size_t(nk_per), [&](size_t b, size_t e, int) {
      for (size_t t = b; t < e; ++t) {
        const int a = int(t) / kw, c = int(t) % kw;
        const int cy = a * ks + ks / 2, cx = c * ks + ks / 2;
        const int y0 = cy - kTransferWindow / 2, x0 = cx - kTransferWindow / 2;
        const size_t kt = size_t(s) * nk_per + t;
        bool valid = y0 >= 0 && x0 >= 0 && y0 + kTransferWindow <= H && x0 + kTransferWindow <= W &&
                     box_sum(d.bad, W, y0, x0, y0 + kTransferWindow, x0 + kTransferWindow) == 0;
        float* row = &k[kt * D];
        if (valid) valid = window_features(ds, cy, cx, prm.match_sigma, prm.colour_sigma, row);
        if (valid) {
          double n2 = 0;
          for (int f = 0; f < kFeatures; ++f) n2 += double(row[f]) * row[f];
          row[kFeatures] = float(-0.5 * n2);
          float* val = &v[kt * D + size_t(kSlotValues) * d.slot];
          val[0] = 1.f;
          val[1] = float(c);
          val[2] = float(a);
          val[3] = float(c) * float(c);
          val[4] = float(a) * float(a);
        }
        kgroup[kt] = valid ? group : planes + 1;
      }
    });
    for (int t = 0; t < nk_per; ++t)
      key_valid_count[size_t(s)] += kgroup[size_t(s) * nk_per + t] <= planes;
    res.keys += key_valid_count[size_t(s)];
  }
}

// 3. Masked attention: query group p (plane) sees key groups p and P (whole references);
// query group P (no plane) and key group P+1 (invalid keys) take part in nothing.
Status attend(TransferWork& work) {
  const int planes = work.planes, nq = work.nq, nk = work.nk, D = work.D;
  std::vector<uint8_t> allowed(size_t(planes + 1) * size_t(planes + 2), 0);
  for (int p = 0; p < planes; ++p) {
    allowed[size_t(p) * (planes + 2) + p] = 1;
    allowed[size_t(p) * (planes + 2) + planes] = 1;
  }
  MACRO_ASSIGN_OR_RETURN(BlockSparseMask mask, mask_from_groups(work.qgroup, work.kgroup,
                                                                planes + 1, planes + 2, allowed));
  work.out.assign(size_t(nq) * D, 0.f);
  AttentionArgs args;
  args.q = work.q.data(), args.k = work.k.data(), args.v = work.v.data();
  args.out = work.out.data();
  args.nq = nq, args.nk = nk, args.heads = 1, args.head_dim = D;
  args.scale = 1.f;  // the features are already in units of their sigmas
  args.mask = &mask;
  MACRO_TRY(attention(args, work.pool).with_context("transfer attention"));
  return Status::ok();
}

// 4-5. Per token: the source of largest mass, the refined displacement, the confidence.
void refine_matches(TransferWork& work) {
  const TransferParams& prm = work.prm;
  const int W = work.W, H = work.H, planes = work.planes, tw = work.tw, nq = work.nq, D = work.D,
            ks = work.ks;
  ThreadPool& pool = work.pool;
  const std::vector<PerSource>& ps = work.ps;
  const std::vector<std::vector<int>>& slot_source = work.slot_source;
  const std::vector<float>& Yr = work.Yr;
  const std::vector<int32_t>& qgroup = work.qgroup;
  const std::vector<float>& out = work.out;
  TransferResult& res = work.res;
  work.disp.assign(size_t(nq) * 2, 0);  // (dy, dx)
  std::vector<int32_t>& disp = work.disp;
  const int R = prm.search_radius;
  pool.parallel_for(size_t(nq), [&](size_t b, size_t e, int) {
    float rv[kTransferWindow * kTransferWindow / 4];
    int ry[kTransferWindow * kTransferWindow / 4], rx[kTransferWindow * kTransferWindow / 4];
    for (size_t t = b; t < e; ++t) {
      if (qgroup[t] >= planes) continue;
      const float* o = &out[t * D];
      const std::vector<int>& ss = slot_source[size_t(qgroup[t])];
      int best = -1;
      for (int sl = 0; sl < int(ss.size()); ++sl)
        if (o[kSlotValues * sl] > 0.f && (best < 0 || o[kSlotValues * sl] > o[kSlotValues * best]))
          best = sl;
      if (best < 0) continue;
      const float* sv = o + kSlotValues * best;
      const double mass = sv[0];
      const double ex = sv[1] / mass, ey = sv[2] / mass;
      const double var =
          std::max(0.0, sv[3] / mass - ex * ex) + std::max(0.0, sv[4] / mass - ey * ey);
      const double peak = std::min(1.0, mass) * std::exp(-var / prm.spread_scale);
      const int src = ss[size_t(best)];
      const int i = int(t) / tw, j = int(t) % tw;
      const int cy = i * kTransferToken + kTransferToken / 2,
                cx = j * kTransferToken + kTransferToken / 2;
      const int dy0 = int(std::lround(ey * ks + ks / 2 - cy));
      const int dx0 = int(std::lround(ex * ks + ks / 2 - cx));
      // Render samples: every second pixel of the window, inside the image.
      int ns = 0;
      double mr = 0;
      for (int y = cy - kTransferWindow / 2; y < cy + kTransferWindow / 2; y += 2)
        for (int x = cx - kTransferWindow / 2; x < cx + kTransferWindow / 2; x += 2) {
          if (y < 0 || y >= H || x < 0 || x >= W) continue;
          ry[ns] = y, rx[ns] = x, rv[ns] = Yr[size_t(y) * W + x];
          mr += rv[ns++];
        }
      if (ns == 0) continue;
      mr /= ns;
      double er = 0;
      for (int a = 0; a < ns; ++a) er += (rv[a] - mr) * (rv[a] - mr);
      const PerSource& d = ps[size_t(src)];
      double best_ssd = -1;
      int bdy = 0, bdx = 0;
      for (int dy = dy0 - R; dy <= dy0 + R; ++dy)
        for (int dx = dx0 - R; dx <= dx0 + R; ++dx) {
          const int y0 = cy - kTransferWindow / 2 + dy, x0 = cx - kTransferWindow / 2 + dx;
          if (y0 < 0 || x0 < 0 || y0 + kTransferWindow > H || x0 + kTransferWindow > W) continue;
          if (box_sum(d.bad, W, y0, x0, y0 + kTransferWindow, x0 + kTransferWindow) != 0) continue;
          double ms = 0;
          for (int a = 0; a < ns; ++a) ms += d.y_deg[size_t(ry[a] + dy) * W + rx[a] + dx];
          ms /= ns;
          double ssd = 0;
          for (int a = 0; a < ns; ++a) {
            const double diff = (rv[a] - mr) - (d.y_deg[size_t(ry[a] + dy) * W + rx[a] + dx] - ms);
            ssd += diff * diff;
          }
          // A window of another mean brightness is no match, however similar its structure.
          ssd += ns * (mr - ms) * (mr - ms);
          if (best_ssd < 0 || ssd < best_ssd) best_ssd = ssd, bdy = dy, bdx = dx;
        }
      if (best_ssd < 0) continue;
      const double residual = best_ssd / (er + ns * kResidualEps * kResidualEps);
      const double match = std::clamp(1.0 - residual / prm.max_residual, 0.0, 1.0);
      double conf = peak * match;
      if (conf < prm.min_confidence) conf = 0;
      res.confidence[t] = float(conf);
      res.chosen[t] = conf > 0 ? src : -1;
      disp[t * 2] = bdy, disp[t * 2 + 1] = bdx;
    }
  });
}

// 6. Compose: render + tent-weighted, confidence-weighted detail of the chosen windows.
void compose_detail(TransferWork& work) {
  const std::vector<TransferSourceImage>& sources = work.sources;
  const TransferParams& prm = work.prm;
  const int W = work.W, H = work.H, th = work.th, tw = work.tw;
  ThreadPool& pool = work.pool;
  const std::vector<PerSource>& ps = work.ps;
  const std::vector<int32_t>& disp = work.disp;
  TransferResult& res = work.res;
  pool.parallel_for(size_t(H), [&](size_t b, size_t e, int) {
    for (size_t yy = b; yy < e; ++yy) {
      const int y = int(yy);
      const int ia = (y + kTransferToken / 2) / kTransferToken;
      for (int x = 0; x < W; ++x) {
        const int ja = (x + kTransferToken / 2) / kTransferToken;
        float add[3] = {0.f, 0.f, 0.f};
        for (int i = ia - 1; i <= ia; ++i) {
          if (i < 0 || i >= th) continue;
          const float wy = tent(y - (i * kTransferToken - kTransferToken / 2));
          for (int j = ja - 1; j <= ja; ++j) {
            if (j < 0 || j >= tw) continue;
            const size_t t = size_t(i) * tw + j;
            if (res.chosen[t] < 0) continue;
            const float w = wy * tent(x - (j * kTransferToken - kTransferToken / 2)) *
                            res.confidence[t] * float(prm.gain);
            const size_t sp = (size_t(y + disp[t * 2]) * W + size_t(x + disp[t * 2 + 1])) * 3;
            const float* c = &sources[size_t(res.chosen[t])].image.data[sp];
            const float* cb = &ps[size_t(res.chosen[t])].rgb_deg[sp];
            for (int ch = 0; ch < 3; ++ch) add[ch] += w * (c[ch] - cb[ch]);
          }
        }
        float* o = &res.image.data[(size_t(y) * W + x) * 3];
        for (int ch = 0; ch < 3; ++ch) o[ch] = std::clamp(o[ch] + add[ch], 0.f, 1.f);
      }
    }
  });
}

void summarise(TransferWork& work) {
  TransferResult& res = work.res;
  double csum = 0;
  for (float c : res.confidence) {
    csum += c;
    res.transferred += c > 0;
  }
  res.mean_confidence = csum / work.nq;
}

}  // namespace macro::enhance::transfer_stages
