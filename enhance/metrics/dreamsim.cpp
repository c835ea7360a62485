// DreamSim ensemble distance (contract and sources in dreamsim.h, docs/dreamsim.md).
#include "enhance/metrics/dreamsim.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>

#include "attention/nets/weights.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "enhance/metrics/feature_metrics.h"
#include "enhance/metrics/metric_value.h"
#include "enhance/resample.h"

namespace macro::enhance {
namespace {

constexpr double kCosineEps = 1e-8;  // torch F.cosine_similarity default

// The file's names for this engine's: CLIP's ln_pre is `pos_drop` in DreamSim's converted towers.
class DreamSimNames final : public nets::ParamVisitor {
 public:
  explicit DreamSimNames(nets::ParamVisitor& inner) : inner_(inner) {}
  void param(const std::string& name, nets::Param& p, const std::vector<int64_t>& shape) override {
    static const std::string kFrom = ".norm_pre.", kTo = ".pos_drop.";
    const size_t at = name.find(kFrom);
    if (at == std::string::npos) return inner_.param(name, p, shape);
    inner_.param(name.substr(0, at) + kTo + name.substr(at + kFrom.size()), p, shape);
  }

 private:
  nets::ParamVisitor& inner_;
};

nets::VitConfig vit_b16(const std::string& prefix) {
  nets::VitConfig c;
  c.prefix = prefix + ".";
  c.width = 768;
  c.depth = 12;
  c.heads = 12;
  c.mlp_hidden = 3072;
  c.patch = 16;
  c.grid_h = c.grid_w = kDreamSimImageSize / 16;
  c.layer_scale = false;
  c.qkv_bias = true;
  c.patch_bias = true;  // vit_base's conv has a bias; the converted CLIP towers store it
  c.pos_resample = nets::PosEmbedResample::kRefuse;
  return c;
}

// Scale of unmerged PEFT LoRA in the file: lora_alpha (metadata) / r (lora_A rows). 0 if none.
Result<double> lora_scale_of(const SafeTensors& file) {
  int64_t r = 0;
  std::string first;
  for (const std::string& name : file.names()) {
    if (name.find(".lora_A.") == std::string::npos) continue;
    const TensorEntry* e = file.find(name);
    if (e->shape.size() != 2 || e->shape[0] < 1)
      return Status::error(file.path() + ": tensor '" + name + "': expected lora_A [r, in], found " +
                           nets::shape_string(e->shape));
    if (r == 0) {
      r = e->shape[0];
      first = name;
    } else if (e->shape[0] != r) {
      return Status::error(file.path() + ": tensor '" + name + "': LoRA rank " +
                           std::to_string(e->shape[0]) + " differs from the rank " +
                           std::to_string(r) + " of '" + first + "'");
    }
  }
  if (r == 0) return 0.0;
  const auto& meta = file.metadata();
  auto it = meta.find("lora_alpha");
  if (it == meta.end())
    return Status::error(file.path() + ": unmerged LoRA ('" + first +
                         "') needs the header metadata \"lora_alpha\" (adapter_config.json's "
                         "lora_alpha), found none; or merge the LoRA before saving");
  char* end = nullptr;
  const double alpha = std::strtod(it->second.c_str(), &end);
  if (end == it->second.c_str() || *end != '\0' || !std::isfinite(alpha) || alpha <= 0)
    return Status::error(file.path() + ": metadata \"lora_alpha\": expected a positive number, "
                         "found \"" + it->second + "\"");
  auto rit = meta.find("lora_r");
  if (rit != meta.end() && rit->second != std::to_string(r))
    return Status::error(file.path() + ": metadata \"lora_r\": \"" + rit->second +
                         "\" differs from the lora_A rows " + std::to_string(r));
  return alpha / double(r);
}

}  // namespace

// ---- config -------------------------------------------------------------------------------------

DreamSimConfig DreamSimConfig::ensemble() {
  DreamSimConfig cfg;
  DreamSimBackbone dino{"dino", vit_b16("dino"), kImagenetMean, kImagenetStd};
  dino.vit.ln_eps = 1e-6f;
  dino.vit.act = nets::VitAct::kGelu;
  dino.vit.final_norm = false;  // 'cls' = the last block's output, before `norm`
  DreamSimBackbone clip{"clip", vit_b16("clip"), kOpenAiClipMean, kOpenAiClipStd};
  clip.vit.ln_eps = 1e-5f;
  clip.vit.act = nets::VitAct::kQuickGelu;
  clip.vit.norm_pre = true;
  clip.vit.final_norm = true;
  clip.vit.proj_dim = 512;
  DreamSimBackbone open_clip{"open_clip", vit_b16("open_clip"), kOpenAiClipMean, kOpenAiClipStd};
  open_clip.vit.ln_eps = 1e-5f;
  open_clip.vit.act = nets::VitAct::kGelu;
  open_clip.vit.norm_pre = true;
  open_clip.vit.final_norm = true;
  open_clip.vit.proj_dim = 512;
  cfg.backbones = {dino, clip, open_clip};
  return cfg;
}

int64_t DreamSimConfig::embed_dim() const {
  int64_t e = 0;
  for (const DreamSimBackbone& b : backbones) e += b.vit.out_dim();
  return e;
}

std::vector<DreamSimTensorSpec> dreamsim_tensor_specs(const DreamSimConfig& cfg) {
  // The names the networks ask for, in the file's spelling.
  struct Lister final : nets::ParamVisitor {
    std::vector<DreamSimTensorSpec> out;
    void param(const std::string& name, nets::Param&, const std::vector<int64_t>& shape) override {
      out.push_back({name, shape});
    }
  } lister;
  DreamSimNames names(lister);
  for (const DreamSimBackbone& b : cfg.backbones) {
    auto m = nets::VitModel::build(b.vit);
    MACRO_CHECK(m.is_ok());
    (*m)->visit(names);
  }
  return lister.out;
}

// ---- preprocessing --------------------------------------------------------------------------------

std::vector<uint8_t> resize_bicubic_u8(const uint8_t* src, int w, int h, int c, int out_w,
                                       int out_h, ThreadPool* pool) {
  return resize_pillow_u8(src, w, h, c, out_w, out_h, PillowFilter::kBicubic,
                          pool ? *pool : ThreadPool::global());
}

std::vector<uint8_t> quantize_u8(const gs::Image& image) {
  std::vector<uint8_t> out(image.data.size());
  for (size_t i = 0; i < out.size(); ++i) {
    const float v = image.data[i];
    const float s = std::floor(std::clamp(v, 0.0f, 1.0f) * 255.0f + 0.5f);
    out[i] = static_cast<uint8_t>(std::isfinite(s) ? s : 0.0f);
  }
  return out;
}

Result<std::vector<float>> dreamsim_preprocess(const gs::Image& image, int side,
                                               ThreadPool* pool) {
  MACRO_TRY(check_image(image, "image"));
  if (image.channels != 3)
    return Status::error("DreamSim: image: expected 3 channels (RGB), found " +
                         std::to_string(image.channels));
  if (side < 1) return Status::error("DreamSim: side: expected >= 1, found " + std::to_string(side));
  const std::vector<uint8_t> u8 = quantize_u8(image);
  const std::vector<uint8_t> r =
      resize_bicubic_u8(u8.data(), image.width, image.height, 3, side, side, pool);
  const size_t hw = size_t(side) * size_t(side);
  std::vector<float> chw(3 * hw);
  for (size_t i = 0; i < hw; ++i)
    for (size_t c = 0; c < 3; ++c) chw[c * hw + i] = float(r[i * 3 + c]) / 255.0f;  // ToTensor
  return chw;
}

void dreamsim_normalize_embedding(std::vector<float>& e) {
  if (e.empty()) return;
  double mean = 0.0;
  for (float v : e) mean += v;
  mean /= double(e.size());
  double sq = 0.0;
  for (float v : e) sq += (v - mean) * (v - mean);
  const double inv = sq > 0 ? 1.0 / std::sqrt(sq) : 0.0;
  for (float& v : e) v = float((v - mean) * inv);
}

double dreamsim_embedding_distance(const std::vector<float>& a, const std::vector<float>& b) {
  MACRO_CHECK(a.size() == b.size());
  double ab = 0.0, aa = 0.0, bb = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    ab += double(a[i]) * b[i];
    aa += double(a[i]) * a[i];
    bb += double(b[i]) * b[i];
  }
  const double na = std::max(std::sqrt(aa), kCosineEps), nb = std::max(std::sqrt(bb), kCosineEps);
  return 1.0 - ab / (na * nb);
}

