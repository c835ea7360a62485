// The CLIP text encoder (transformers CLIPTextModel), the text conditioning of SD-Turbo / Difix.
//
// Legend: B batch (prompts), L tokens (<= max_position_embeddings, 77), D width (hidden_size,
// 1024 for SD-Turbo), F MLP width (intermediate_size), H heads, Dh = D / H.
//
//   x  = token_embedding[ids] + position_embedding[0..L)          [L, D]    per prompt
//   per layer (pre-LN):
//     x += out_proj(attn_causal(q_proj, k_proj, v_proj of LN1(x)))  [L, D]  (biases everywhere)
//     x += fc2(act(fc1(LN2(x))))                                   [L, D]  act: exact-erf GELU
//                                                                         or quick_gelu
//   last_hidden_state = final_layer_norm(x)                        [B, L, D]
//
// Every output row is kept (padding rows attend causally to the prompt; there is no padding
// mask), as SD 2.x uses all 77 rows. No pooled output, no projection.
//
// Tensor names (the real download, text_encoder/model.safetensors):
//   text_model.embeddings.{token_embedding,position_embedding}.weight,
//   text_model.encoder.layers.N.{self_attn.{q,k,v,out}_proj,layer_norm1,layer_norm2,mlp.fc1,
//   mlp.fc2}.{weight,bias}, text_model.final_layer_norm.{weight,bias};
//   text_model.embeddings.position_ids (a buffer) is ignored by the WeightStore.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "attention/nets/diffusers_config.h"
#include "attention/nets/layers.h"

namespace macro::nets {

struct ClipEncoderLayer {
  int64_t d = 0, ff = 0;
  int heads = 1;
  LayerNorm layer_norm1, layer_norm2;
  Linear q_proj, k_proj, v_proj, out_proj;  // [D, D] + [D]
  FusedLinear qkv;                          // q|k|v [3D, D], built by pack()
  Linear fc1, fc2;                          // [F, D], [D, F]

  void init(const ClipTextConfig& cfg);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
};

class ClipTextModel {
 public:
  // A folder with config.json (CLIPTextModel) and model.safetensors.
  static Result<std::unique_ptr<ClipTextModel>> load(const std::string& folder,
                                                     Precision precision = Precision::kF32);
  // The module tree for a config (no weights). load() = build + walk + finish + pack.
  static Result<std::unique_ptr<ClipTextModel>> build(const ClipTextConfig& cfg);
  void visit(ParamVisitor& v);
  void pack(Precision p);

  const ClipTextConfig& config() const { return cfg_; }
  int64_t width() const { return cfg_.hidden_size; }

  // ids [B * L] row-major (B prompts of L tokens) -> last_hidden_state [B, L, D]. Errors name
  // `what` and the offending id or length.
  Result<Tensor> forward(const std::vector<int32_t>& ids, int64_t batch, ThreadPool* pool,
                         const std::string& what = "clip text encoder") const;

 private:
  void forward_impl(const Run& r, const int32_t* ids, int64_t l, float* out) const;

  ClipTextConfig cfg_;
  Precision precision_ = Precision::kF32;
  Param token_embedding, position_embedding;  // [V, D], [P, D] (bound by the walk)
  std::vector<float> tok_, pos_;              // copies kept after pack()
  std::vector<ClipEncoderLayer> layers;
  LayerNorm final_layer_norm;
};

// The weights file of a text-encoder folder: model.safetensors (or its sharded .index.json).
Result<std::string> clip_text_weights_path(const std::string& folder);

}  // namespace macro::nets
