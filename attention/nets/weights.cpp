#include "attention/nets/weights.h"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstring>

#include "attention/runtime/conv.h"
#include "attention/runtime/half.h"

namespace macro::nets {
namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Copy any supported dtype to fp32.
Status to_f32(const TensorEntry& e, float* out) {
  const int64_t n = e.numel();
  switch (e.dtype) {
    case DType::kF32:
      std::memcpy(out, e.data, size_t(n) * 4);
      return Status::ok();
    case DType::kBF16:
      for (int64_t i = 0; i < n; ++i) {
        uint16_t h;
        std::memcpy(&h, e.data + 2 * i, 2);
        out[i] = bf16_to_f32(h);
      }
      return Status::ok();
    case DType::kF16:
      for (int64_t i = 0; i < n; ++i) {
        uint16_t h;
        std::memcpy(&h, e.data + 2 * i, 2);
        out[i] = f16_to_f32(h);
      }
      return Status::ok();
    case DType::kF64:
      for (int64_t i = 0; i < n; ++i) {
        double d;
        std::memcpy(&d, e.data + 8 * i, 8);
        out[i] = float(d);
      }
      return Status::ok();
    default:
      return Status::error("tensor '" + e.name + "': expected a floating-point dtype, found " +
                           dtype_name(e.dtype));
  }
}

// Legacy VAE attention names -> current ones.
std::string modern_name(const std::string& name, bool* renamed) {
  static const std::pair<const char*, const char*> kRenames[] = {{".query.", ".to_q."},
                                                                 {".key.", ".to_k."},
                                                                 {".value.", ".to_v."},
                                                                 {".proj_attn.", ".to_out.0."}};
  for (const auto& [from, to] : kRenames) {
    size_t p = name.find(from);
    if (p != std::string::npos && name.find("attentions.") != std::string::npos) {
      *renamed = true;
      return name.substr(0, p) + to + name.substr(p + std::string(from).size());
    }
  }
  *renamed = false;
  return name;
}

bool is_float_dtype(DType d) {
  return d == DType::kF32 || d == DType::kBF16 || d == DType::kF16 || d == DType::kF64;
}

// The parameter's fp32 values (converted, LoRA merged) into out[numel]; dtypes were checked when
// the source was bound.
void widen(const WeightSource& src, float* out) {
  const TensorEntry& e = *src.entry;
  MACRO_CHECK(to_f32(e, out).is_ok());
  if (!src.lora_a) return;
  // W[o, rest] += scale * sum_r B[o, r] * A[r, rest]
  const int64_t n_out = e.shape[0], r = src.lora_a->shape[0];
  const int64_t rest = e.numel() / n_out;
  std::vector<float> A(size_t(src.lora_a->numel())), B(size_t(src.lora_b->numel()));
  MACRO_CHECK(to_f32(*src.lora_a, A.data()).is_ok());
  MACRO_CHECK(to_f32(*src.lora_b, B.data()).is_ok());
  for (int64_t o = 0; o < n_out; ++o) {
    for (int64_t j = 0; j < rest; ++j) {
      double acc = 0;
      for (int64_t q = 0; q < r; ++q)
        acc += double(B[size_t(o * r + q)]) * double(A[size_t(q * rest + j)]);
      out[o * rest + j] = float(double(out[o * rest + j]) + src.lora_scale * acc);
    }
  }
}

std::atomic<size_t> g_widened_live{0}, g_widened_peak{0};

}  // namespace

// ---- reading bound parameters ------------------------------------------------------------------

const uint16_t* param_bf16(const Param& p) {
  if (!p.source || p.source->lora_a) return nullptr;
  const TensorEntry& e = *p.source->entry;
  if (e.dtype != DType::kBF16 || reinterpret_cast<uintptr_t>(e.data) % 2 != 0) return nullptr;
  return reinterpret_cast<const uint16_t*>(e.data);
}

