// UNet2DConditionModel (see unet.h): module tree from the config, the weight walk, the forward.
//
// Legend (the letters of unet.h): V views (the batch; one scene's views, attended jointly), Vc
// context views (V or 1), C channels, C_L = block_out_channels[L] (SD-Turbo: 320, 640, 1280, 1280),
// C0 = C_0, Cin / Cout latent channels in / out (4), Cs a popped skip's channels, h x w latent
// (H/8 x W/8 of an H x W image), h_L x w_L the grid of level L (ceil halves of h x w; h/2^L when
// h, w are multiples of 8), HW = h_L*w_L tokens per view, M = V*HW token rows, heads x D head
// slices (D = C/heads = 64), Lc context tokens (77), Dc context width (1024), T = 4*C0
// time-embedding width (1280).
//
// Layouts: between blocks NCHW [V, C, h_L, w_L] (= [V, C, HW]); inside a transformer token-major
// [M, C] = [V, HW, C], row v*HW + y*w_L + x (view-major, row-major within a view), the multi-view
// joint layout attn1 attends over as one sequence.
#include "attention/nets/unet.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "attention/runtime/file_io.h"
#include "attention/runtime/op_profile.h"
#include "attention/runtime/ops.h"

namespace macro::nets {

// ---- attention and transformer -----------------------------------------------------------------

void CrossAttention::init(int64_t channels, int64_t context_dim, int num_heads,
                          bool self_attention) {
  c = channels;
  ctx_dim = context_dim;
  heads = num_heads;
  self = self_attention;
  const int64_t kv = self ? c : ctx_dim;
  to_q.init(c, c, false);
  to_k.init(kv, c, false);
  to_v.init(kv, c, false);
  to_out.init(c, c, true);
}

void CrossAttention::visit(const std::string& prefix, ParamVisitor& v) {
  to_q.visit(join_name(prefix, "to_q"), v);
  to_k.visit(join_name(prefix, "to_k"), v);
  to_v.visit(join_name(prefix, "to_v"), v);
  to_out.visit(join_name(prefix, "to_out.0"), v);
}

void CrossAttention::pack(Precision p) {
  if (self) {
    qkv.pack({&to_q, &to_k, &to_v}, p);
    to_q = Linear();
  } else {
    qkv.pack({&to_k, &to_v}, p);
    to_q.pack(p);
  }
  to_k = Linear();
  to_v = Linear();
  to_out.pack(p);
}

void BasicTransformerBlock::init(int64_t channels, int64_t context_dim, int num_heads) {
  c = channels;
  norm1.init(c, 1e-5f);
  norm2.init(c, 1e-5f);
  norm3.init(c, 1e-5f);
  attn1.init(c, c, num_heads, true);
  attn2.init(c, context_dim, num_heads, false);
  ff_proj.init(c, 8 * c, true);
  // value * GELU(gate) in the projection's epilogue, in groups of up to 64 columns (4C is a
  // multiple of 4; the SD-Turbo widths take 64).
  int group = 64;
  while ((4 * c) % group != 0) group /= 2;
  ff_proj.geglu_group = group;
  ff_out.init(4 * c, c, true);
}

void BasicTransformerBlock::visit(const std::string& prefix, ParamVisitor& v) {
  norm1.visit(join_name(prefix, "norm1"), v);
  attn1.visit(join_name(prefix, "attn1"), v);
  norm2.visit(join_name(prefix, "norm2"), v);
  attn2.visit(join_name(prefix, "attn2"), v);
  norm3.visit(join_name(prefix, "norm3"), v);
  ff_proj.visit(join_name(prefix, "ff.net.0.proj"), v);
  ff_out.visit(join_name(prefix, "ff.net.2"), v);
}

void BasicTransformerBlock::pack(Precision p) {
  norm1.pack();
  norm2.pack();
  norm3.pack();
  attn1.pack(p);
  attn2.pack(p);
  ff_proj.pack(p);
  ff_out.pack(p);
}

namespace {
// Token rows per feed-forward chunk: the GEGLU output [rows, 4C] is only ever this tall (instead
// of the whole M = V*HW), which keeps the 10-view case's scratch small; 4096 rows still give the
// GEMM full-size tiles. (The [rows, 8C] projection never reaches memory: the GEMM's GEGLU
// epilogue.)
constexpr int64_t kFeedForwardRows = 4096;
}  // namespace

void BasicTransformerBlock::forward(const Run& r, float* x, int64_t views, int64_t hw,
                                    const float* ctx, int64_t ctx_views, int64_t lc,
                                    const BlockSparseMask* mask, int64_t live_views,
                                    const BlockSparseMask* live_mask) const {
  const int64_t all = views * hw;  // rows that give attn1 its keys and values
  if (live_views <= 0 || live_views > views) live_views = views;
  const int64_t m = live_views * hw;  // rows computed from the attention on
  const int64_t dc = attn2.ctx_dim;
  const int heads = attn1.heads;
  ScratchFrame frame(r);
  const int64_t ff_rows = std::min(m, kFeedForwardRows);
  float* n = r.alloc(all * c);                  // LayerNorm output, then attention output [M, C]
  float* big = r.alloc(all * 3 * c);            // q|k|v [M, 3C], then q2 [M, C]
  float* g = r.alloc(ff_rows * 4 * c);          // GEGLU output of the chunk [rows, 4C]
  float* kv = r.alloc(ctx_views * lc * 2 * c);  // cross k|v [Vc*Lc, 2C]

  // attn1: joint self-attention over all views' tokens (view-major), optionally masked.
  norm1.forward(r, n, x, all);                  // [M, C]
  attn1.qkv.forward(r, all, n, c, big, 3 * c);  // [M, 3C] = q | k | v, each [M, heads, D]
  round_if_bf16(r, big, all * 3 * c);
  // One sequence of M = V*HW tokens: q, k, v [M, heads, D] -> n [M, heads*D = C]; mask M x M.
  // With live views, only their queries (the first rows) against every key.
  AttentionArgs a1 = packed_qkv_attention(big, n, all, c, heads);
  a1.mask = mask;
  if (m < all) {
    a1.nq = int(m);
    a1.mask = mask ? live_mask : nullptr;
    MACRO_CHECK(!mask || (live_mask && live_mask->nq == m && live_mask->nk == all));
  }
  run_attention(r, a1);
  attn1.to_out.forward(r, m, n, c, x, c, /*residual=*/x);  // x [M, C] += to_out(n)

  // attn2: per-view cross-attention to the text context.
  norm2.forward(r, n, x, m);                                 // [M, C]
  attn2.to_q.forward(r, m, n, c, big, c);                    // q [M, C]
  attn2.qkv.forward(r, ctx_views * lc, ctx, dc, kv, 2 * c);  // ctx [Vc*Lc, Dc] -> k | v [Vc*Lc, 2C]
  round_if_bf16(r, big, m * c);
  round_if_bf16(r, kv, ctx_views * lc * 2 * c);
  for (int64_t v = 0; v < live_views; ++v) {
    // View v: q [HW, heads, D] (rows v*HW..) x k, v [Lc, heads, D] of its context -> n [HW, C].
    const float* kv_v = kv + (ctx_views == 1 ? 0 : v) * lc * 2 * c;  // k | v [Lc, 2C]
    AttentionArgs a2;
    a2.q = big + v * hw * c;
    a2.k = kv_v;
    a2.v = kv_v + c;
    a2.q_stride = size_t(c);
    a2.k_stride = a2.v_stride = size_t(2 * c);
    a2.out = n + v * hw * c;
    a2.out_stride = size_t(c);
    a2.nq = int(hw);
    a2.nk = int(lc);
    a2.heads = heads;
    a2.head_dim = int(c / heads);
    run_attention(r, a2);
  }
  attn2.to_out.forward(r, m, n, c, x, c, x);  // x [M, C] += to_out(n)

  // Feed-forward: GEGLU (value = first half, gate = second half, exact-erf GELU), by row chunks;
  // the projection's GEMM applies it as it goes (Linear::geglu_group).
  norm3.forward(r, n, x, m);  // [M, C]
  for (int64_t r0 = 0; r0 < m; r0 += ff_rows) {
    const int64_t rows = std::min(ff_rows, m - r0);
    ff_proj.forward(r, rows, n + r0 * c, c, g, 4 * c);  // [rows, 4C] = value * GELU(gate)
    // x rows [rows, C] += ff_out(g)
    ff_out.forward(r, rows, g, 4 * c, x + r0 * c, c, x + r0 * c);
  }
}

void Transformer2D::init(int64_t channels, int64_t context_dim, int num_heads, int groups) {
  c = channels;
  norm.init(c, groups, 1e-6f);
  proj_in.init(c, c, true);
  proj_out.init(c, c, true);
  block.init(c, context_dim, num_heads);
}

void Transformer2D::visit(const std::string& prefix, ParamVisitor& v) {
  norm.visit(join_name(prefix, "norm"), v);
  proj_in.visit(join_name(prefix, "proj_in"), v);
  block.visit(join_name(prefix, "transformer_blocks.0"), v);
  proj_out.visit(join_name(prefix, "proj_out"), v);
}

void Transformer2D::pack(Precision p) {
  norm.pack();
  proj_in.pack(p);
  proj_out.pack(p);
  block.pack(p);
}

void Transformer2D::forward(const Run& r, float* x, int64_t views, int64_t hw, const float* ctx,
                            int64_t ctx_views, int64_t lc, const BlockSparseMask* mask,
                            int64_t live_views, const BlockSparseMask* live_mask) const {
  const int64_t m = views * hw;
  if (live_views <= 0 || live_views > views) live_views = views;
  ScratchFrame frame(r);
  float* g = r.alloc(m * c);  // GN(x) NCHW, later proj_out tokens [M, C]
  float* t = r.alloc(m * c);  // tokens [M, C]
  // g = GN(x) [V, C, HW]
  norm.forward(r, g, x, views, hw, false);
  for (int64_t v = 0; v < views; ++v)  // NCHW plane read transposed: tokens [HW, C]
    proj_in.forward(r, hw, g + v * c * hw, hw, t + v * hw * c, c, nullptr, /*trans_x=*/true);
  // t [M, C] = [V, HW, C], view-major: the joint token layout of attn1.
  block.forward(r, t, views, hw, ctx, ctx_views, lc, mask, live_views, live_mask);  // in place
  proj_out.forward(r, live_views * hw, t, c, g, c);      // g: tokens [live*HW, C]
  tokens_to_nchw_add(r, x, x, g, c, live_views, c, hw);  // x [live, C, HW] += g^T per view
}

// ---- blocks ------------------------------------------------------------------------------------

void UNetBlock::visit(const std::string& prefix, ParamVisitor& v) {
  for (size_t j = 0; j < resnets.size(); ++j)
    resnets[j].visit(join_name(prefix, "resnets." + std::to_string(j)), v);
  for (size_t j = 0; j < attentions.size(); ++j)
    attentions[j].visit(join_name(prefix, "attentions." + std::to_string(j)), v);
  if (has_down) downsampler.visit(join_name(prefix, "downsamplers.0"), v);
  if (has_up) upsampler.visit(join_name(prefix, "upsamplers.0"), v);
}

size_t UNetBlock::bytes() const {
  size_t n = downsampler.bytes() + upsampler.bytes();
  for (const auto& rb : resnets) n += rb.bytes();
  for (const auto& at : attentions) n += at.bytes();
  return n;
}

void UNetBlock::pack(Precision p) {
  for (auto& rb : resnets) rb.pack(p);
  for (auto& at : attentions) at.pack(p);
  if (has_down) downsampler.pack(p);
  if (has_up) upsampler.pack(p);
}

// ---- the model ---------------------------------------------------------------------------------

Result<std::unique_ptr<UNet2DConditionModel>> UNet2DConditionModel::build(const UNetConfig& cfg) {
  auto m = std::make_unique<UNet2DConditionModel>();
  m->cfg_ = cfg;
  const auto& boc = cfg.block_out_channels;
  const int n = int(boc.size());
  if (n < 1 || int(cfg.num_heads.size()) != n)
    return Status::error("UNet config: expected one head count per level");
  const int groups = cfg.norm_num_groups;
  const float eps = float(cfg.norm_eps);
  const int64_t c0 = boc[0], temb = cfg.time_embed_dim();
  for (int i = 0; i < n; ++i)
    if (boc[i] / cfg.num_heads[i] > attention_detail::kMaxHeadDim)
      return Status::error("UNet config: head dim " + std::to_string(boc[i] / cfg.num_heads[i]) +
                           " at level " + std::to_string(i) + " exceeds the attention kernel's " +
                           std::to_string(attention_detail::kMaxHeadDim));
  m->conv_in.init(cfg.in_channels, c0, 3);
  m->time_linear_1.init(c0, temb, true);
  m->time_linear_2.init(temb, temb, true);
  int64_t out = c0;
  m->down_blocks.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    UNetBlock& b = m->down_blocks[size_t(i)];
    const int64_t in = out;
    out = boc[size_t(i)];
    const bool cross = cfg.down_block_types[size_t(i)] == "CrossAttnDownBlock2D";
    b.resnets.resize(size_t(cfg.layers_per_block));
    if (cross) b.attentions.resize(size_t(cfg.layers_per_block));
    for (int j = 0; j < cfg.layers_per_block; ++j) {
      b.resnets[size_t(j)].init(j == 0 ? in : out, out, temb, groups, eps);
      if (cross)
        b.attentions[size_t(j)].init(out, cfg.cross_attention_dim, cfg.num_heads[size_t(i)],
                                     groups);
    }
    b.c_out = out;
    b.has_down = i + 1 < n;
    if (b.has_down) b.downsampler.init(out, /*vae_pad=*/false);
  }
  const int64_t cl = boc.back();
  m->mid_block.resnets.resize(2);
  m->mid_block.attentions.resize(1);
  m->mid_block.resnets[0].init(cl, cl, temb, groups, eps);
  m->mid_block.resnets[1].init(cl, cl, temb, groups, eps);
  m->mid_block.attentions[0].init(cl, cfg.cross_attention_dim, cfg.num_heads.back(), groups);
  m->mid_block.c_out = cl;
  std::vector<int> rev(boc.rbegin(), boc.rend()),
      rev_heads(cfg.num_heads.rbegin(), cfg.num_heads.rend());
  out = rev[0];
  m->up_blocks.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    UNetBlock& b = m->up_blocks[size_t(i)];
    const int64_t prev = out;
    out = rev[size_t(i)];
    const int64_t in = rev[size_t(std::min(i + 1, n - 1))];
    const bool cross = cfg.up_block_types[size_t(i)] == "CrossAttnUpBlock2D";
    const int layers = cfg.layers_per_block + 1;
    b.resnets.resize(size_t(layers));
    if (cross) b.attentions.resize(size_t(layers));
    for (int j = 0; j < layers; ++j) {
      const int64_t skip = j == layers - 1 ? in : out;
      const int64_t rin = j == 0 ? prev : out;
      b.resnets[size_t(j)].init(rin + skip, out, temb, groups, eps);
      if (cross)
        b.attentions[size_t(j)].init(out, cfg.cross_attention_dim, rev_heads[size_t(i)], groups);
    }
    b.c_out = out;
    b.has_up = i + 1 < n;
    if (b.has_up) b.upsampler.init(out);
  }
  m->conv_norm_out.init(c0, groups, eps);
  m->conv_out.init(c0, cfg.out_channels, 3);
  return m;
}

