// Loading a checkpoint into a module tree, by name.
//
// Modules (attention/nets/*) mirror the diffusers tensor names and expose
//   void visit(const std::string& prefix, ParamVisitor& v)
// which calls v.param("<prefix>.<name>", param, {expected shape}) for each of their tensors.
// Loading is a walk: WeightStore::param() binds each Param and finish() reports, by name, every
// tensor that was missing, mis-shaped, or present in the file but never used. The networks bind
// lazily (WeightStoreOptions::lazy): nothing is converted until a module packs its tensors, one
// module at a time, so a load holds the mapped file, the packed weights built so far and one
// module's transient fp32 copies, never a second full copy of the checkpoint.
//
// Name conversions (one table, here):
//  * PEFT LoRA left unmerged (Difix VAE): `M.base_layer.{weight,bias}` + `M.lora_A.<ad>.weight`
//    [r, in(, kh, kw)] + `M.lora_B.<ad>.weight` [out, r(, 1, 1)] are presented as `M.weight` =
//    base + scale * B @ A and `M.bias`. The scale comes from the caller (VaeConfig::lora_scale).
//  * Older VAE attention names: `query/key/value/proj_attn` -> `to_q/to_k/to_v/to_out.0`, their
//    1x1-conv shape [C, C, 1, 1] accepted for a Linear [C, C].
//  * Ignored buffers: `text_model.embeddings.position_ids`.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "attention/nets/precision.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/large_alloc.h"
#include "attention/runtime/status.h"

namespace macro::nets {

struct WeightSource;

// One parameter tensor, row-major, as bound by a ParamVisitor. Two forms:
//  * `data`: fp32 values the module may read directly. Set by visitors that own fp32 values
//    (tests), by a WeightStore for aligned F32 entries (zero copy into the mapping), and for
//    every entry by a materialising store (lazy == false: converted copies owned by the store).
//  * `source`: the checkpoint entry behind the parameter (lazy stores). Modules read it once, in
//    the form they pack (param_bf16 / read_param_f32 / ParamF32 below), then release_param().
// Either form requires the store to outlive the module's pack().
struct Param {
  const float* data = nullptr;
  const WeightSource* source = nullptr;
  std::vector<int64_t> shape;
  int64_t numel() const {
    int64_t n = 1;
    for (int64_t d : shape) n *= d;
    return n;
  }
  bool loaded() const { return data != nullptr || source != nullptr; }
};

// ---- reading bound parameters while packing ----------------------------------------------------
// The file's bf16 values with no conversion (a BF16 entry, aligned, no LoRA merge), or null.
const uint16_t* param_bf16(const Param& p);
// The parameter as fp32 into dst[numel] (widening F16/BF16/F64, merging LoRA). Counted in
// widen_stats() while the caller's buffer lives only if it is a WidenedBuffer.
void read_param_f32(const Param& p, float* dst);
// Drop the resident file pages behind a lazily bound parameter (its values were packed); a later
// read faults them back in from the file. No-op for `data`-only parameters.
void release_param(const Param& p);

// " N <what> (a; b; c; d; e; ...)" — the first five names of a mismatch list, for load errors;
// "" when items is empty.
std::string name_list(const char* what, const std::vector<std::string>& items);

// A transient fp32 copy of parameters while one module packs: the process-wide live and peak
// bytes of these are what loading holds beyond the packed weights (tests check the peak stays at
// one module's tensors, never a whole checkpoint).
class WidenedBuffer {
 public:
  explicit WidenedBuffer(int64_t floats);
  ~WidenedBuffer();
  WidenedBuffer(const WidenedBuffer&) = delete;
  WidenedBuffer& operator=(const WidenedBuffer&) = delete;
  float* data() { return p_.get(); }
  int64_t size() const { return int64_t(n_); }

 private:
  std::unique_ptr<float, LargeFree> p_;  // huge-page backed and pre-faulted when large
  size_t n_ = 0, cap_ = 0;
};
struct WidenStats {
  size_t live_bytes = 0, peak_bytes = 0;
};
WidenStats widen_stats();
// Frees the calling thread's spare widening buffer (kept between WidenedBuffers; loaders call
// this when they are done).
void release_widen_spare();
void reset_widen_peak();  // peak := live

// fp32 view of a parameter: `data` when bound to fp32, else widened into a WidenedBuffer.
class ParamF32 {
 public:
  explicit ParamF32(const Param& p);
  const float* data() const { return ptr_; }

