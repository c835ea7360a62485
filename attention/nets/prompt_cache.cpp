// Cached prompt embeddings of a pipeline folder (see prompt_cache.h).
#include "attention/nets/prompt_cache.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <system_error>
#include <vector>

#include "attention/nets/clip_text.h"
#include "attention/nets/clip_tokenizer.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"

namespace macro::nets {
namespace {

namespace fs = std::filesystem;

constexpr const char* kFormatTag = "macro prompt cache v1";
constexpr const char* kTensorName = "prompt_embedding";

struct Fnv1a {
  uint64_t h = 1469598103934665603ull;
  void bytes(const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    for (size_t i = 0; i < n; ++i) {
      h ^= b[i];
      h *= 1099511628211ull;
    }
  }
  void str(const std::string& s) {
    const uint64_t n = s.size();
    bytes(&n, sizeof n);  // length-prefixed: no two field sequences hash the same bytes
    bytes(s.data(), s.size());
  }
  void u64(uint64_t v) { bytes(&v, sizeof v); }
};

std::string hex16(uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

struct Prepared {
  std::vector<int32_t> ids;
  std::string weights;
  std::string key;
};

Result<Prepared> prepare(const std::string& folder, const std::string& prompt) {
  Prepared p;
  MACRO_ASSIGN_OR_RETURN(ClipTokenizer tok, ClipTokenizer::load(folder + "/tokenizer"));
  p.ids = tok.encode(prompt);
  const std::string te = folder + "/text_encoder";
  MACRO_ASSIGN_OR_RETURN(std::string config, read_text_file(te + "/config.json", 1 << 20));
  MACRO_ASSIGN_OR_RETURN(p.weights, clip_text_weights_path(te));
  std::error_code ec;
  const uint64_t size = fs::file_size(p.weights, ec);
  if (ec) return Status::error(p.weights + ": cannot read the file size: " + ec.message());
  const auto mtime = fs::last_write_time(p.weights, ec);
  if (ec) return Status::error(p.weights + ": cannot read the modification time: " + ec.message());
  Fnv1a h;
  h.str(kFormatTag);
  h.u64(p.ids.size());
  h.bytes(p.ids.data(), p.ids.size() * sizeof(int32_t));
  h.str(config);
  h.str(fs::weakly_canonical(p.weights, ec).string());
  h.u64(size);
  h.u64(uint64_t(mtime.time_since_epoch().count()));
  p.key = hex16(h.h);
  return p;
}

// The cached tensor, if the file exists and checks out.
bool try_read(const std::string& path, const std::string& key, int64_t width, Tensor* out) {
  if (!file_exists(path)) return false;
  auto f = SafeTensors::open(path);
  if (!f.is_ok()) return false;
  const auto it = f->metadata().find("key");
  if (it == f->metadata().end() || it->second != key) return false;
  const TensorEntry* e = f->find(kTensorName);
  if (!e || e->dtype != DType::kF32 ||
      e->shape != std::vector<int64_t>{1, ClipTokenizer::kContextLength, width})
    return false;
  Tensor t = Tensor::f32(e->shape);
  if (!convert_to_f32(*e, t.f32(), size_t(t.numel())).is_ok()) return false;
  for (int64_t i = 0; i < t.numel(); ++i)
    if (!std::isfinite(t.f32()[i])) return false;
  *out = std::move(t);
  return true;
}

Status try_write(const std::string& dir, const std::string& path, const Tensor& t,
                 const std::string& key, const std::string& prompt, const std::string& weights) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !is_directory(dir))
    return Status::error(dir + ": cannot create the cache folder" +
                         (ec ? ": " + ec.message() : std::string()));
  return write_safetensors(path, {{kTensorName, DType::kF32, t.shape(), t.f32()}},
                           {{"key", key}, {"prompt", prompt}, {"weights", weights}});
}

}  // namespace

bool has_text_encoder(const std::string& folder) {
  return file_exists(folder + "/text_encoder/config.json") &&
         clip_text_weights_path(folder + "/text_encoder").is_ok() &&
         file_exists(folder + "/tokenizer/vocab.json") &&
         file_exists(folder + "/tokenizer/merges.txt");
}

std::string prompt_cache_folder(const std::string& folder) {
  return folder + "/text_encoder/prompt_cache";
}

std::string user_prompt_cache_folder() {
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x)
    return std::string(x) + "/macro/prompt_cache";
  if (const char* h = std::getenv("HOME"); h && *h)
    return std::string(h) + "/.cache/macro/prompt_cache";
  return std::string();
}

Result<std::string> prompt_cache_key(const std::string& folder, const std::string& prompt) {
  MACRO_ASSIGN_OR_RETURN(Prepared p, prepare(folder, prompt));
  return p.key;
}

Result<Tensor> prompt_embedding(const std::string& folder, const std::string& prompt,
                                ThreadPool* pool, const PromptCacheOptions& options,
                                PromptCacheInfo* info) {
  PromptCacheInfo local;
  PromptCacheInfo& inf = info ? *info : local;
  inf = PromptCacheInfo();
  if (!has_text_encoder(folder))
    return Status::error(folder +
                         ": expected text_encoder/ (config.json, model.safetensors) and tokenizer/ "
                         "(vocab.json, merges.txt) to compute the prompt embedding");
  MACRO_ASSIGN_OR_RETURN(ClipTextConfig cfg,
                         load_clip_text_config(folder + "/text_encoder/config.json"));
  MACRO_ASSIGN_OR_RETURN(Prepared p, prepare(folder, prompt));
  std::vector<std::string> dirs;
  if (!options.cache_dir.empty()) {
    dirs.push_back(options.cache_dir);
  } else {
    dirs.push_back(prompt_cache_folder(folder));
    if (std::string u = user_prompt_cache_folder(); !u.empty()) dirs.push_back(u);
  }
  const std::string file = p.key + ".safetensors";
  if (options.use_cache) {
    for (const std::string& d : dirs) {
      Tensor t;
      if (try_read(d + "/" + file, p.key, cfg.hidden_size, &t)) {
        inf.hit = true;
        inf.path = d + "/" + file;
        return t;
      }
    }
  }
  MACRO_ASSIGN_OR_RETURN(auto model,
                         ClipTextModel::load(folder + "/text_encoder", Precision::kF32));
  MACRO_ASSIGN_OR_RETURN(Tensor t, model->forward(p.ids, 1, pool, folder + "/text_encoder"));
  if (!options.use_cache) return t;
  for (const std::string& d : dirs) {
    Status s = try_write(d, d + "/" + file, t, p.key, prompt, p.weights);
    if (s.is_ok()) {
      inf.path = d + "/" + file;
      inf.note.clear();
      return t;
    }
    inf.note += (inf.note.empty() ? "" : "; ") + s.message();
  }
  return t;
}

}  // namespace macro::nets