void UNet2DConditionModel::visit(ParamVisitor& v) {
  conv_in.visit("conv_in", v);
  time_linear_1.visit("time_embedding.linear_1", v);
  time_linear_2.visit("time_embedding.linear_2", v);
  for (size_t i = 0; i < down_blocks.size(); ++i)
    down_blocks[i].visit("down_blocks." + std::to_string(i), v);
  mid_block.visit("mid_block", v);
  for (size_t i = 0; i < up_blocks.size(); ++i)
    up_blocks[i].visit("up_blocks." + std::to_string(i), v);
  conv_norm_out.visit("conv_norm_out", v);
  conv_out.visit("conv_out", v);
}

void UNet2DConditionModel::pack(Precision p) {
  precision_ = p;
  conv_in.pack(p);
  time_linear_1.pack(p);
  time_linear_2.pack(p);
  for (auto& b : down_blocks) b.pack(p);
  mid_block.pack(p);
  for (auto& b : up_blocks) b.pack(p);
  conv_norm_out.pack();
  conv_out.pack(p);
}

Result<std::unique_ptr<UNet2DConditionModel>> UNet2DConditionModel::load(const std::string& folder,
                                                                         Precision precision) {
  MACRO_ASSIGN_OR_RETURN(UNetConfig cfg, load_unet_config(folder + "/config.json"));
  MACRO_ASSIGN_OR_RETURN(std::string weights, component_weights_path(folder));
  MACRO_ASSIGN_OR_RETURN(auto model, build(cfg));
  MACRO_TRY(load_weights(*model, weights, {}, precision));
  return model;
}

