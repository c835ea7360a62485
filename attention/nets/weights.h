// Loading a checkpoint into a module tree, by name.
//
// Modules (attention/nets/*) mirror the diffusers tensor names and expose
//   void visit(const std::string& prefix, ParamVisitor& v)
// which calls v.param("<prefix>.<name>", param, {expected shape}) for each of their tensors. Loading
// is a walk: WeightStore::bind() fills each Param and finish() reports, by name, every tensor that
// was missing, mis-shaped, or present in the file but never used.
//
// Name conversions (one table, here):
//  * PEFT LoRA left unmerged (Difix VAE): `M.base_layer.{weight,bias}` + `M.lora_A.<adapter>.weight`
//    [r, in(, kh, kw)] + `M.lora_B.<adapter>.weight` [out, r(, 1, 1)] are presented as `M.weight` =
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

#include "attention/runtime/safetensors.h"
#include "attention/runtime/status.h"

namespace macro::nets {

// One parameter tensor, fp32, row-major. `data` points into the mapped file (F32 entries, zero copy)
// or into storage owned by the WeightStore (converted or merged entries); the store must outlive it.
struct Param {
  const float* data = nullptr;
  std::vector<int64_t> shape;
  int64_t numel() const {
    int64_t n = 1;
    for (int64_t d : shape) n *= d;
    return n;
  }
  bool loaded() const { return data != nullptr; }
};

class ParamVisitor {
 public:
  virtual ~ParamVisitor() = default;
  virtual void param(const std::string& name, Param& p, const std::vector<int64_t>& shape) = 0;
};

struct WeightStoreOptions {
  double lora_scale = 0.0;  // > 0: merge PEFT LoRA triples with this scale (alpha / r)
  std::set<std::string> ignored;  // names present in files that are not parameters
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

 private:
  WeightStore() = default;
  Status prepare(const WeightStoreOptions& options);

  struct Source {
    const TensorEntry* entry = nullptr;     // plain tensor in the file
    std::vector<int64_t> shape;             // as presented (after renames/squeezes)
    bool legacy_squeeze = false;            // 1x1-conv-shaped legacy Linear
    // LoRA merge: base + scale * B @ A
    const TensorEntry* lora_a = nullptr;
    const TensorEntry* lora_b = nullptr;
    std::vector<std::string> file_names;    // the file's own names behind this entry
  };
  Result<const float*> materialise(const std::string& name, const Source& src);

  SafeTensors file_;
  double lora_scale_ = 0.0;
  std::map<std::string, Source> sources_;
  std::set<std::string> used_;
  std::vector<std::string> missing_, misshaped_;
  std::vector<std::unique_ptr<std::vector<float>>> owned_;
  size_t lora_merged_ = 0;
};

std::string shape_string(const std::vector<int64_t>& shape);

}  // namespace macro::nets
