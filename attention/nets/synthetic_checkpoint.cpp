#include "attention/nets/synthetic_checkpoint.h"

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

#include "attention/runtime/file_io.h"
#include "attention/runtime/half.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/thread_pool.h"

namespace macro::nets {
namespace {

using json = nlohmann::json;

uint64_t splitmix64(uint64_t& s) {
  uint64_t z = (s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
uint64_t hash_name(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}
bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

enum class Init { kNormWeight, kBias, kLoraB, kWeight };

Init init_for(const std::string& name, const std::vector<int64_t>& shape) {
  if (name.find("lora_B") != std::string::npos) return Init::kLoraB;
  if (ends_with(name, ".bias")) return Init::kBias;
  if (shape.size() == 1) return Init::kNormWeight;  // GroupNorm / LayerNorm affine weights
  return Init::kWeight;
}

// Fills n values of one tensor starting at element `first`, a multiple of kChunk: each chunk has its
// own generator seeded from (seed, name, chunk index), so values do not depend on write order or
// threads.
constexpr int64_t kChunk = 1 << 16;

void fill(const std::string& name, const std::vector<int64_t>& shape, uint64_t seed, int64_t first,
          int64_t n, float* out) {
  Init init = init_for(name, shape);
  int64_t fan_in = 1;
  for (size_t i = 1; i < shape.size(); ++i) fan_in *= shape[i];
  const double w_scale = 1.0 / std::sqrt(double(std::max<int64_t>(1, fan_in)));
  uint64_t s = seed ^ hash_name(name) ^ (uint64_t(first / kChunk) * 0xD1B54A32D192ED03ull);
  for (int64_t i = 0; i < n; i += 2) {
    uint64_t r1 = splitmix64(s), r2 = splitmix64(s);
    double u1 = (double(r1 >> 11) + 0.5) * 0x1.0p-53, u2 = double(r2 >> 11) * 0x1.0p-53;
    double rad = std::sqrt(-2.0 * std::log(u1));
    double pair[2] = {rad * std::cos(2.0 * M_PI * u2), rad * std::sin(2.0 * M_PI * u2)};
    double unif[2] = {u1 * 2.0 - 1.0, u2 * 2.0 - 1.0};
    for (int k = 0; k < 2 && i + k < n; ++k) {
      double v = 0;
      switch (init) {
        case Init::kNormWeight: v = 1.0 + 0.05 * unif[k]; break;
        case Init::kBias: v = 0.02 * unif[k]; break;
        case Init::kLoraB: v = 0.01 * pair[k]; break;
        case Init::kWeight: v = pair[k] * w_scale; break;
      }
      out[i + k] = float(v);
    }
  }
}

struct Manifest {
  json config;
  std::vector<std::pair<std::string, std::vector<int64_t>>> tensors;
  json lora_targets;
};

Result<Manifest> read_manifest(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 64 << 20));
  json j = json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object() || !j.contains("tensors") || !j["tensors"].is_object() ||
      !j.contains("config") || !j["config"].is_object())
    return Status::error(path + ": expected a manifest {config, tensors: {name: {dtype, shape}}}");
  Manifest m;
  m.config = j["config"];
  if (j.contains("lora_targets")) m.lora_targets = j["lora_targets"];
  for (auto it = j["tensors"].begin(); it != j["tensors"].end(); ++it) {
    const json& t = it.value();
    if (!t.contains("shape") || !t["shape"].is_array())
      return Status::error(path + ": tensor '" + it.key() + "': expected a shape list");
    std::vector<int64_t> shape;
    for (const auto& d : t["shape"]) {
      if (!d.is_number_integer() || d.get<int64_t>() < 0 || d.get<int64_t>() > (int64_t(1) << 32))
        return Status::error(path + ": tensor '" + it.key() + "': bad dimension " + d.dump());
      shape.push_back(d.get<int64_t>());
    }
    if (t.contains("dtype") && t["dtype"] != "F32")
      return Status::error(path + ": tensor '" + it.key() + "': expected dtype F32, found " +
                           t["dtype"].dump());
    m.tensors.emplace_back(it.key(), std::move(shape));
  }
  return m;
}

Status write_tensors(const std::string& path, const Manifest& m, const SyntheticCheckpointOptions& o) {
  const size_t elem = o.bf16 ? 2 : 4;
  json header = json::object();
  uint64_t offset = 0, total = 0;
  for (const auto& [name, shape] : m.tensors) {
    int64_t n = 1;
    for (int64_t d : shape) n *= d;
    uint64_t bytes = uint64_t(n) * elem;
    header[name] = {{"dtype", o.bf16 ? "BF16" : "F32"}, {"shape", shape},
                    {"data_offsets", {offset, offset + bytes}}};
    offset += bytes;
    total += uint64_t(n);
  }
  header["__metadata__"] = {{"format", "pt"}, {"note", "synthetic weights (seed " +
                                                        std::to_string(o.seed) + "), not a trained network"}};
  std::string h = header.dump();
  while (h.size() % 8) h += ' ';
  AtomicFile f;
  MACRO_TRY(f.open(path));
  uint64_t hlen = h.size();
  uint8_t len_bytes[8];
  for (int i = 0; i < 8; ++i) len_bytes[i] = uint8_t(hlen >> (8 * i));
  MACRO_TRY(f.write(len_bytes, 8));
  MACRO_TRY(f.write(h));
  Progress progress("synthetic weights", size_t(total));
  // Generate a block of chunks in parallel, then write it in order.
  constexpr int64_t kBlockChunks = 64;
  std::vector<float> buf(size_t(kChunk * kBlockChunks));
  std::vector<uint16_t> half(o.bf16 ? buf.size() : 0);
  ThreadPool& pool = ThreadPool::global();
  for (const auto& [name, shape] : m.tensors) {
    int64_t n = 1;
    for (int64_t d : shape) n *= d;
    for (int64_t first = 0; first < n; first += kChunk * kBlockChunks) {
      const int64_t count = std::min(kChunk * kBlockChunks, n - first);
      const int64_t chunks = (count + kChunk - 1) / kChunk;
      pool.parallel_for(size_t(chunks), [&](size_t b, size_t e, int) {
        for (size_t c = b; c < e; ++c) {
          int64_t off = int64_t(c) * kChunk, len = std::min(kChunk, count - off);
          fill(name, shape, o.seed, first + off, len, buf.data() + off);
          if (o.bf16)
            for (int64_t i = off; i < off + len; ++i) half[size_t(i)] = f32_to_bf16(buf[size_t(i)]);
        }
      }, 1);
      if (o.bf16) MACRO_TRY(f.write(half.data(), size_t(count) * 2));
      else MACRO_TRY(f.write(buf.data(), size_t(count) * 4));
      progress.advance(size_t(count));
    }
  }
  progress.finish();
  return f.commit();
}

}  // namespace