size_t UNet2DConditionModel::weight_bytes() const {
  size_t n = conv_in.bytes() + conv_out.bytes() + time_linear_1.bytes() + time_linear_2.bytes() +
             mid_block.bytes() + conv_norm_out.bytes();
  for (const auto& b : down_blocks) n += b.bytes();
  for (const auto& b : up_blocks) n += b.bytes();
  return n;
}

std::vector<std::pair<int64_t, int64_t>> UNet2DConditionModel::level_grids(int64_t h,
                                                                           int64_t w) const {
  std::vector<std::pair<int64_t, int64_t>> g;  // (h_L, w_L): h x w, then ceil halves
  for (size_t i = 0; i < down_blocks.size(); ++i) {
    g.emplace_back(h, w);
    if (down_blocks[i].has_down) down_blocks[i].downsampler.out_size(h, w, &h, &w);
  }
  return g;
}

namespace {

struct Skip {
  const float* data;
  int64_t c, h, w;
};

}  // namespace

void UNet2DConditionModel::forward_impl(const Run& r, const float* z, int64_t views, int64_t h,
                                        int64_t w, float t, const float* ctx, int64_t ctx_views,
                                        int64_t lc, const UNetMasks& masks, float* eps,
                                        const UNetTap& tap, int64_t output_views,
                                        const BlockSparseMask* live_mask) const {
  // z [V, Cin, h, w], ctx [Vc, Lc, Dc] -> eps [V_out, Cout, h, w].
  const auto grids = level_grids(h, w);  // (h_L, w_L) per level
  const int n = levels();
  const int64_t c0 = cfg_.block_out_channels[0], temb = cfg_.time_embed_dim();
  auto mask_at = [&](int level) -> const BlockSparseMask* {
    return size_t(level) < masks.level.size() ? masks.level[size_t(level)] : nullptr;
  };
  // Views computed from here on: all of them until the last transformer's joint attention, then
  // the output views only (the others are dead: nothing mixes views after that attention).
  int64_t live = views;
  const auto [last_block, last_layer] = last_up_transformer();
  auto emit = [&](const std::string& name, const float* data, int64_t c, int64_t hh, int64_t ww) {
    if (tap && !r.planning()) tap(name, data, Shape{live, c, hh, ww});
  };

  // Time embedding: SiLU(linear_2(SiLU(linear_1(sinusoid(t))))) — the SiLU every resnet applies.
  float* sinus = r.alloc(c0);  // [C0] (320)
  float* e1 = r.alloc(temb);   // [T] (1280)
  float* emb = r.alloc(temb);  // [T], one for all views
  if (!r.planning()) {
    TimestepEmbeddingParams tp;
    tp.dim = int(c0);
    tp.flip_sin_to_cos = cfg_.flip_sin_to_cos;
    tp.freq_shift = float(cfg_.freq_shift);
    timestep_embedding(sinus, &t, 1, tp);  // [1, C0] = cos | sin
  }
  time_linear_1.forward(r, 1, sinus, c0, e1, temb);  // [1, C0] -> [1, T]
  if (!r.planning()) activation(e1, e1, temb, Act::kSilu, nullptr);
  time_linear_2.forward(r, 1, e1, temb, emb, temb);  // [1, T] -> [1, T]
  if (!r.planning()) activation(emb, emb, temb, Act::kSilu, nullptr);

  // Down path: every resnet/transformer output and every downsample is a skip (kept until popped).
  // SD-Turbo's 12 skips: [V, 320, h, w] x3, [V, 320, h/2, w/2], [V, 640, h/2, w/2] x2,
  // [V, 640, h/4, w/4], [V, 1280, h/4, w/4] x2, [V, 1280, h/8, w/8] x3.
  std::vector<Skip> skips;
  int64_t hh = grids[0].first, ww = grids[0].second, cc = c0;
  float* cur = r.alloc(views * c0 * hh * ww);
  conv_in.forward_same(r, z, views, hh, ww, cur);  // [V, Cin, h, w] -> [V, C0, h, w]
  emit("conv_in", cur, cc, hh, ww);
  skips.push_back({cur, cc, hh, ww});  // [V, C0, h, w]
  for (int i = 0; i < n; ++i) {
    const UNetBlock& b = down_blocks[size_t(i)];  // level i: hh x ww = h_i x w_i
    for (size_t j = 0; j < b.resnets.size(); ++j) {
      float* o = r.alloc(views * b.c_out * hh * ww);
      // [V, C_{i-1} (j = 0; C_0 at i = 0) or C_i, h_i, w_i] -> o [V, C_i, h_i, w_i]
      b.resnets[j].forward(r, cur, views, hh, ww, emb, o);
      cc = b.c_out;
      if (!b.attentions.empty())  // in place on [V, C_i, h_i*w_i]; tokens [V*h_i*w_i, C_i]
        b.attentions[j].forward(r, o, views, hh * ww, ctx, ctx_views, lc, mask_at(i));
      cur = o;
      skips.push_back({cur, cc, hh, ww});  // [V, C_i, h_i, w_i]
    }
    if (b.has_down) {  // stride 2, pad 1: [V, C_i, h_i, w_i] -> [V, C_i, h_{i+1}, w_{i+1}]
      int64_t oh, ow;
      b.downsampler.out_size(hh, ww, &oh, &ow);  // ceil(h_i/2), ceil(w_i/2)
      float* o = r.alloc(views * cc * oh * ow);
      b.downsampler.forward(r, cur, views, hh, ww, o);
      cur = o;
      hh = oh, ww = ow;
      skips.push_back({cur, cc, hh, ww});  // [V, C_i, h_{i+1}, w_{i+1}]
    }
    emit("down_blocks." + std::to_string(i), cur, cc, hh, ww);
  }

  // Mid block at the last level: [V, C_{n-1}, h_{n-1}, w_{n-1}] throughout ([V, 1280, h/8, w/8]).
  {
    const UNetBlock& b = mid_block;
    float* a = r.alloc(views * cc * hh * ww);  // [V, C, hh, ww]
    b.resnets[0].forward(r, cur, views, hh, ww, emb, a);
    // In place; tokens [V*hh*ww, C], attn1 over all of them.
    b.attentions[0].forward(r, a, views, hh * ww, ctx, ctx_views, lc, mask_at(n - 1));
    float* o = r.alloc(views * cc * hh * ww);  // [V, C, hh, ww]
    b.resnets[1].forward(r, a, views, hh, ww, emb, o);
    cur = o;
    emit("mid_block", cur, cc, hh, ww);
  }

  // Up path: ping-pong buffers sized for the largest level, one concat buffer.
  // max_h: the largest [V, c_out, h_L, w_L] of a block, before or after its upsample;
  // max_cat: the largest resnet input [V, C + Cs, h_L, w_L].
  int64_t max_h = 0, max_cat = 0;
  {
    for (int i = 0; i < n; ++i) {
      const UNetBlock& b = up_blocks[size_t(i)];
      const auto [gh, gw] = grids[size_t(n - 1 - i)];
      for (const ResnetBlock2D& rb : b.resnets)
        max_cat = std::max(max_cat, views * rb.c_in * gh * gw);
      max_h = std::max(max_h, views * b.c_out * gh * gw);
      if (b.has_up && n - 2 - i >= 0) {
        const auto [nh, nw] = grids[size_t(n - 2 - i)];
        max_h = std::max(max_h, views * b.c_out * nh * nw);
      }
    }
  }
  float* hbuf[2] = {r.alloc(max_h), r.alloc(max_h)};
  float* cat = r.alloc(max_cat);
  int which = 0;
  // SD-Turbo (C + Cs -> c_out per resnet): up0 @ h/8: 2560, 2560, 2560 -> 1280; up1 @ h/4:
  // 2560, 2560, 1920 -> 1280; up2 @ h/2: 1920, 1280, 960 -> 640; up3 @ h: 960, 640, 640 -> 320.
  for (int i = 0; i < n; ++i) {
    const UNetBlock& b = up_blocks[size_t(i)];
    const int level = n - 1 - i;  // hh x ww = h_level x w_level
    for (size_t j = 0; j < b.resnets.size(); ++j) {
      MACRO_CHECK(!skips.empty());
      const Skip s = skips.back();  // [V, Cs, hh, ww] (LIFO)
      skips.pop_back();
      MACRO_CHECK(s.h == hh && s.w == ww && cc + s.c == b.resnets[j].c_in);
      const int64_t hw = hh * ww;
      for (int64_t v = 0; v < live; ++v) {  // cat[v] = [h[v], skip[v]] on channels
        copy_floats(r, cat + v * (cc + s.c) * hw, cur + v * cc * hw, cc * hw);
        copy_floats(r, cat + v * (cc + s.c) * hw + cc * hw, s.data + v * s.c * hw, s.c * hw);
      }  // cat [V, C + Cs, hh, ww]
      float* o = hbuf[which];
      which ^= 1;
      // [V, C + Cs, hh, ww] -> [V, c_out, hh, ww]
      b.resnets[j].forward(r, cat, live, hh, ww, emb, o, /*x_is_scratch=*/true);
      cc = b.c_out;
      if (!b.attentions.empty()) {  // in place on [V, c_out, hw]; tokens [V*hw, c_out]
        const bool last = i == last_block && int(j) == last_layer;
        b.attentions[j].forward(r, o, views, hw, ctx, ctx_views, lc, mask_at(level),
                                last ? output_views : views, last ? live_mask : nullptr);
        if (last) live = output_views;
      }
      cur = o;
    }
    if (b.has_up) {
      // diffusers upsamples to the next skip's size (forward_upsample_size for odd latents).
      // [V, C, h_L, w_L] -> [V, C, oh, ow] = [V, C, h_{L-1}, w_{L-1}] (2*h_L, or 2*h_L - 1)
      const int64_t oh = skips.empty() ? 2 * hh : skips.back().h;
      const int64_t ow = skips.empty() ? 2 * ww : skips.back().w;
      MACRO_CHECK(cur == hbuf[which ^ 1]);  // both buffers hold max_h: resize into the other one
      b.upsampler.forward_in_place(r, cur, live, cc, hh, ww, oh, ow, hbuf[which]);
      hh = oh, ww = ow;
    }
    emit("up_blocks." + std::to_string(i), cur, cc, hh, ww);
  }

  // Output: conv_out(SiLU(GN(h))).
  live = output_views;  // views are independent from the last joint attention on
  float* t2 = r.alloc(live * cc * hh * ww);                                    // [V, C0, h, w]
  conv_norm_out.forward(r, t2, cur, live, hh * ww, /*silu=*/true);             // [V, C0, h, w]
  conv_out.forward_scratch(r, t2, live, hh, ww, eps, nullptr, 1, 1, 1, 1, 1);  // [V, Cout, h, w]
}

