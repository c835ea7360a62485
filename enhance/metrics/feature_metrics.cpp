// DINOv2 / DreamSim entries of the metric suite (contract in feature_metrics.h).
#include "enhance/metrics/feature_metrics.h"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>

#include "attention/runtime/bundled_data.h"
#include "attention/runtime/file_io.h"
#include "enhance/metrics/dreamsim.h"

namespace macro::enhance {
namespace {

// A path as messages show it: absolute, so "expected at" says where from any working folder.
std::string shown_path(const std::string& path) {
  std::error_code ec;
  const std::filesystem::path a = std::filesystem::absolute(path, ec);
  return ec ? path : a.lexically_normal().string();
}

// The entry for absent weights (callers check file_exists first).
MetricValue not_computed(const char* name, const std::string& path) {
  MetricValue m;
  m.name = name;
  m.computed = false;
  m.reason = std::string("weights not supplied (expected at ") + shown_path(path) + ")";
  return m;
}

}  // namespace

std::string default_dinov2_path() {
  return find_bundled_data(std::string("data/weights/dinov2/") + kDinov2File);
}
std::string default_dreamsim_path() {
  return find_bundled_data(std::string("data/weights/dreamsim/") + kDreamSimFile);
}

// ---- DINOv2 -------------------------------------------------------------------------------------

std::vector<float> resize_bilinear_chw(const gs::Image& image, int oh, int ow) {
  MACRO_CHECK(image.channels == 3 && image.width > 0 && image.height > 0 && oh > 0 && ow > 0);
  // One axis: the lower source index, the upper one (clamped) and the upper weight.
  struct Tap {
    int i0, i1;
    float l1;
  };
  auto taps = [](int in, int out) {
    std::vector<Tap> t(static_cast<size_t>(out));
    const float scale = float(in) / float(out);
    for (int o = 0; o < out; ++o) {
      float src = scale * (float(o) + 0.5f) - 0.5f;
      if (src < 0) src = 0;
      const int i0 = std::min(int(src), in - 1);
      t[size_t(o)] = {i0, i0 < in - 1 ? i0 + 1 : i0, src - float(i0)};
    }
    return t;
  };
  const std::vector<Tap> ty = taps(image.height, oh), tx = taps(image.width, ow);
  std::vector<float> out(size_t(3) * size_t(oh) * size_t(ow));
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < oh; ++y) {
      const Tap& a = ty[size_t(y)];
      const float h1 = a.l1, h0 = 1.0f - a.l1;
      float* dst = out.data() + (size_t(c) * size_t(oh) + size_t(y)) * size_t(ow);
      for (int x = 0; x < ow; ++x) {
        const Tap& b = tx[size_t(x)];
        const float w1 = b.l1, w0 = 1.0f - b.l1;
        // torch's order: the outer (height) weights over inner (width) interpolations.
        dst[x] = h0 * (w0 * image.at(a.i0, b.i0, c) + w1 * image.at(a.i0, b.i1, c)) +
                 h1 * (w0 * image.at(a.i1, b.i0, c) + w1 * image.at(a.i1, b.i1, c));
      }
    }
  return out;
}

std::vector<float> dinov2_input(const gs::Image& image) {
  std::vector<float> x = resize_bilinear_chw(image, kDinov2Size, kDinov2Size);
  const size_t plane = size_t(kDinov2Size) * size_t(kDinov2Size);
  for (size_t c = 0; c < 3; ++c)
    for (size_t i = 0; i < plane; ++i)
      x[c * plane + i] = (x[c * plane + i] - kDinov2Mean[c]) / kDinov2Std[c];
  return x;
}

nets::VitConfig dinov2_config() {
  return nets::VitConfig::dinov2_small();
}

namespace {

struct CachedModel {
  FileStamp stamp;
  std::shared_ptr<const nets::VitModel> model;
};

std::mutex& dinov2_cache_mutex() {
  static std::mutex m;
  return m;
}

// One forward at a time per process: the forwards share the thread pool, which runs one
// parallel_for at a time.
std::mutex& dinov2_forward_mutex() {
  static std::mutex m;
  return m;
}

}  // namespace

Result<std::shared_ptr<const nets::VitModel>> load_dinov2(const std::string& path) {
  const FileStamp stamp = file_stamp(path);
  if (stamp.size < 0)
    return Status::error(path + ": cannot read the DINOv2 weights (no such file)");
  std::lock_guard<std::mutex> lock(dinov2_cache_mutex());
  static std::map<std::string, CachedModel> cache;
  CachedModel& c = cache[path];
  if (c.model && c.stamp == stamp) return c.model;
  c = CachedModel();
  nets::VitLoadOptions opt;
  opt.ignored_prefixes = {"head.", "mask_token"};  // classifier (num_classes=0), torch.hub buffer
  auto model = nets::VitModel::load(path, dinov2_config(), opt);
  if (!model) return model.status().with_context("DINOv2 ViT-S/14");
  c.stamp = stamp;
  c.model = std::shared_ptr<const nets::VitModel>(std::move(*model));
  return c.model;
}

