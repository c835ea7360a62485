// The SD-Turbo U-Net (diffusers UNet2DConditionModel, linear projections), multi-view and masked.
//
// Legend: V views (the batch: one scene's views, attended jointly), C channels, h x w latent,
// HW_L tokens per view at level L, M = V*HW_L token rows, Lc context tokens (77), Dc context width,
// T = 4*C0 time-embedding width.
//
//   emb  = linear_2(SiLU(linear_1(timestep_embedding(t))))           [T]  (one t for all views)
//   h    = conv_in(z)                                                 [V, C0, h, w]
//   down: per level L: layers x (resnet, transformer?) then a stride-2 downsample (not on the last)
//   mid:  resnet, transformer, resnet
//   up:   per level (deepest first): layers+1 x (cat[h, skip] -> resnet, transformer?), upsample to
//         the next skip's spatial size (so odd latents work)
//   eps  = conv_out(SiLU(GN(h)))                                      [V, Cout, h, w]
//
// Multi-view (Difix-ref / MACRO): every attn1 runs over all V*HW_L tokens (view-major,
// row-major within a view); attn2, FF, norms, resnets are per view. An optional BlockSparseMask per
// level restricts attn1 (nq = nk = V*HW_L); level L is the L-th token grid from the top (the
// grid of down block L; the mid block uses the last level).
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "attention/nets/diffusers_config.h"
#include "attention/nets/layers.h"
#include "attention/runtime/attention_mask.h"

namespace macro::nets {

// diffusers Attention without biases on q/k/v (heads = contiguous slices, scale 1/sqrt(head dim)).
struct CrossAttention {
  int64_t c = 0, ctx_dim = 0;
  int heads = 1;
  bool self = true;
  Linear to_q, to_k, to_v, to_out;
  FusedLinear qkv;  // self: q|k|v [3C, C]; cross: k|v [2C, Dc]
  Linear q_only;    // cross: to_q

  void init(int64_t channels, int64_t context_dim, int num_heads, bool self_attention);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const { return qkv.bytes() + to_q.bytes() + to_out.bytes(); }
};

struct BasicTransformerBlock {
  int64_t c = 0;
  LayerNorm norm1, norm2, norm3;
  CrossAttention attn1, attn2;
  Linear ff_proj, ff_out;  // ff.net.0.proj [8C, C] (GEGLU value | gate), ff.net.2 [C, 4C]

  void init(int64_t channels, int64_t context_dim, int num_heads);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const {
    return norm1.bytes() + norm2.bytes() + norm3.bytes() + attn1.bytes() + attn2.bytes() +
           ff_proj.bytes() + ff_out.bytes();
  }
  // x [V*HW, C] in place; ctx [Vc, Lc, Dc] with Vc = V or 1 (shared by all views).
  // live_views (1..V): only the first live views' rows are computed after attn1's keys and values
  // (their queries, attn2, FF); the other rows of x are left as they were, dead to the caller.
  // `live_mask` is `mask` restricted to the live rows (restrict_queries), when mask is set.
  void forward(const Run& r, float* x, int64_t views, int64_t hw, const float* ctx,
               int64_t ctx_views, int64_t lc, const BlockSparseMask* mask, int64_t live_views = 0,
               const BlockSparseMask* live_mask = nullptr) const;
};

struct Transformer2D {
  int64_t c = 0;
  GroupNorm norm;  // eps 1e-6 (hard-coded in diffusers)
  Linear proj_in, proj_out;
  BasicTransformerBlock block;

  void init(int64_t channels, int64_t context_dim, int num_heads, int groups);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const { return norm.bytes() + proj_in.bytes() + proj_out.bytes() + block.bytes(); }
  // x [V, C, HW] in place; live_views / live_mask as BasicTransformerBlock (0: every view).
  void forward(const Run& r, float* x, int64_t views, int64_t hw, const float* ctx,
               int64_t ctx_views, int64_t lc, const BlockSparseMask* mask, int64_t live_views = 0,
               const BlockSparseMask* live_mask = nullptr) const;
};

struct UNetBlock {  // down, mid or up block
  std::vector<ResnetBlock2D> resnets;
  std::vector<Transformer2D> attentions;  // empty for DownBlock2D / UpBlock2D
  bool has_down = false, has_up = false;
  Downsample2D downsampler;
  Upsample2D upsampler;
  int64_t c_out = 0;

  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const;
};

// Per-level attn1 masks (null entries: unmasked). Pointers must outlive the forward.
struct UNetMasks {
  std::vector<const BlockSparseMask*> level;
};

// Called with intermediate activations: "conv_in", "down_blocks.i", "mid_block", "up_blocks.i".
using UNetTap = std::function<void(const std::string& name, const float* data, const Shape& shape)>;

class UNet2DConditionModel {
 public:
  // From a folder with config.json + diffusion_pytorch_model.safetensors (or a sharded index).
  static Result<std::unique_ptr<UNet2DConditionModel>> load(const std::string& folder,
                                                            Precision precision);
  // Build the module tree for a config (no weights). load() = build + walk + finish + pack.
  static Result<std::unique_ptr<UNet2DConditionModel>> build(const UNetConfig& cfg);
  void visit(ParamVisitor& v);
  void pack(Precision p);
  // Bytes the loaded model holds: packed weights plus fp32 norm/bias vectors.
  size_t weight_bytes() const;

  const UNetConfig& config() const { return cfg_; }
  Precision precision() const { return precision_; }
  int levels() const { return int(cfg_.block_out_channels.size()); }
  // Token grid (h, w) of every level for a latent h x w.
  std::vector<std::pair<int64_t, int64_t>> level_grids(int64_t h, int64_t w) const;

  // z [V, Cin, h, w], ctx [V or 1, Lc, Dc], one timestep for all views -> eps [V, Cout, h, w].
  // Shapes and masks are validated (errors name `what` and the argument).
  // `arena` (optional, empty): scratch reused across calls (grown to the planned size if needed).
  // output_views (1..V, 0 = V): eps of the first output_views views only, [output_views, Cout,
  // h, w], bit-identical to those views of the full output. After the last transformer's joint
  // attention no view reads another, so everything the other views compute from there on is dead
  // and skipped: their attention queries in that transformer, its attn2, FF and proj_out, and
  // every later resnet, upsample and the output convolution (MACRO needs only the close-up, view
  // 0). Taps see only the computed views after that point.
  Result<Tensor> forward(const TensorView& z, float timestep, const TensorView& ctx,
                         const UNetMasks& masks, ThreadPool* pool, const UNetTap& tap = {},
                         Arena* arena = nullptr, int64_t output_views = 0) const;
  // Scratch bytes one forward takes (the planned arena size) for V views of a latent h x w.
  size_t workspace_bytes(int64_t views, int64_t h, int64_t w, int64_t ctx_tokens = 77) const;

 private:
  void forward_impl(const Run& r, const float* z, int64_t views, int64_t h, int64_t w, float t,
                    const float* ctx, int64_t ctx_views, int64_t lc, const UNetMasks& masks,
                    float* eps, const UNetTap& tap, int64_t output_views,
                    const BlockSparseMask* live_mask) const;
  // The up block and layer of the last transformer ({-1, -1}: none in the up path).
  std::pair<int, int> last_up_transformer() const;

  UNetConfig cfg_;
  Precision precision_ = Precision::kF32;
  Conv2d conv_in, conv_out;
  Linear time_linear_1, time_linear_2;
  std::vector<UNetBlock> down_blocks, up_blocks;
  UNetBlock mid_block;
  GroupNorm conv_norm_out;
};

}  // namespace macro::nets