// ---- the model ------------------------------------------------------------------------------------

Result<std::unique_ptr<DreamSimModel>> DreamSimModel::load(const std::string& path,
                                                           const DreamSimConfig& cfg) {
  if (cfg.backbones.empty()) return Status::error("DreamSim config: expected backbones, found none");
  if (cfg.image_size < 1)
    return Status::error("DreamSim config: image_size: expected >= 1, found " +
                         std::to_string(cfg.image_size));
  if (!file_exists(path))
    return Status::error("DreamSim weights not found at " + path +
                         " (docs/dreamsim.md says how to write them from dreamsim(pretrained=True))");
  double scale = 0.0;
  nets::WeightStoreOptions opt;
  opt.lazy = true;
  {
    MACRO_ASSIGN_OR_RETURN(SafeTensors file, SafeTensors::open(path));
    MACRO_ASSIGN_OR_RETURN(scale, lora_scale_of(file));
    // DINO's final `norm` is in its state dict but not used by the 'cls' feature.
    for (const DreamSimBackbone& b : cfg.backbones)
      if (!b.vit.final_norm)
        for (const char* leaf : {"norm.weight", "norm.bias"})
          if (file.contains(b.vit.prefix + leaf)) opt.ignored.insert(b.vit.prefix + leaf);
  }
  opt.lora_scale = scale;
  MACRO_ASSIGN_OR_RETURN(auto store, nets::WeightStore::open(path, opt));
  auto model = std::unique_ptr<DreamSimModel>(new DreamSimModel());
  model->cfg_ = cfg;
  model->path_ = path;
  DreamSimNames names(*store);
  for (const DreamSimBackbone& b : cfg.backbones) {
    if (b.vit.grid_h * b.vit.patch != cfg.image_size || b.vit.grid_w * b.vit.patch != cfg.image_size)
      return Status::error("DreamSim config: backbone " + b.name + ": pos_embed grid " +
                           std::to_string(b.vit.grid_h) + "x" + std::to_string(b.vit.grid_w) +
                           " of patch " + std::to_string(b.vit.patch) + " does not cover " +
                           std::to_string(cfg.image_size) + " pixels");
    MACRO_ASSIGN_OR_RETURN(auto net, nets::VitModel::build(b.vit));
    net->visit(names);
    model->nets_.push_back(std::move(net));
  }
  MACRO_TRY(store->finish().with_context("DreamSim weights"));
  for (auto& net : model->nets_) net->pack(nets::Precision::kF32);
  model->lora_merged_ = store->lora_merged();
  model->arenas_.resize(model->nets_.size());
  return model;
}