std::pair<int, int> UNet2DConditionModel::last_up_transformer() const {
  for (int i = levels() - 1; i >= 0; --i)
    if (!up_blocks[size_t(i)].attentions.empty())
      return {i, int(up_blocks[size_t(i)].attentions.size()) - 1};
  return {-1, -1};
}

size_t UNet2DConditionModel::workspace_bytes(int64_t views, int64_t h, int64_t w,
                                             int64_t ctx_tokens) const {
  Workspace plan;
  forward_impl(Run{&plan, nullptr, precision_}, nullptr, views, h, w, 0, nullptr, views, ctx_tokens,
               {}, nullptr, {}, views, nullptr);
  return plan.peak();
}

Result<Tensor> UNet2DConditionModel::forward(const TensorView& z, float timestep,
                                             const TensorView& ctx, const UNetMasks& masks,
                                             ThreadPool* pool, const UNetTap& tap, Arena* arena,
                                             int64_t output_views) const {
  if (z.dtype != DType::kF32 || z.rank != 4 || !z.is_contiguous() || z.dim(1) != cfg_.in_channels ||
      z.dim(0) < 1 || z.dim(2) < 1 || z.dim(3) < 1)
    return Status::error("unet: z: expected contiguous F32 [V," + std::to_string(cfg_.in_channels) +
                         ",h,w], found " + z.describe());
  const int64_t views = z.dim(0), h = z.dim(2), w = z.dim(3);  // z [V, Cin, h, w]
  if (ctx.dtype != DType::kF32 || ctx.rank != 3 || !ctx.is_contiguous() ||
      (ctx.dim(0) != views && ctx.dim(0) != 1) || ctx.dim(1) < 1 ||
      ctx.dim(2) != cfg_.cross_attention_dim)
    return Status::error("unet: ctx: expected contiguous F32 [" + std::to_string(views) +
                         " or 1,L," + std::to_string(cfg_.cross_attention_dim) + "], found " +
                         ctx.describe());
  const auto grids = level_grids(h, w);
  if (masks.level.size() > grids.size())
    return Status::error("unet: masks: expected at most " + std::to_string(grids.size()) +
                         " levels, found " + std::to_string(masks.level.size()));
  for (size_t l = 0; l < masks.level.size(); ++l) {
    const BlockSparseMask* m = masks.level[l];
    if (!m) continue;
    const int64_t tokens = views * grids[l].first * grids[l].second;  // M = V*h_l*w_l
    if (m->nq != tokens || m->nk != tokens)
      return Status::error("unet: mask level " + std::to_string(l) + ": expected " +
                           std::to_string(tokens) + " x " + std::to_string(tokens) +
                           " tokens (views x " + std::to_string(grids[l].first) + "x" +
                           std::to_string(grids[l].second) + "), found " + std::to_string(m->nq) +
                           " x " + std::to_string(m->nk));
  }
  if (output_views == 0) output_views = views;
  if (output_views < 1 || output_views > views)
    return Status::error("unet: output views: expected 1.." + std::to_string(views) + ", found " +
                         std::to_string(output_views));
  // The last transformer's mask restricted to the output views' queries.
  const auto [last_block, last_layer] = last_up_transformer();
  std::optional<BlockSparseMask> live_mask;
  if (output_views < views && last_block >= 0) {
    const size_t level = size_t(levels() - 1 - last_block);
    if (level < masks.level.size() && masks.level[level]) {
      const auto [gh, gw] = grids[level];
      MACRO_ASSIGN_OR_RETURN(live_mask,
                             restrict_queries(*masks.level[level], int(output_views * gh * gw)));
    }
  }
  const BlockSparseMask* live = live_mask ? &*live_mask : nullptr;
  Tensor eps = Tensor::f32({output_views, cfg_.out_channels, h, w});  // [V_out, Cout, h, w]
  Workspace plan;
  forward_impl(Run{&plan, pool, precision_}, nullptr, views, h, w, timestep, nullptr, ctx.dim(0),
               ctx.dim(1), masks, nullptr, tap, output_views, live);
  Arena local;
  Arena& a = prepare_arena(arena, local, plan.peak());
  Workspace ws(&a);
  forward_impl(Run{&ws, pool, precision_}, z.f32(), views, h, w, timestep, ctx.f32(), ctx.dim(0),
               ctx.dim(1), masks, eps.f32(), tap, output_views, live);
  a.reset();
  return eps;
}

}  // namespace macro::nets