void read_param_f32(const Param& p, float* dst) {
  MACRO_CHECK(p.loaded());
  if (p.data) {
    std::memcpy(dst, p.data, size_t(p.numel()) * sizeof(float));
    return;
  }
  MACRO_CHECK(p.source->entry->numel() == p.numel());
  widen(*p.source, dst);
}

std::string name_list(const char* what, const std::vector<std::string>& items) {
  if (items.empty()) return "";
  std::string msg = std::string(" ") + std::to_string(items.size()) + " " + what + " (";
  for (size_t i = 0; i < items.size() && i < 5; ++i) msg += (i ? "; " : "") + items[i];
  if (items.size() > 5) msg += "; ...";
  return msg + ")";
}

void release_param(const Param& p) {
  if (!p.source) return;
  static const uintptr_t page = uintptr_t(sysconf(_SC_PAGESIZE));
  for (const TensorEntry* e : {p.source->entry, p.source->lora_a, p.source->lora_b}) {
    if (!e) continue;
    const uintptr_t b = reinterpret_cast<uintptr_t>(e->data), end = b + e->bytes;
    const uintptr_t lo = (b + page - 1) / page * page, hi = end / page * page;
    // The mapping is read-only and private: dropped pages are re-read from the file if touched.
    if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED);
  }
}

namespace {
// The largest buffer a thread has widened into, kept for the next one: a loader widens tensor
// after tensor, and a fresh buffer each time costs its page faults again. Freed by
// release_widen_spare().
// A new buffer comes huge-page backed and pre-faulted (large_alloc.h).
struct WidenSpare {
  std::unique_ptr<float, LargeFree> p;
  size_t cap = 0;
};
thread_local WidenSpare t_widen_spare;
}  // namespace

void release_widen_spare() {
  t_widen_spare = WidenSpare{};
}

WidenedBuffer::WidenedBuffer(int64_t floats) {
  n_ = size_t(std::max<int64_t>(floats, 0));
  if (t_widen_spare.cap >= n_) {
    p_ = std::move(t_widen_spare.p);
    cap_ = t_widen_spare.cap;
    t_widen_spare.cap = 0;
  } else {
    cap_ = std::max<size_t>(n_, 1);
    p_.reset(static_cast<float*>(large_alloc(cap_ * sizeof(float), /*populate=*/true)));
    MACRO_CHECK(p_ != nullptr);
  }
  if (n_) std::memset(p_.get(), 0, n_ * sizeof(float));
  const size_t live = g_widened_live += n_ * sizeof(float);
  size_t peak = g_widened_peak.load();
  while (live > peak && !g_widened_peak.compare_exchange_weak(peak, live)) {
  }
}

WidenedBuffer::~WidenedBuffer() {
  g_widened_live -= n_ * sizeof(float);
  if (cap_ > t_widen_spare.cap) {
    t_widen_spare.p = std::move(p_);
    t_widen_spare.cap = cap_;
  }
}

WidenStats widen_stats() {
  return {g_widened_live.load(), g_widened_peak.load()};
}

void reset_widen_peak() {
  g_widened_peak = g_widened_live.load();
}

ParamF32::ParamF32(const Param& p) {
  MACRO_CHECK(p.loaded());
  if (p.data) {
    ptr_ = p.data;
    return;
  }
  buf_ = std::make_unique<WidenedBuffer>(p.numel());
  read_param_f32(p, buf_->data());
  ptr_ = buf_->data();
}

std::string shape_string(const std::vector<int64_t>& s) {
  std::string t = "[";
  for (size_t i = 0; i < s.size(); ++i) {
    if (i) t += ',';
    t += std::to_string(s[i]);
  }
  return t + "]";
}

Result<std::unique_ptr<WeightStore>> WeightStore::open(const std::string& path,
                                                       const WeightStoreOptions& options) {
  std::unique_ptr<WeightStore> store(new WeightStore());
  MACRO_ASSIGN_OR_RETURN(store->file_, SafeTensors::open_checkpoint(path));
  MACRO_TRY(store->prepare(options));
  return store;
}

