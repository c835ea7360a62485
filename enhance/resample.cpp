// Pillow-exact Lanczos, model size, upsamplers (see resample.h).
#include "enhance/resample.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include "attention/nets/pft.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/progress.h"

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

std::vector<uint8_t> resize_pillow_u8(const uint8_t* src, int w, int h, int c, int out_w, int out_h,
                                      PillowFilter filter, ThreadPool& pool) {
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

// ---- PFT-SR ------------------------------------------------------------------------------------

std::vector<int> pft_pass_scales(int w, int h, int target_w, int target_h) {
  std::vector<int> scales;
  while (w < target_w || h < target_h) {
    if (std::max(w, h) > kPftMaxSrSide) break;
    const int s = (h <= kPftMaxSideForX4 && w <= kPftMaxSideForX4) ? 4 : 2;
    scales.push_back(s);
    w *= s, h *= s;
  }
  return scales;
}

Result<gs::Image> pft_upsample(const gs::Image& src, int out_w, int out_h, const SrPass& pass,
                               gs::Image* before_lanczos) {
  if (src.width <= 0 || src.height <= 0 || src.channels != 3)
    return Status::error("pft-sr: expected a non-empty RGB image, found " +
                         std::to_string(src.width) + "x" + std::to_string(src.height) + "x" +
                         std::to_string(src.channels));
  if (out_w <= 0 || out_h <= 0)
    return Status::error("pft-sr: output size " + std::to_string(out_w) + "x" +
                         std::to_string(out_h) + " must be positive");
  // valid = RGB sum > 0 at the canvas resolution.
  const int w0 = src.width, h0 = src.height;
  std::vector<uint8_t> valid(src.pixels());
  for (size_t p = 0; p < valid.size(); ++p)
    valid[p] = src.data[p * 3] + src.data[p * 3 + 1] + src.data[p * 3 + 2] > 0.f;
  gs::Image img = src;
  for (int s : pft_pass_scales(w0, h0, out_w, out_h)) {
    MACRO_ASSIGN_OR_RETURN(gs::Image up, pass(img, s));
    if (up.width != img.width * s || up.height != img.height * s || up.channels != 3)
      return Status::error("pft-sr: a x" + std::to_string(s) + " pass of " +
                           std::to_string(img.width) + "x" + std::to_string(img.height) +
                           " returned " + std::to_string(up.width) + "x" +
                           std::to_string(up.height));
    for (float& v : up.data) v = std::clamp(v, 0.f, 1.f);  // NaN stays NaN: handled below
    img = std::move(up);
  }
  // Mask (nearest from the canvas: every pass is an integer factor), then to_pil_image's
  // float -> uint8: x * 255 in float, truncated.
  const int w = img.width, h = img.height;
  std::vector<uint8_t> u8(size_t(w) * h * 3);
  for (int y = 0; y < h; ++y) {
    const int sy = nearest_index(y, h0, h);
    for (int x = 0; x < w; ++x) {
      const bool keep = valid[size_t(sy) * w0 + nearest_index(x, w0, w)] != 0;
      for (int c = 0; c < 3; ++c) {
        const float v = keep ? img.data[(size_t(y) * w + x) * 3 + c] : 0.f;
        const float b = v * 255.f;
        u8[(size_t(y) * w + x) * 3 + c] = b >= 0.f && b <= 255.f ? uint8_t(b) : uint8_t(0);
      }
    }
  }
  if (before_lanczos) {
    *before_lanczos = gs::Image(w, h, 3);
    for (size_t i = 0; i < u8.size(); ++i) before_lanczos->data[i] = float(u8[i]) / 255.f;
  }
  const std::vector<uint8_t> res = resize_lanczos_u8(u8.data(), w, h, 3, out_w, out_h);
  gs::Image out(out_w, out_h, 3);
  for (size_t i = 0; i < res.size(); ++i) out.data[i] = float(res[i]) / 255.f;
  return out;
}

struct PftSrUpsampler::Models {
  std::unique_ptr<nets::PftNet> x4, x2;
};

PftSrUpsampler::PftSrUpsampler(std::string weights_dir) : weights_dir_(std::move(weights_dir)) {}
PftSrUpsampler::~PftSrUpsampler() = default;

std::string PftSrUpsampler::weights_file(const char* stem) const {
  const std::string base = weights_dir_ + "/" + stem;
  std::error_code ec;
  for (const char* ext : {".safetensors", ".pth"})
    if (std::filesystem::is_regular_file(base + ext, ec)) return base + ext;
  return "";
}

Result<std::shared_ptr<const PftSrUpsampler::Models>> PftSrUpsampler::models() const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (models_) return models_;
  std::vector<std::string> missing;
  const char* stems[2] = {kPftX4Stem, kPftX2Stem};
  std::string files[2];
  for (int i = 0; i < 2; ++i) {
    files[i] = weights_file(stems[i]);
    if (files[i].empty()) missing.push_back(std::string(stems[i]) + ".pth (or .safetensors)");
  }
  if (!missing.empty()) {
    std::string list;
    for (size_t i = 0; i < missing.size(); ++i) list += (i ? " and " : "") + missing[i];
    std::error_code ec;  // the folder as an absolute path, so the message says where
    const std::filesystem::path dir = std::filesystem::absolute(weights_dir_, ec);
    return Status::error("upsampler pft-sr: weights not available: " + list + " not found in " +
                         (ec ? weights_dir_ : dir.lexically_normal().string()) +
                         " (the released PFT-SR light weights, read from params_ema; a "
                         ".safetensors with the same tensor names also works; see docs/pft.md); "
                         "or use --upsampler lanczos");
  }
  auto m = std::make_shared<Models>();
  const int scales[2] = {4, 2};
  for (int i = 0; i < 2; ++i) {
    const bool torch = files[i].size() > 4 && files[i].compare(files[i].size() - 4, 4, ".pth") == 0;
    MACRO_ASSIGN_OR_RETURN(SafeTensors st, torch ? SafeTensors::open_torch(files[i], "params_ema")
                                                 : SafeTensors::open(files[i]));
    MACRO_ASSIGN_OR_RETURN(std::unique_ptr<nets::PftNet> net,
                           nets::PftNet::load(st, nets::PftConfig::light(scales[i])));
    (i == 0 ? m->x4 : m->x2) = std::move(net);
  }
  models_ = m;
  return models_;
}

Status PftSrUpsampler::ready() const {
  return models().status();
}

Result<gs::Image> PftSrUpsampler::resize(const gs::Image& src, int out_w, int out_h) const {
  MACRO_ASSIGN_OR_RETURN(std::shared_ptr<const Models> m, models());
  const SrPass pass = [&](const gs::Image& in, int scale) -> Result<gs::Image> {
    const nets::PftNet& net = scale == 4 ? *m->x4 : *m->x2;
    const auto t0 = std::chrono::steady_clock::now();
    std::unique_ptr<Progress> progress;
    const std::string stage = "pft-sr x" + std::to_string(scale) + " " + std::to_string(in.width) +
                              "x" + std::to_string(in.height);
    auto on_layer = [&](int done, int total) {
      if (!progress && ms_since(t0) > 1000.0) progress = std::make_unique<Progress>(stage, total);
      if (progress) progress->set(size_t(done));
    };
    MACRO_ASSIGN_OR_RETURN(std::vector<float> y, net.forward(in.data.data(), in.height, in.width,
                                                             &ThreadPool::global(), on_layer));
    gs::Image out(in.width * scale, in.height * scale, 3);
    out.data = std::move(y);
    return out;
  };
  return pft_upsample(src, out_w, out_h, pass);
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