Status write_synthetic_component(const std::string& manifest_path, const std::string& out_dir,
                                 const std::string& class_name, const SyntheticCheckpointOptions& o) {
  MACRO_ASSIGN_OR_RETURN(Manifest m, read_manifest(manifest_path));
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) return Status::error(out_dir + ": cannot create the folder: " + ec.message());
  json config = m.config;
  config["_class_name"] = class_name;
  if (m.lora_targets.is_array()) config["lora_targets"] = m.lora_targets;
  MACRO_TRY(write_file_atomic(out_dir + "/config.json", config.dump(1) + "\n"));
  return write_tensors(out_dir + "/diffusion_pytorch_model.safetensors", m, o);
}

Status write_synthetic_pipeline(const std::string& unet_manifest, const std::string& vae_manifest,
                                const std::string& out_dir, const SyntheticCheckpointOptions& o) {
  MACRO_TRY(write_synthetic_component(unet_manifest, out_dir + "/unet", "UNet2DConditionModel", o));
  MACRO_TRY(write_synthetic_component(vae_manifest, out_dir + "/vae", "AutoencoderKL", o));
  json index = {{"_class_name", "DifixPipeline"},
                {"unet", {"diffusers", "UNet2DConditionModel"}},
                {"vae", {"diffusers", "AutoencoderKL"}},
                {"scheduler", {"diffusers", "DDPMScheduler"}}};
  MACRO_TRY(write_file_atomic(out_dir + "/model_index.json", index.dump(1) + "\n"));
  std::filesystem::create_directories(out_dir + "/scheduler");
  json sched = {{"_class_name", "DDPMScheduler"}, {"num_train_timesteps", 1000},
                {"beta_schedule", "scaled_linear"}, {"beta_start", 0.00085}, {"beta_end", 0.012},
                {"prediction_type", "epsilon"}, {"clip_sample", false}};
  return write_file_atomic(out_dir + "/scheduler/scheduler_config.json", sched.dump(1) + "\n");
}

}  // namespace macro::nets