Status WeightStore::prepare(const WeightStoreOptions& options) {
  lora_scale_ = options.lora_scale;
  lazy_ = options.lazy;
  const std::string& path = file_.path();
  // LoRA triples first: group by module.
  std::map<std::string, Source> lora_modules;
  for (const std::string& name : file_.names()) {
    if (options.ignored.count(name) || name == "text_model.embeddings.position_ids") continue;
    const TensorEntry* e = file_.find(name);
    size_t base_at = name.find(".base_layer.");
    size_t a_at = name.find(".lora_A.");
    size_t b_at = name.find(".lora_B.");
    if (base_at != std::string::npos) {
      std::string module = name.substr(0, base_at);
      std::string leaf = name.substr(base_at + std::string(".base_layer.").size());  // weight|bias
      Source& s = sources_[module + "." + leaf];
      s.entry = e;
      s.shape = e->shape;
      s.file_names.push_back(name);
      if (leaf == "weight") lora_modules[module].entry = e;
      continue;
    }
    if (a_at != std::string::npos || b_at != std::string::npos) {
      std::string module = name.substr(0, a_at != std::string::npos ? a_at : b_at);
      if (!ends_with(name, ".weight"))
        return Status::error(path + ": tensor '" + name +
                             "': expected a LoRA '.weight', found another leaf");
      Source& m = lora_modules[module];
      (a_at != std::string::npos ? m.lora_a : m.lora_b) = e;
      m.file_names.push_back(name);
      continue;
    }
    bool renamed = false;
    std::string canonical = modern_name(name, &renamed);
    if (sources_.count(canonical))
      return Status::error(path + ": tensor '" + name + "': a second tensor maps to '" + canonical +
                           "'");
    Source& s = sources_[canonical];
    s.entry = e;
    s.shape = e->shape;
    s.file_names.push_back(name);
    if (renamed && e->shape.size() == 4 && e->shape[2] == 1 && e->shape[3] == 1 &&
        ends_with(canonical, ".weight")) {
      s.shape = {e->shape[0], e->shape[1]};
      s.legacy_squeeze = true;
    }
  }
  for (auto& [module, m] : lora_modules) {
    const std::string wname = module + ".weight";
    if (!m.entry)
      return Status::error(path + ": LoRA module '" + module + "': expected '" + module +
                           ".base_layer.weight', found only the adapter");
    if (!m.lora_a || !m.lora_b)
      return Status::error(path + ": LoRA module '" + module +
                           "': expected both lora_A and lora_B, found " +
                           (m.lora_a ? "only lora_A" : "only lora_B"));
    if (lora_scale_ <= 0)
      return Status::error(
          path + ": tensor '" + m.lora_a->name +
          "': unmerged LoRA found but no LoRA scale is configured (lora_rank in config.json)");
    const auto& W = m.entry->shape;
    const auto& A = m.lora_a->shape;
    const auto& B = m.lora_b->shape;
    // A: [r, in, kh, kw] or [r, in]; B: [out, r, 1, 1] or [out, r]; W: [out, in, kh, kw] or
    // [out, in].
    bool ok = A.size() == W.size() && B.size() == W.size() && A.size() >= 2 && B[0] == W[0] &&
              A[0] == B[1] && A[1] == W[1];
    for (size_t i = 2; ok && i < W.size(); ++i) ok = A[i] == W[i] && B[i] == 1;
    if (!ok)
      return Status::error(path + ": LoRA module '" + module + "': shapes do not compose: base " +
                           shape_string(W) + ", lora_A " + shape_string(A) + ", lora_B " +
                           shape_string(B));
    Source& s = sources_[wname];
    s.lora_a = m.lora_a;
    s.lora_b = m.lora_b;
    s.file_names.insert(s.file_names.end(), m.file_names.begin(), m.file_names.end());
  }
  return Status::ok();
}