size_t DreamSimModel::weight_bytes() const {
  size_t n = 0;
  for (const auto& net : nets_) n += net->weight_bytes();
  return n;
}

Result<std::vector<std::vector<float>>> DreamSimModel::features(const std::vector<float>& pixels,
                                                                ThreadPool& pool) const {
  const int64_t s = cfg_.image_size;
  const size_t hw = size_t(s) * size_t(s);
  if (pixels.size() != 3 * hw)
    return Status::error("DreamSim: input: expected [3, " + std::to_string(s) + ", " +
                         std::to_string(s) + "] = " + std::to_string(3 * hw) + " values, found " +
                         std::to_string(pixels.size()));
  std::lock_guard<std::mutex> lock(mutex_);
  return features_locked(pixels, pool);
}

Result<std::vector<std::vector<float>>> DreamSimModel::features_locked(
    const std::vector<float>& pixels, ThreadPool& pool) const {
  const int64_t s = cfg_.image_size;
  const size_t hw = size_t(s) * size_t(s);
  std::vector<std::vector<float>> out;
  std::vector<float> x(3 * hw);
  for (size_t i = 0; i < nets_.size(); ++i) {
    const DreamSimBackbone& b = cfg_.backbones[i];
    for (size_t c = 0; c < 3; ++c)  // torchvision Normalize: (x - mean) / std in fp32
      for (size_t j = 0; j < hw; ++j) x[c * hw + j] = (pixels[c * hw + j] - b.mean[c]) / b.std[c];
    MACRO_ASSIGN_OR_RETURN(nets::VitModel::Output o,
                           nets_[i]->forward(x.data(), s, s, &pool, false, &arenas_[i]));
    out.push_back(std::move(o.cls));
  }
  return out;
}

