// Pillow-exact Lanczos, model size, upsamplers (see resample.h).
#include "enhance/resample.h"

#include <algorithm>
#include <cmath>

namespace macro::enhance {
namespace {

double sinc(double x) {
  if (x == 0.0) return 1.0;
  x *= M_PI;
  return std::sin(x) / x;
}
double lanczos(double x) {
  return (-kLanczosSupport <= x && x < kLanczosSupport) ? sinc(x) * sinc(x / kLanczosSupport) : 0.0;
}
// Pillow's bicubic_filter: Keys cubic with a = -0.5.
double bicubic(double x) {
  constexpr double a = -0.5;
  x = std::fabs(x);
  if (x < 1.0) return ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
  if (x < 2.0) return (((x - 5.0) * x + 8.0) * x - 4.0) * a;
  return 0.0;
}

// Fixed-point weights of the 8-bit path: round half away from zero, truncate.
std::vector<int32_t> fixed_weights(const ResampleTaps& t) {
  std::vector<int32_t> k(t.weights.size());
  const double one = double(1 << kPillowPrecisionBits);
  for (size_t i = 0; i < k.size(); ++i) {
    const double w = t.weights[i] * one;
    k[i] = static_cast<int32_t>(t.weights[i] < 0 ? w - 0.5 : w + 0.5);
  }
  return k;
}

uint8_t clip8(int64_t v) {
  if (v >= (int64_t(1) << kPillowPrecisionBits << 8)) return 255;
  if (v <= 0) return 0;
  return static_cast<uint8_t>(v >> kPillowPrecisionBits);
}

}  // namespace

ResampleTaps pillow_taps(int in_size, int out_size, PillowFilter filter) {
  MACRO_CHECK(in_size > 0 && out_size > 0);
  const bool cubic = filter == PillowFilter::kBicubic;
  double (*fn)(double) = cubic ? bicubic : lanczos;
  ResampleTaps t;
  t.in_size = in_size;
  t.out_size = out_size;
  const double scale = double(in_size) / double(out_size);
  const double filterscale = std::max(scale, 1.0);
  const double support = (cubic ? kBicubicSupport : kLanczosSupport) * filterscale;
  t.max_taps = int(std::ceil(support)) * 2 + 1;
  t.first.resize(size_t(out_size));
  t.count.resize(size_t(out_size));
  t.weights.assign(size_t(out_size) * size_t(t.max_taps), 0.0);
  const double ss = 1.0 / filterscale;
  for (int x = 0; x < out_size; ++x) {
    const double center = (x + 0.5) * scale;
    int xmin = int(center - support + 0.5);
    if (xmin < 0) xmin = 0;
    int xmax = int(center + support + 0.5);
    if (xmax > in_size) xmax = in_size;
    const int n = std::max(xmax - xmin, 0);
    double* k = &t.weights[size_t(x) * size_t(t.max_taps)];
    double sum = 0.0;
    for (int i = 0; i < n; ++i) {
      k[i] = fn((i + xmin - center + 0.5) * ss);
      sum += k[i];
    }
    if (sum != 0.0)
      for (int i = 0; i < n; ++i) k[i] /= sum;
    t.first[size_t(x)] = xmin;
    t.count[size_t(x)] = n;
  }
  return t;
}

gs::Image resize_lanczos(const gs::Image& src, int out_w, int out_h, ThreadPool& pool) {
  MACRO_CHECK(src.width > 0 && src.height > 0 && src.channels > 0 && out_w > 0 && out_h > 0);
  const int c = src.channels;
  // Horizontal pass (skipped when the width is unchanged, as Pillow does).
  gs::Image mid;
  if (out_w != src.width) {
    const ResampleTaps tx = lanczos_taps(src.width, out_w);
    mid = gs::Image(out_w, src.height, c);
    pool.parallel_for(size_t(src.height), [&](size_t y0, size_t y1, int) {
      for (size_t y = y0; y < y1; ++y) {
        const float* in = &src.data[y * size_t(src.width) * c];
        float* out = &mid.data[y * size_t(out_w) * c];
        for (int x = 0; x < out_w; ++x) {
          const double* k = &tx.weights[size_t(x) * tx.max_taps];
          const float* p = in + size_t(tx.first[size_t(x)]) * c;
          for (int ch = 0; ch < c; ++ch) {
            double s = 0.0;
            for (int i = 0; i < tx.count[size_t(x)]; ++i) s += double(p[size_t(i) * c + ch]) * k[i];
            out[size_t(x) * c + ch] = float(s);
          }
        }
      }
    });
  } else {
    mid = src;
  }
  if (out_h == src.height) return mid;
  const ResampleTaps ty = lanczos_taps(src.height, out_h);
  gs::Image dst(out_w, out_h, c);
  const size_t row = size_t(out_w) * c;
  pool.parallel_for(size_t(out_h), [&](size_t y0, size_t y1, int) {
    std::vector<double> acc(row);
    for (size_t y = y0; y < y1; ++y) {
      std::fill(acc.begin(), acc.end(), 0.0);
      const double* k = &ty.weights[y * ty.max_taps];
      for (int i = 0; i < ty.count[y]; ++i) {
        const float* in = &mid.data[size_t(ty.first[y] + i) * row];
        for (size_t e = 0; e < row; ++e) acc[e] += double(in[e]) * k[i];
      }
      float* out = &dst.data[y * row];
      for (size_t e = 0; e < row; ++e) out[e] = float(acc[e]);
    }
  });
  return dst;
}

std::vector<uint8_t> resize_lanczos_u8(const uint8_t* src, int w, int h, int c, int out_w,
                                       int out_h, ThreadPool& pool) {
  return resize_pillow_u8(src, w, h, c, out_w, out_h, PillowFilter::kLanczos, pool);
}

std::vector<uint8_t> resize_pillow_u8(const uint8_t* src, int w, int h, int c, int out_w,
                                      int out_h, PillowFilter filter, ThreadPool& pool) {
  MACRO_CHECK(src && w > 0 && h > 0 && c > 0 && out_w > 0 && out_h > 0);
  std::vector<uint8_t> mid;
  const uint8_t* hsrc = src;
  if (out_w != w) {
    const ResampleTaps tx = pillow_taps(w, out_w, filter);
    const std::vector<int32_t> k = fixed_weights(tx);
    mid.resize(size_t(out_w) * h * c);
    pool.parallel_for(size_t(h), [&](size_t y0, size_t y1, int) {
      for (size_t y = y0; y < y1; ++y) {
        const uint8_t* in = src + y * size_t(w) * c;
        uint8_t* out = &mid[y * size_t(out_w) * c];
        for (int x = 0; x < out_w; ++x) {
          const int32_t* kx = &k[size_t(x) * tx.max_taps];
          const uint8_t* p = in + size_t(tx.first[size_t(x)]) * c;
          for (int ch = 0; ch < c; ++ch) {
            int64_t s = int64_t(1) << (kPillowPrecisionBits - 1);
            for (int i = 0; i < tx.count[size_t(x)]; ++i)
              s += int64_t(p[size_t(i) * c + ch]) * kx[i];
            out[size_t(x) * c + ch] = clip8(s);
          }
        }
      }
    });
    hsrc = mid.data();
  }
  const size_t row = size_t(out_w) * c;
  if (out_h == h) {
    if (hsrc == src) return std::vector<uint8_t>(src, src + row * h);
    return mid;
  }
  const ResampleTaps ty = pillow_taps(h, out_h, filter);
  const std::vector<int32_t> k = fixed_weights(ty);
  std::vector<uint8_t> dst(row * out_h);
  pool.parallel_for(size_t(out_h), [&](size_t y0, size_t y1, int) {
    std::vector<int64_t> acc(row);
    for (size_t y = y0; y < y1; ++y) {
      std::fill(acc.begin(), acc.end(), int64_t(1) << (kPillowPrecisionBits - 1));
      const int32_t* ky = &k[y * ty.max_taps];
      for (int i = 0; i < ty.count[y]; ++i) {
        const uint8_t* in = hsrc + size_t(ty.first[y] + i) * row;
        for (size_t e = 0; e < row; ++e) acc[e] += int64_t(in[e]) * ky[i];
      }
      for (size_t e = 0; e < row; ++e) dst[y * row + e] = clip8(acc[e]);
    }
  });
  return dst;
}

Result<Size2> model_size(int width, int height, int max_side) {
  if (width < kModelMultiple || height < kModelMultiple)
    return Status::error("model size: image " + std::to_string(width) + "x" +
                         std::to_string(height) + " is smaller than " +
                         std::to_string(kModelMultiple) + " pixels on a side");
  Size2 s{width / kModelMultiple * kModelMultiple, height / kModelMultiple * kModelMultiple};
  const int longer = std::max(s.w, s.h);
  if (longer > max_side) {
    const double f = double(max_side) / double(longer);
    s.w = int(std::lround(s.w * f)) / kModelMultiple * kModelMultiple;
    s.h = int(std::lround(s.h * f)) / kModelMultiple * kModelMultiple;
    if (s.w < kModelMultiple || s.h < kModelMultiple)
      return Status::error("model size: image " + std::to_string(width) + "x" +
                           std::to_string(height) + " is too elongated for a " +
                           std::to_string(max_side) + "-pixel longer side");
  }
  return s;
}

Result<gs::Image> LanczosUpsampler::resize(const gs::Image& src, int out_w, int out_h) const {
  if (src.width <= 0 || src.height <= 0 || src.channels <= 0)
    return Status::error("lanczos: empty input image");
  if (out_w <= 0 || out_h <= 0)
    return Status::error("lanczos: output size " + std::to_string(out_w) + "x" +
                         std::to_string(out_h) + " must be positive");
  return resize_lanczos(src, out_w, out_h);
}

Result<gs::Image> PftSrUpsampler::resize(const gs::Image&, int, int) const {
  MACRO_TRY(ready());
  return Status::error("upsampler pft-sr: unreachable");
}

Status PftSrUpsampler::ready() const {
  return Status::error(
      "upsampler pft-sr: the PFT-SR network is not available in this build and its weights "
      "are not supplied (expected 103_PFT_light_SRx4_finetune.pth and "
      "101_PFT_light_SRx2_scratch.pth, converted to safetensors, under " +
      weights_dir_ + "); use --upsampler lanczos");
}

Result<std::unique_ptr<Upsampler>> make_upsampler(const std::string& name,
                                                  const std::string& weights_dir) {
  if (name == "lanczos") return std::unique_ptr<Upsampler>(new LanczosUpsampler());
  if (name == "pft-sr" || name == "pft")
    return std::unique_ptr<Upsampler>(
        new PftSrUpsampler(weights_dir.empty() ? std::string("data/weights/pft-sr") : weights_dir));
  return Status::error("--upsampler: expected lanczos or pft-sr, found '" + name + "'");
}

}  // namespace macro::enhance