Result<const float*> WeightStore::materialise(const std::string& name, const Source& src) {
  const TensorEntry& e = *src.entry;
  for (const TensorEntry* t : {src.entry, src.lora_a, src.lora_b})
    if (t && !is_float_dtype(t->dtype))
      return Status::error(file_.path() + ": tensor '" + t->name +
                           "': expected a floating-point dtype, found " + dtype_name(t->dtype));
  if (e.dtype == DType::kF32 && !src.lora_a && reinterpret_cast<uintptr_t>(e.data) % 4 == 0)
    return reinterpret_cast<const float*>(e.data);
  if (lazy_) return nullptr;  // read when the module packs it
  (void)name;
  auto buf = std::make_unique<std::vector<float>>(size_t(e.numel()));
  widen(src.lazy, buf->data());
  if (src.lora_a) ++lora_merged_;
  owned_bytes_ += buf->size() * sizeof(float);
  owned_.push_back(std::move(buf));
  return owned_.back()->data();
}

void WeightStore::param(const std::string& name, Param& p, const std::vector<int64_t>& shape) {
  auto it = sources_.find(name);
  if (it == sources_.end()) {
    missing_.push_back(name + " " + shape_string(shape));
    return;
  }
  used_.insert(name);
  if (it->second.shape != shape) {
    misshaped_.push_back(name + ": expected " + shape_string(shape) + ", found " +
                         shape_string(it->second.shape));
    return;
  }
  Source& src = it->second;
  src.lazy = WeightSource{src.entry, src.lora_a, src.lora_b, lora_scale_};
  auto data = materialise(name, src);
  if (!data) {
    misshaped_.push_back(name + ": " + data.status().message());
    return;
  }
  p.data = *data;
  p.source = lazy_ ? &src.lazy : nullptr;
  if (lazy_ && src.lora_a) ++lora_merged_;
  p.shape = shape;
}

Status WeightStore::finish() const {
  std::vector<std::string> unused;
  for (const auto& [name, src] : sources_)
    if (!used_.count(name))
      unused.push_back(src.file_names.empty() ? name : src.file_names.front());
  if (missing_.empty() && misshaped_.empty() && unused.empty()) return Status::ok();
  std::string msg = file_.path() + ": checkpoint does not match the model config:";
  msg += name_list("missing", missing_) + name_list("mis-shaped", misshaped_) +
         name_list("unused", unused);
  return Status::error(msg);
}

std::vector<std::string> WeightStore::names() const {
  std::vector<std::string> out;
  for (const auto& kv : sources_) out.push_back(kv.first);
  return out;
}

// ---- overrides ---------------------------------------------------------------------------------

void ParamOverrides::param(const std::string& name, Param& p, const std::vector<int64_t>& shape) {
  auto it = overrides_.find(name);
  if (it == overrides_.end()) return inner_.param(name, p, shape);
  used_.insert(name);
  const OverrideTensor& t = it->second;
  int64_t n = 1;
  for (int64_t s : t.shape) n *= s;
  if (t.shape != shape || int64_t(t.values.size()) != n) {
    misshaped_.push_back(name + ": expected " + shape_string(shape) + ", found " +
                         shape_string(t.shape) + " with " + std::to_string(t.values.size()) +
                         " values");
    return;
  }
  p = Param();
  p.data = t.values.data();
  p.shape = shape;
}

Status ParamOverrides::finish() const {
  std::vector<std::string> unused;
  for (const auto& kv : overrides_)
    if (!used_.count(kv.first)) unused.push_back(kv.first);
  if (misshaped_.empty() && unused.empty()) return Status::ok();
  std::string msg = "tensor overrides do not match the model:";
  return Status::error(msg + name_list("mis-shaped", misshaped_) + name_list("unused", unused));
}

void release_load_buffers() {
  release_widen_spare();
  conv2d_release_scratch();
}

}  // namespace macro::nets
