// LPIPS-Alex (contract in lpips.h): weight loading by name, the AlexNet feature stack on conv2d,
// and the per-tap normalised, head-weighted distances.
#include "enhance/metrics/lpips.h"

#include <cmath>
#include <filesystem>

#include "attention/nets/weights.h"
#include "attention/runtime/bundled_data.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/ops.h"
#include "enhance/metrics/metric_value.h"

namespace macro::enhance {
namespace {

// torchvision alexnet().features: index, Cin, Cout, kernel, stride, pad.
struct AlexConvSpec {
  int index, c_in, c_out, k, stride, pad;
};
constexpr std::array<AlexConvSpec, kLpipsTaps> kAlexConvs = {{
    {0, 3, 64, 11, 4, 2},
    {3, 64, 192, 5, 1, 2},
    {6, 192, 384, 3, 1, 1},
    {8, 384, 256, 3, 1, 1},
    {10, 256, 256, 3, 1, 1},
}};

// Max pool 3x3 stride 2, no padding, floor mode: x [NC, H, W] -> y [NC, (H-3)/2+1, (W-3)/2+1].
void max_pool_3s2(const float* x, int64_t nc, int64_t h, int64_t w, float* y, ThreadPool* pool) {
  const int64_t oh = (h - 3) / 2 + 1, ow = (w - 3) / 2 + 1;
  auto body = [&](size_t p0, size_t p1, int) {
    for (size_t p = p0; p < p1; ++p) {
      const float* src = x + int64_t(p) * h * w;
      float* dst = y + int64_t(p) * oh * ow;
      for (int64_t i = 0; i < oh; ++i)
        for (int64_t j = 0; j < ow; ++j) {
          const float* s = src + (2 * i) * w + 2 * j;
          float m = s[0];
          for (int u = 0; u < 3; ++u)
            for (int v = 0; v < 3; ++v) m = std::max(m, s[u * w + v]);
          dst[i * ow + j] = m;
        }
    }
  };
  if (pool)
    pool->parallel_for(size_t(nc), body, 1);
  else
    body(0, size_t(nc), 0);
}

// One tap's distance: f [2, C, HW] (image 0 then 1), head w [C] ->
//   mean_p sum_c w_c (f0_c / (|f0| + eps) - f1_c / (|f1| + eps))^2.
double tap_distance(const float* f, int64_t c, int64_t hw, const float* w, ThreadPool* pool) {
  const float* f0 = f;
  const float* f1 = f + c * hw;
  constexpr int64_t kChunk = 256;
  const int64_t chunks = (hw + kChunk - 1) / kChunk;
  std::vector<double> chunk_sum(size_t(chunks), 0.0);
  auto body = [&](size_t q0, size_t q1, int) {
    double s0[kChunk], s1[kChunk], acc[kChunk];
    for (size_t q = q0; q < q1; ++q) {
      const int64_t p0 = int64_t(q) * kChunk, np = std::min(kChunk, hw - p0);
      for (int64_t i = 0; i < np; ++i) s0[i] = s1[i] = acc[i] = 0;
      for (int64_t ch = 0; ch < c; ++ch) {
        const float* a = f0 + ch * hw + p0;
        const float* b = f1 + ch * hw + p0;
        for (int64_t i = 0; i < np; ++i) {
          s0[i] += double(a[i]) * a[i];
          s1[i] += double(b[i]) * b[i];
        }
      }
      for (int64_t i = 0; i < np; ++i) {
        s0[i] = 1.0 / (std::sqrt(s0[i]) + kLpipsEps);
        s1[i] = 1.0 / (std::sqrt(s1[i]) + kLpipsEps);
      }
      for (int64_t ch = 0; ch < c; ++ch) {
        const float* a = f0 + ch * hw + p0;
        const float* b = f1 + ch * hw + p0;
        const double wc = w[ch];
        for (int64_t i = 0; i < np; ++i) {
          const double d = a[i] * s0[i] - b[i] * s1[i];
          acc[i] += wc * d * d;
        }
      }
      double s = 0;
      for (int64_t i = 0; i < np; ++i) s += acc[i];
      chunk_sum[q] = s;
    }
  };
  if (pool)
    pool->parallel_for(size_t(chunks), body, 1);
  else
    body(0, size_t(chunks), 0);
  double total = 0;
  for (double s : chunk_sum) total += s;
  return total / double(hw);
}

}  // namespace

std::string default_lpips_folder() {
  return find_bundled_data("data/weights/lpips", "MACRO_LPIPS", [](const std::string& cand) {
    return file_exists(cand + "/" + kLpipsHeadsFile);
  });
}

namespace {
// A path as messages show it: absolute, so "expected at" says where from any working folder.
std::string shown_path(const std::string& path) {
  std::error_code ec;
  const std::filesystem::path a = std::filesystem::absolute(path, ec);
  return ec ? path : a.lexically_normal().string();
}

}  // namespace

Result<LpipsAlex> LpipsAlex::load(const std::string& backbone_path, const std::string& heads_path,
                                  Isa isa) {
  const std::string folder =
      backbone_path.empty() || heads_path.empty() ? default_lpips_folder() : std::string();
  const std::string bpath =
      backbone_path.empty() ? folder + "/" + kAlexBackboneFile : backbone_path;
  const std::string hpath = heads_path.empty() ? folder + "/" + kLpipsHeadsFile : heads_path;
  if (!file_exists(bpath))
    return Status::error("LPIPS-Alex backbone not supplied (expected at " + shown_path(bpath) +
                         "; convert torchvision's alexnet weights to safetensors with the names "
                         "features.{0,3,6,8,10}.{weight,bias} and pass --lpips-backbone)");
  if (!file_exists(hpath))
    return Status::error("LPIPS v0.1 alex heads not found (expected at " + shown_path(hpath) + ")");

  LpipsAlex net;
  net.backbone_path_ = bpath;
  {
    nets::WeightStoreOptions opt;
    // A whole torchvision alexnet state_dict also holds the classifier; LPIPS does not use it.
    for (const char* n : {"classifier.1.weight", "classifier.1.bias", "classifier.4.weight",
                          "classifier.4.bias", "classifier.6.weight", "classifier.6.bias"})
      opt.ignored.insert(n);
    MACRO_ASSIGN_OR_RETURN(std::unique_ptr<nets::WeightStore> store,
                           nets::WeightStore::open(bpath, opt));
    std::array<nets::Param, kLpipsTaps> w, b;
    for (int k = 0; k < kLpipsTaps; ++k) {
      const AlexConvSpec& sp = kAlexConvs[size_t(k)];
      const std::string prefix = "features." + std::to_string(sp.index);
      store->param(prefix + ".weight", w[size_t(k)], {sp.c_out, sp.c_in, sp.k, sp.k});
      store->param(prefix + ".bias", b[size_t(k)], {sp.c_out});
    }
    MACRO_TRY(store->finish().with_context("LPIPS-Alex backbone"));
    for (int k = 0; k < kLpipsTaps; ++k) {
      const AlexConvSpec& sp = kAlexConvs[size_t(k)];
      Conv& c = net.convs_[size_t(k)];
      c.c_in = sp.c_in, c.c_out = sp.c_out, c.k = sp.k, c.stride = sp.stride, c.pad = sp.pad;
      c.weight.assign(w[size_t(k)].data, w[size_t(k)].data + w[size_t(k)].numel());
      c.bias.assign(b[size_t(k)].data, b[size_t(k)].data + b[size_t(k)].numel());
      c.packed = ConvWeights::pack(c.weight.data(), c.bias.data(), c.c_out, c.c_in, c.k, c.k,
                                   WeightType::kF32, isa);
    }
  }
  {
    MACRO_ASSIGN_OR_RETURN(std::unique_ptr<nets::WeightStore> store,
                           nets::WeightStore::open(hpath));
    std::array<nets::Param, kLpipsTaps> h;
    for (int k = 0; k < kLpipsTaps; ++k)
      store->param("lin" + std::to_string(k) + ".model.1.weight", h[size_t(k)],
                   {1, kAlexTapChannels[size_t(k)], 1, 1});
    MACRO_TRY(store->finish().with_context("LPIPS heads"));
    for (int k = 0; k < kLpipsTaps; ++k)
      net.heads_[size_t(k)].assign(h[size_t(k)].data, h[size_t(k)].data + h[size_t(k)].numel());
  }
  return net;
}

Result<LpipsResult> LpipsAlex::distance(const gs::Image& pred, const gs::Image& gt,
                                        ThreadPool& pool) const {
  return run(pred, gt, &pool, false);
}

Result<LpipsResult> LpipsAlex::distance_reference(const gs::Image& pred,
                                                  const gs::Image& gt) const {
  return run(pred, gt, nullptr, true);
}

Result<LpipsResult> LpipsAlex::run(const gs::Image& a, const gs::Image& b, ThreadPool* pool,
                                   bool reference) const {
  MACRO_TRY(check_pair(a, b).with_context("lpips"));
  if (a.channels != 3)
    return Status::error("lpips: expected RGB images (3 channels), found " +
                         std::to_string(a.channels));
  if (a.width < kLpipsMinSide || a.height < kLpipsMinSide)
    return Status::error("lpips: images must be at least " + std::to_string(kLpipsMinSide) + "x" +
                         std::to_string(kLpipsMinSide) + ", found " + std::to_string(a.width) +
                         "x" + std::to_string(a.height));
  const int64_t N = 2, H = a.height, W = a.width, HW = H * W;

  // Input [2, 3, H, W]: 2x - 1, then the ScalingLayer, in float as torch does.
  std::vector<float> x(size_t(N * 3 * HW));
  for (int64_t n = 0; n < N; ++n) {
    const gs::Image& im = n == 0 ? a : b;
    for (int64_t c = 0; c < 3; ++c) {
      float* dst = x.data() + (n * 3 + c) * HW;
      const float sh = kLpipsShift[size_t(c)], sc = kLpipsScale[size_t(c)];
      for (int64_t p = 0; p < HW; ++p)
        dst[p] = ((im.data[size_t(p * 3 + c)] * 2.0f - 1.0f) - sh) / sc;
    }
  }

  LpipsResult result;
  std::vector<float> cur = std::move(x), next;
  int64_t c_cur = 3, h = H, w = W;
  for (int k = 0; k < kLpipsTaps; ++k) {
    if (k == 1 || k == 2) {  // maxpool 3/2 before conv2 and conv3
      const int64_t oh = (h - 3) / 2 + 1, ow = (w - 3) / 2 + 1;
      next.assign(size_t(N * c_cur * oh * ow), 0.f);
      max_pool_3s2(cur.data(), N * c_cur, h, w, next.data(), pool);
      cur.swap(next);
      h = oh, w = ow;
    }
    const Conv& cv = convs_[size_t(k)];
    const Conv2dShape s = Conv2dShape::make(N, cv.c_in, h, w, cv.c_out, cv.k, cv.stride, cv.pad);
    const int64_t oh = s.out_h(), ow = s.out_w();
    MACRO_CHECK(c_cur == cv.c_in && oh >= 1 && ow >= 1);
    next.assign(size_t(N * cv.c_out * oh * ow), 0.f);  // [2, Cout, OH, OW]
    if (reference) {
      conv2d_reference(s, cur.data(), cv.weight.data(), cv.bias.data(), nullptr, next.data());
      activation(next.data(), next.data(), int64_t(next.size()), Act::kRelu, pool);
    } else {
      conv2d(s, cur.data(), cv.packed, nullptr, next.data(), ConvAct::kRelu, pool);  // fused ReLU
    }
    cur.swap(next);
    c_cur = cv.c_out, h = oh, w = ow;
    result.per_layer[size_t(k)] =
        tap_distance(cur.data(), c_cur, h * w, heads_[size_t(k)].data(), pool);
    result.value += result.per_layer[size_t(k)];
  }
  return result;
}

}  // namespace macro::enhance