Result<std::vector<float>> DreamSimModel::embed(const gs::Image& image, ThreadPool& pool) const {
  // One call at a time: the pool runs one parallel_for at a time, and the arenas are shared.
  std::lock_guard<std::mutex> lock(mutex_);
  MACRO_ASSIGN_OR_RETURN(std::vector<float> pixels,
                         dreamsim_preprocess(image, cfg_.image_size, &pool));
  MACRO_ASSIGN_OR_RETURN(auto feats, features_locked(pixels, pool));
  std::vector<float> e;
  e.reserve(size_t(cfg_.embed_dim()));
  for (const auto& f : feats) e.insert(e.end(), f.begin(), f.end());
  dreamsim_normalize_embedding(e);
  return e;
}

Result<double> DreamSimModel::distance(const gs::Image& pred, const gs::Image& gt,
                                       ThreadPool& pool) const {
  MACRO_TRY(check_pair(pred, gt));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> a, embed(pred, pool));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> b, embed(gt, pool));
  return dreamsim_embedding_distance(a, b);
}

namespace {
std::mutex g_cache_mutex;
std::shared_ptr<const DreamSimModel> g_cached;  // under g_cache_mutex
FileStamp g_cached_stamp;                       // of the file g_cached was loaded from
}  // namespace

Result<std::shared_ptr<const DreamSimModel>> dreamsim_cached_model(const std::string& weights_path) {
  const std::string path = weights_path.empty() ? default_dreamsim_path() : weights_path;
  std::lock_guard<std::mutex> lock(g_cache_mutex);
  const FileStamp stamp = file_stamp(path);
  // A replaced file (another size or modification time) is loaded again; a file removed after
  // loading keeps answering from the cached model.
  const bool replaced = stamp.size >= 0 && !(stamp == g_cached_stamp);
  if (!g_cached || g_cached->path() != path || replaced) {
    g_cached.reset();  // release the old model's memory before loading the new one
    g_cached_stamp = FileStamp();
    MACRO_ASSIGN_OR_RETURN(auto loaded, DreamSimModel::load(path));
    g_cached = std::move(loaded);
    g_cached_stamp = stamp;
  }
  return g_cached;
}

void dreamsim_release_cached_model() {
  std::lock_guard<std::mutex> lock(g_cache_mutex);
  g_cached.reset();
}

Result<double> dreamsim_distance_value(const gs::Image& pred, const gs::Image& gt,
                                       const std::string& weights_path, ThreadPool* pool) {
  MACRO_TRY(check_pair(pred, gt));
  MACRO_ASSIGN_OR_RETURN(std::shared_ptr<const DreamSimModel> model,
                         dreamsim_cached_model(weights_path));
  return model->distance(pred, gt, pool ? *pool : ThreadPool::global());
}

}  // namespace macro::enhance