 private:
  std::unique_ptr<WidenedBuffer> buf_;
  const float* ptr_ = nullptr;
};

class ParamVisitor {
 public:
  virtual ~ParamVisitor() = default;
  virtual void param(const std::string& name, Param& p, const std::vector<int64_t>& shape) = 0;
};

struct WeightStoreOptions {
  double lora_scale = 0.0;        // > 0: merge PEFT LoRA triples with this scale (alpha / r)
  std::set<std::string> ignored;  // names present in files that are not parameters
  // false: every bound Param gets fp32 `data` (converted/merged copies owned by the store).
  // true: Params carry their `source` (plus zero-copy `data` for aligned F32 entries without a
  // merge); nothing is converted until a module packs it. The networks load this way.
  bool lazy = false;
};

// What a lazily bound Param points at (owned by the WeightStore).
struct WeightSource {
  const TensorEntry* entry = nullptr;   // plain tensor (or the LoRA base) in the mapped file
  const TensorEntry* lora_a = nullptr;  // LoRA merge: base + scale * B @ A
  const TensorEntry* lora_b = nullptr;
  double lora_scale = 0.0;
};

class WeightStore : public ParamVisitor {
 public:
  // A .safetensors file or a sharded *.safetensors.index.json.
  static Result<std::unique_ptr<WeightStore>> open(const std::string& path,
                                                   const WeightStoreOptions& options = {});

  // ParamVisitor: binds `p` to the tensor `name`, checking the shape; problems are recorded.
  void param(const std::string& name, Param& p, const std::vector<int64_t>& shape) override;

  // Every problem found by the walk, or ok. The message lists missing, mis-shaped and unused
  // tensors by name (the first few of each kind, with counts).
  Status finish() const;

  // Names available after conversion (merged LoRA modules appear under their plain names).
  std::vector<std::string> names() const;
  const std::string& path() const { return file_.path(); }
  size_t lora_merged() const { return lora_merged_; }
  // Bytes of fp32 copies the store owns (materialised entries); 0 for a lazy store.
  size_t owned_bytes() const { return owned_bytes_; }

 private:
  WeightStore() = default;
  Status prepare(const WeightStoreOptions& options);

  struct Source {
    WeightSource lazy;                   // what lazily bound Params point at
    const TensorEntry* entry = nullptr;  // plain tensor in the file
    std::vector<int64_t> shape;          // as presented (after renames/squeezes)
    bool legacy_squeeze = false;         // 1x1-conv-shaped legacy Linear
    // LoRA merge: base + scale * B @ A
    const TensorEntry* lora_a = nullptr;
    const TensorEntry* lora_b = nullptr;
    std::vector<std::string> file_names;  // the file's own names behind this entry
  };
  Result<const float*> materialise(const std::string& name, const Source& src);

  SafeTensors file_;
  double lora_scale_ = 0.0;
  std::map<std::string, Source> sources_;
  std::set<std::string> used_;
  std::vector<std::string> missing_, misshaped_;
  std::vector<std::unique_ptr<std::vector<float>>> owned_;
  size_t lora_merged_ = 0;
  size_t owned_bytes_ = 0;
  bool lazy_ = false;
};

std::string shape_string(const std::vector<int64_t>& shape);

// A caller-supplied fp32 tensor that replaces (or supplies) one named parameter.
struct OverrideTensor {
  std::vector<int64_t> shape;
  std::vector<float> values;  // row-major, numel(shape) values
};

// A ParamVisitor in front of another: names in the map are bound to the caller's values (shape
// checked) instead of being asked of the inner visitor; every other name goes to the inner one.
// The map must outlive pack(). finish() reports overrides that were mis-shaped or never asked for.
class ParamOverrides : public ParamVisitor {
 public:
  ParamOverrides(ParamVisitor& inner, const std::map<std::string, OverrideTensor>& overrides)
      : inner_(inner), overrides_(overrides) {}
  void param(const std::string& name, Param& p, const std::vector<int64_t>& shape) override;
  Status finish() const;

 private:
  ParamVisitor& inner_;
  const std::map<std::string, OverrideTensor>& overrides_;
  std::set<std::string> used_;
  std::vector<std::string> misshaped_;
};

// Frees what loading keeps between tensors on the calling thread: the spare widening buffer
// (release_widen_spare) and the conv scratch.
void release_load_buffers();

// The loading tail the networks share, for a module tree `Model` with visit(ParamVisitor&) and
// pack(Precision): opens the checkpoint `path` lazily with `options` (each tensor read once, when
// its module packs), walks the tree over it (through a ParamOverrides in front of the store when
// `overrides` is given), reports every missing, mis-shaped or unused tensor by name (then the
// overrides' problems, naming `path`), packs at `precision` and frees the loading buffers.
template <class Model>
Status load_weights(Model& model, const std::string& path, WeightStoreOptions options,
                    Precision precision,
                    const std::map<std::string, OverrideTensor>* overrides = nullptr) {
  options.lazy = true;
  MACRO_ASSIGN_OR_RETURN(std::unique_ptr<WeightStore> store, WeightStore::open(path, options));
  if (overrides) {
    ParamOverrides front(*store, *overrides);
    model.visit(front);
    MACRO_TRY(store->finish());
    MACRO_TRY(front.finish().with_context(path));
  } else {
    model.visit(*store);
    MACRO_TRY(store->finish());
  }
  model.pack(precision);
  release_load_buffers();
  return Status::ok();
}
}  // namespace macro::nets
