// CLIPTextModel (see clip_text.h): module tree from the config, the weight walk, the forward.
#include "attention/nets/clip_text.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "attention/runtime/file_io.h"
#include "attention/runtime/ops.h"

namespace macro::nets {

Result<std::string> clip_text_weights_path(const std::string& folder) {
  for (const char* name : {"model.safetensors", "model.safetensors.index.json"}) {
    const std::string p = folder + "/" + name;
    if (file_exists(p)) return p;
  }
  return Status::error(folder +
                       ": expected model.safetensors (or model.safetensors.index.json), found "
                       "neither");
}

// ---- one encoder layer -------------------------------------------------------------------------

void ClipEncoderLayer::init(const ClipTextConfig& cfg) {
  d = cfg.hidden_size;
  ff = cfg.intermediate_size;
  heads = cfg.num_attention_heads;
  const float eps = float(cfg.layer_norm_eps);
  layer_norm1.init(d, eps);
  layer_norm2.init(d, eps);
  q_proj.init(d, d, true);
  k_proj.init(d, d, true);
  v_proj.init(d, d, true);
  out_proj.init(d, d, true);
  fc1.init(d, ff, true);
  fc2.init(ff, d, true);
}

void ClipEncoderLayer::visit(const std::string& prefix, ParamVisitor& v) {
  q_proj.visit(join_name(prefix, "self_attn.q_proj"), v);
  k_proj.visit(join_name(prefix, "self_attn.k_proj"), v);
  v_proj.visit(join_name(prefix, "self_attn.v_proj"), v);
  out_proj.visit(join_name(prefix, "self_attn.out_proj"), v);
  layer_norm1.visit(join_name(prefix, "layer_norm1"), v);
  layer_norm2.visit(join_name(prefix, "layer_norm2"), v);
  fc1.visit(join_name(prefix, "mlp.fc1"), v);
  fc2.visit(join_name(prefix, "mlp.fc2"), v);
}

void ClipEncoderLayer::pack(Precision p) {
  layer_norm1.pack();
  layer_norm2.pack();
  qkv.pack({&q_proj, &k_proj, &v_proj}, p);
  q_proj = Linear();
  k_proj = Linear();
  v_proj = Linear();
  out_proj.pack(p);
  fc1.pack(p);
  fc2.pack(p);
}

// ---- the model ---------------------------------------------------------------------------------

Result<std::unique_ptr<ClipTextModel>> ClipTextModel::build(const ClipTextConfig& cfg) {
  if (cfg.hidden_size % cfg.num_attention_heads != 0 ||
      cfg.hidden_size / cfg.num_attention_heads > 512)
    return Status::error("clip text encoder: hidden_size " + std::to_string(cfg.hidden_size) +
                         " / num_attention_heads " + std::to_string(cfg.num_attention_heads) +
                         ": expected a head dim of at most 512 dividing the width");
  auto m = std::make_unique<ClipTextModel>();
  m->cfg_ = cfg;
  m->layers.resize(size_t(cfg.num_hidden_layers));
  for (ClipEncoderLayer& l : m->layers) l.init(cfg);
  m->final_layer_norm.init(cfg.hidden_size, float(cfg.layer_norm_eps));
  return m;
}

void ClipTextModel::visit(ParamVisitor& v) {
  const int64_t d = cfg_.hidden_size;
  v.param("text_model.embeddings.token_embedding.weight", token_embedding, {cfg_.vocab_size, d});
  v.param("text_model.embeddings.position_embedding.weight", position_embedding,
          {cfg_.max_position_embeddings, d});
  for (size_t i = 0; i < layers.size(); ++i)
    layers[i].visit("text_model.encoder.layers." + std::to_string(i), v);
  final_layer_norm.visit("text_model.final_layer_norm", v);
}

void ClipTextModel::pack(Precision p) {
  precision_ = p;
  for (auto [param, dst] : {std::pair{&token_embedding, &tok_}, {&position_embedding, &pos_}}) {
    dst->resize(size_t(param->numel()));
    read_param_f32(*param, dst->data());
    release_param(*param);
    *param = Param();
  }
  for (ClipEncoderLayer& l : layers) l.pack(p);
  final_layer_norm.pack();
}

Result<std::unique_ptr<ClipTextModel>> ClipTextModel::load(const std::string& folder,
                                                           Precision precision) {
  MACRO_ASSIGN_OR_RETURN(ClipTextConfig cfg, load_clip_text_config(folder + "/config.json"));
  MACRO_ASSIGN_OR_RETURN(std::string weights, clip_text_weights_path(folder));
  MACRO_ASSIGN_OR_RETURN(auto model, build(cfg));
  MACRO_TRY(load_weights(*model, weights, {}, precision));
  return model;
}

// One prompt: ids [L] -> out [L, D].
void ClipTextModel::forward_impl(const Run& r, const int32_t* ids, int64_t l, float* out) const {
  const int64_t d = cfg_.hidden_size, ff = cfg_.intermediate_size;
  const int heads = cfg_.num_attention_heads;
  ScratchFrame frame(r);
  float* x = r.alloc(l * d);  // residual stream [L, D]
  float* n = r.alloc(l * d);  // LayerNorm output, then attention output [L, D]
  float* big = r.alloc(l * std::max<int64_t>(3 * d, ff));  // q|k|v [L, 3D], then fc1 [L, F]
  if (!r.planning()) {
    for (int64_t i = 0; i < l; ++i) {
      const float* te = tok_.data() + int64_t(ids[i]) * d;
      const float* pe = pos_.data() + i * d;
      for (int64_t c = 0; c < d; ++c) x[i * d + c] = te[c] + pe[c];
    }
  }
  for (const ClipEncoderLayer& layer : layers) {
    // Causal self-attention, pre-LN.
    layer.layer_norm1.forward(r, n, x, l);
    layer.qkv.forward(r, l, n, d, big, 3 * d);  // [L, 3D]
    round_if_bf16(r, big, l * 3 * d);
    AttentionArgs a = packed_qkv_attention(big, n, l, d, heads);
    a.causal = true;
    run_attention(r, a);
    layer.out_proj.forward(r, l, n, d, x, d, /*residual=*/x);  // x += out_proj(attn)
    // MLP, pre-LN.
    layer.layer_norm2.forward(r, n, x, l);
    layer.fc1.forward(r, l, n, d, big, ff);  // [L, F]
    if (cfg_.hidden_act == "quick_gelu")
      quick_gelu(r, big, l * ff);
    else if (!r.planning())
      activation(big, big, l * ff, Act::kGelu, r.pool);
    layer.fc2.forward(r, l, big, ff, x, d, /*residual=*/x);  // x += fc2(act)
  }
  final_layer_norm.forward(r, out, x, l);
}

Result<Tensor> ClipTextModel::forward(const std::vector<int32_t>& ids, int64_t batch,
                                      ThreadPool* pool, const std::string& what) const {
  if (batch < 1 || ids.empty() || int64_t(ids.size()) % batch != 0)
    return Status::error(what + ": expected " + std::to_string(batch) +
                         " prompts of equal length, found " + std::to_string(ids.size()) + " ids");
  const int64_t l = int64_t(ids.size()) / batch;
  if (l > cfg_.max_position_embeddings)
    return Status::error(what + ": expected at most " +
                         std::to_string(cfg_.max_position_embeddings) + " tokens, found " +
                         std::to_string(l));
  for (size_t i = 0; i < ids.size(); ++i)
    if (ids[i] < 0 || ids[i] >= cfg_.vocab_size)
      return Status::error(what + ": token " + std::to_string(i) + ": expected an id in [0, " +
                           std::to_string(cfg_.vocab_size) + "), found " + std::to_string(ids[i]));
  const int64_t d = cfg_.hidden_size;
  Tensor out = Tensor::f32({batch, l, d});
  Workspace plan;
  forward_impl(Run{&plan, pool, precision_}, nullptr, l, nullptr);
  Arena arena(plan.peak());
  Workspace ws(&arena);
  for (int64_t b = 0; b < batch; ++b)
    forward_impl(Run{&ws, pool, precision_}, ids.data() + b * l, l, out.f32() + b * l * d);
  return out;
}

}  // namespace macro::nets