Result<std::vector<float>> dinov2_embedding(const nets::VitModel& model, const gs::Image& image,
                                            ThreadPool* pool) {
  if (image.channels != 3 || image.width < 1 || image.height < 1 ||
      image.data.size() != image.pixels() * 3)
    return Status::error("DINOv2: expected a non-empty RGB image, found " +
                         std::to_string(image.width) + "x" + std::to_string(image.height) + "x" +
                         std::to_string(image.channels));
  const std::vector<float> x = dinov2_input(image);
  std::lock_guard<std::mutex> lock(dinov2_forward_mutex());
  auto out = model.forward(x.data(), kDinov2Size, kDinov2Size, pool ? pool : &ThreadPool::global());
  if (!out) return out.status();
  return std::move(out->cls);
}

namespace {

// Recent embeddings, so that a ground truth scored against several methods is embedded once.
// Keyed by the model (a weak_ptr: an entry of a freed model never matches a new one at the same
// address), the size and two independent 64-bit hashes of the pixel values.
struct EmbeddingEntry {
  std::weak_ptr<const nets::VitModel> model;
  int width = 0, height = 0;
  uint64_t h1 = 0, h2 = 0;
  std::vector<float> embedding;
};
constexpr size_t kEmbeddingCacheEntries = 16;

struct EmbeddingCache {
  std::mutex mutex;
  std::vector<EmbeddingEntry> entries;  // oldest first
  Dinov2CacheStats stats;
};
EmbeddingCache& embedding_cache() {
  static EmbeddingCache c;
  return c;
}

void hash_image(const gs::Image& image, uint64_t* h1, uint64_t* h2) {
  uint64_t a = 0xcbf29ce484222325ull, b = 0x243F6A8885A308D3ull;
  for (float v : image.data) {
    uint32_t w;
    std::memcpy(&w, &v, 4);
    a = (a ^ w) * 0x100000001b3ull;                               // FNV-1a over 32-bit words
    b = (b + w + 0x9E3779B97F4A7C15ull) * 0xBF58476D1CE4E5B9ull;  // multiply-mix
    b ^= b >> 29;
  }
  *h1 = a;
  *h2 = b;
}

Result<std::vector<float>> cached_embedding(const std::shared_ptr<const nets::VitModel>& model,
                                            const gs::Image& image, ThreadPool* pool) {
  uint64_t h1 = 0, h2 = 0;
  hash_image(image, &h1, &h2);
  EmbeddingCache& c = embedding_cache();
  {
    std::lock_guard<std::mutex> lock(c.mutex);
    for (const EmbeddingEntry& e : c.entries)
      if (e.width == image.width && e.height == image.height && e.h1 == h1 && e.h2 == h2 &&
          e.model.lock() == model) {
        ++c.stats.hits;
        return e.embedding;
      }
  }
  MACRO_ASSIGN_OR_RETURN(std::vector<float> emb, dinov2_embedding(*model, image, pool));
  std::lock_guard<std::mutex> lock(c.mutex);
  ++c.stats.computed;
  if (c.entries.size() >= kEmbeddingCacheEntries) c.entries.erase(c.entries.begin());
  c.entries.push_back({model, image.width, image.height, h1, h2, emb});
  return emb;
}

}  // namespace

Dinov2CacheStats dinov2_cache_stats() {
  EmbeddingCache& c = embedding_cache();
  std::lock_guard<std::mutex> lock(c.mutex);
  return c.stats;
}

double cosine_distance(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size() || a.empty()) return std::nan("");
  double ab = 0, aa = 0, bb = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    ab += double(a[i]) * double(b[i]);
    aa += double(a[i]) * double(a[i]);
    bb += double(b[i]) * double(b[i]);
  }
  if (!(aa > 0) || !(bb > 0) || !std::isfinite(aa) || !std::isfinite(bb)) return std::nan("");
  return 1.0 - ab / std::sqrt(aa * bb);
}

MetricValue dinov2_distance(const gs::Image& pred, const gs::Image& gt,
                            const std::string& weights_path, ThreadPool* pool) {
  const std::string path = weights_path.empty() ? default_dinov2_path() : weights_path;
  MetricValue m;
  m.name = "dinov2";
  if (!file_exists(path)) return not_computed("dinov2", path);
  auto fail = [&](const Status& s) {
    m.computed = false;
    m.reason = s.message();
    return m;
  };
  auto model = load_dinov2(path);
  if (!model) return fail(model.status());
  auto ep = cached_embedding(*model, pred, pool);
  if (!ep) return fail(ep.status().with_context("prediction"));
  auto eg = cached_embedding(*model, gt, pool);
  if (!eg) return fail(eg.status().with_context("ground truth"));
  const double d = cosine_distance(*ep, *eg);
  if (!std::isfinite(d))
    return fail(Status::error("DINOv2: an embedding is zero or not finite (" + path + ")"));
  m.computed = true;
  m.value = d;
  return m;
}

MetricValue dreamsim_distance(const gs::Image& pred, const gs::Image& gt,
                              const std::string& weights_path, ThreadPool* pool) {
  const std::string path = weights_path.empty() ? default_dreamsim_path() : weights_path;
  if (!file_exists(path)) return not_computed("dreamsim", path);
  MetricValue m;
  m.name = "dreamsim";
  Result<double> d = dreamsim_distance_value(pred, gt, path, pool);
  if (!d) {
    m.computed = false;
    m.reason = d.status().message();
    return m;
  }
  m.computed = true;
  m.value = *d;
  return m;
}

}  // namespace macro::enhance
