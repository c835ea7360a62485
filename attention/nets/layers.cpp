// Shared network layers (see layers.h): parameter walks, one-time packing, planned forwards.
#include "attention/nets/layers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <type_traits>

#include "attention/runtime/file_io.h"
#include "attention/runtime/op_profile.h"
#include "attention/runtime/ops.h"

namespace macro::nets {

std::string join_name(const std::string& prefix, const std::string& name) {
  return prefix.empty() ? name : prefix + "." + name;
}

Result<std::string> component_weights_path(const std::string& folder) {
  for (const char* name : {"diffusion_pytorch_model.safetensors",
                           "diffusion_pytorch_model.safetensors.index.json", "model.safetensors"}) {
    const std::string p = folder + "/" + name;
    if (file_exists(p)) return p;
  }
  return Status::error(folder +
                       ": expected diffusion_pytorch_model.safetensors (or its .index.json), "
                       "found neither");
}

// ---- workspace ---------------------------------------------------------------------------------

float* Workspace::alloc(int64_t floats) {
  MACRO_CHECK(floats >= 0);
  const size_t bytes = Arena::footprint(size_t(floats) * sizeof(float));
  used_ += bytes;
  peak_ = std::max(peak_, used_);
  if (!arena_) return nullptr;
  return static_cast<float*>(arena_->alloc(size_t(floats) * sizeof(float)));
}

Arena& prepare_arena(Arena* arena, Arena& local, size_t bytes) {
  Arena& a = arena ? *arena : local;
  MACRO_CHECK(a.used() == 0);
  a.reserve(bytes);  // grows only
  return a;
}

size_t packed_bytes(const PackedWeights& w) {
  return w.bytes();
}

size_t packed_bytes(const ConvWeights& w) {
  return w.bytes();  // the direct pack, the Winograd packs and the bias
}

void Workspace::reset(size_t mark) {
  MACRO_CHECK(mark <= used_);
  used_ = mark;
  if (arena_) arena_->reset(mark);
}

namespace {

// parallel_for on the run's pool, or inline.
template <typename Fn>
void parallel(const Run& r, size_t n, Fn&& fn, size_t grain = 0) {
  if (n == 0) return;
  if (r.pool && r.pool->size() > 1) {
    r.pool->parallel_for(
        n, [&](size_t b, size_t e, int) { fn(b, e); }, grain);
  } else {
    fn(size_t(0), n);
  }
}

constexpr int64_t kChunk = 1 << 14;  // elements per task of the elementwise helpers

}  // namespace

void round_if_bf16(const Run& r, float* x, int64_t n) {
  if (r.planning() || !r.bf16()) return;
  op_profile::OpScope prof("round to bf16");
  const auto round = ops_kernels().round_bf16;
  const size_t chunks = size_t((n + kChunk - 1) / kChunk);
  parallel(r, chunks, [&](size_t b, size_t e) {
    for (size_t c = b; c < e; ++c) {
      const int64_t lo = int64_t(c) * kChunk, hi = std::min(n, lo + kChunk);
      round(x + lo, hi - lo);
    }
  });
}

void copy_floats(const Run& r, float* dst, const float* src, int64_t n) {
  if (r.planning() || dst == src) return;
  op_profile::OpScope prof("copy");
  const size_t chunks = size_t((n + kChunk - 1) / kChunk);
  parallel(r, chunks, [&](size_t b, size_t e) {
    for (size_t c = b; c < e; ++c) {
      const int64_t lo = int64_t(c) * kChunk, hi = std::min(n, lo + kChunk);
      std::memcpy(dst + lo, src + lo, size_t(hi - lo) * sizeof(float));
    }
  });
}

void gather_rows(const Run& r, float* dst, const float* src, int64_t c, int64_t h, int64_t w,
                 int64_t y0, int64_t y1) {
  if (r.planning()) return;
  op_profile::OpScope prof("copy");
  const int64_t n = (y1 - y0) * w;
  parallel(r, size_t(c), [&](size_t b, size_t e) {
    for (size_t ch = b; ch < e; ++ch)
      std::memcpy(dst + int64_t(ch) * n, src + int64_t(ch) * h * w + y0 * w,
                  size_t(n) * sizeof(float));
  });
}

void scatter_rows(const Run& r, float* dst, const float* src, int64_t c, int64_t h, int64_t w,
                  int64_t y0, int64_t y1) {
  if (r.planning()) return;
  op_profile::OpScope prof("copy");
  const int64_t n = (y1 - y0) * w;
  parallel(r, size_t(c), [&](size_t b, size_t e) {
    for (size_t ch = b; ch < e; ++ch)
      std::memcpy(dst + int64_t(ch) * h * w + y0 * w, src + int64_t(ch) * n,
                  size_t(n) * sizeof(float));
  });
}

void tokens_to_nchw_add(const Run& r, float* dst, const float* src, const float* tokens,
                        int64_t ldt, int64_t n, int64_t c, int64_t hw) {
  if (r.planning()) return;
  op_profile::OpScope prof("tokens to NCHW + residual");
  constexpr int64_t kTile = 32;  // pixels per task: 32 token rows stay in cache across channels
  const int64_t tiles = (hw + kTile - 1) / kTile;
  parallel(r, size_t(n * tiles), [&](size_t b, size_t e) {
    for (size_t t = b; t < e; ++t) {
      const int64_t i = int64_t(t) / tiles, p0 = (int64_t(t) % tiles) * kTile;
      const int64_t p1 = std::min(hw, p0 + kTile);
      const float* tok = tokens + (i * hw) * ldt;
      for (int64_t ch = 0; ch < c; ++ch) {
        const int64_t base = (i * c + ch) * hw;
        for (int64_t p = p0; p < p1; ++p) dst[base + p] = src[base + p] + tok[p * ldt + ch];
      }
    }
  });
}

void run_attention(const Run& r, const AttentionArgs& args) {
  if (r.planning()) return;
  const bool prof_on = op_profile::enabled();
  const double pairs = !prof_on    ? 0.0
                       : args.mask ? double(args.mask->computed_pairs())
                                   : double(args.nq) * args.nk;
  op_profile::OpScope prof(args.mask ? "attention (masked)" : "attention",
                           4.0 * pairs * args.heads * args.head_dim);
  AttentionArgs a = args;
  a.bf16 = r.bf16();  // bf16 products where the path has them (attention.h)
  Status s = attention(a, r.pool ? *r.pool : ThreadPool::global());
  if (!s) {
    std::fprintf(stderr, "attention: %s\n", s.message().c_str());
    MACRO_CHECK(s.is_ok());
  }
}

AttentionArgs packed_qkv_attention(const float* qkv, float* out, int64_t tokens, int64_t d,
                                   int heads) {
  AttentionArgs a;
  a.q = qkv;
  a.k = qkv + d;
  a.v = qkv + 2 * d;
  a.q_stride = a.k_stride = a.v_stride = size_t(3 * d);
  a.out = out;
  a.out_stride = size_t(d);
  a.nq = a.nk = int(tokens);
  a.heads = heads;
  a.head_dim = int(d / heads);
  return a;
}

void quick_gelu(const Run& r, float* x, int64_t n) {
  if (r.planning()) return;
  // x * sigmoid(1.702 x) = SiLU(1.702 x) / 1.702
  scale(x, x, 1.702f, n, r.pool);
  activation(x, x, n, Act::kSilu, r.pool);
  scale(x, x, float(1.0 / 1.702), n, r.pool);
}

void take_vector(Param& p, std::vector<float>& dst) {
  dst.resize(size_t(p.numel()));
  read_param_f32(p, dst.data());
  release_param(p);
  p = Param();
}

// ---- Linear ------------------------------------------------------------------------------------

void Linear::init(int64_t in_features, int64_t out_features, bool with_bias) {
  in = in_features;
  out = out_features;
  has_bias = with_bias;
}

void Linear::visit(const std::string& prefix, ParamVisitor& v) {
  v.param(join_name(prefix, "weight"), weight, {out, in});
  if (has_bias) v.param(join_name(prefix, "bias"), bias, {out});
}

namespace {

WeightType weight_type(Precision p) {
  return p == Precision::kBf16 ? WeightType::kBf16 : WeightType::kF32;
}

}  // namespace

void Linear::pack(Precision p) {
  MACRO_CHECK(weight.loaded());
  // bf16 files pack straight from the mapping; anything else goes through one transient fp32 copy.
  const int g = geglu_group;
  MACRO_CHECK(g == 0 || out % (2 * g) == 0);
  // Rows in GEGLU order (a permuted copy of the same values), or as stored.
  auto permuted = [&](const auto* w) {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(w)>>;
    std::vector<T> v(size_t(out * in));
    for (int64_t r = 0; r < out; ++r)
      std::memcpy(v.data() + r * in, w + geglu_source_row(r, out, g) * in, size_t(in) * sizeof(T));
    return v;
  };
  if (const uint16_t* wb = p == Precision::kBf16 ? param_bf16(weight) : nullptr) {
    packed = g ? PackedWeights::pack(permuted(wb).data(), out, in, in)
               : PackedWeights::pack(wb, out, in, in);
  } else {
    ParamF32 w(weight);
    packed = g ? PackedWeights::pack(permuted(w.data()).data(), out, in, in, weight_type(p))
               : PackedWeights::pack(w.data(), out, in, in, weight_type(p));
  }
  release_param(weight);
  weight = Param();
  if (has_bias) {
    take_vector(bias, b);
    if (g) {
      const std::vector<float> src = b;
      for (int64_t r = 0; r < out; ++r) b[size_t(r)] = src[size_t(geglu_source_row(r, out, g))];
    }
  }
}

void Linear::forward(const Run& r, int64_t m, const float* x, int64_t ldx, float* y, int64_t ldy,
                     const float* residual, bool trans_x) const {
  if (r.planning() || m == 0) return;
  op_profile::OpScope prof(geglu_group ? "linear + GEGLU" : "linear",
                           2.0 * double(m) * double(in) * double(out));
  GemmParams p;
  p.trans_a = trans_x;
  p.geglu_group = geglu_group;
  MACRO_CHECK(!geglu_group || !residual);
  p.bias_n = b.empty() ? nullptr : b.data();
  if (residual) {
    p.residual = residual;
    p.ldr = ldy;
  }
  gemm_packed(m, x, ldx, packed, y, ldy, p, r.pool);
}

void FusedLinear::pack(const std::vector<const Linear*>& parts, Precision p) {
  MACRO_CHECK(!parts.empty());
  in = parts[0]->in;
  out = 0;
  bool any_bias = false;
  for (const Linear* l : parts) {
    MACRO_CHECK(l->in == in && l->weight.loaded());
    out += l->out;
    any_bias |= l->has_bias;
  }
  b.assign(any_bias ? size_t(out) : 0, 0.0f);
  bool all_bf16 = p == Precision::kBf16;
  for (const Linear* l : parts) all_bf16 = all_bf16 && param_bf16(l->weight) != nullptr;
  int64_t row = 0;
  if (all_bf16) {  // concatenate the file's bf16 rows, pack without widening
    std::vector<uint16_t> w(size_t(out * in));
    for (const Linear* l : parts) {
      std::memcpy(w.data() + row * in, param_bf16(l->weight), size_t(l->out * in) * 2);
      row += l->out;
    }
    packed = PackedWeights::pack(w.data(), out, in, in);
  } else {
    WidenedBuffer w(out * in);
    for (const Linear* l : parts) {
      read_param_f32(l->weight, w.data() + row * in);
      row += l->out;
    }
    packed = PackedWeights::pack(w.data(), out, in, in, weight_type(p));
  }
  row = 0;
  for (const Linear* l : parts) {
    if (l->has_bias) read_param_f32(l->bias, b.data() + row);
    release_param(l->weight);
    if (l->has_bias) release_param(l->bias);
    row += l->out;
  }
}

void FusedLinear::forward(const Run& r, int64_t m, const float* x, int64_t ldx, float* y,
                          int64_t ldy, bool trans_x) const {
  if (r.planning() || m == 0) return;
  op_profile::OpScope prof("linear", 2.0 * double(m) * double(in) * double(out));
  GemmParams p;
  p.trans_a = trans_x;
  p.bias_n = b.empty() ? nullptr : b.data();
  gemm_packed(m, x, ldx, packed, y, ldy, p, r.pool);
}

// ---- Conv2d ------------------------------------------------------------------------------------

void Conv2d::init(int64_t cin, int64_t cout, int kernel, bool with_bias) {
  c_in = cin;
  c_out = cout;
  k = kernel;
  has_bias = with_bias;
}

void Conv2d::visit(const std::string& prefix, ParamVisitor& v) {
  v.param(join_name(prefix, "weight"), weight, {c_out, c_in, k, k});
  if (has_bias) v.param(join_name(prefix, "bias"), bias, {c_out});
}

void Conv2d::pack(Precision p) {
  MACRO_CHECK(weight.loaded());
  std::vector<float> bv;
  if (has_bias) take_vector(bias, bv);
  const float* bp = has_bias ? bv.data() : nullptr;
  // bf16: the conv kernel takes bf16 weights (packed from the rounded fp32 values) and rounds its
  // input itself; fp32 F32 files pack straight from the mapping.
  // Only Downsample2D calls its conv at stride 2; every other conv keeps just the Winograd packs
  // when it gets them (conv.h, stride1_only).
  if (weight_scale == 1.0f) {
    ParamF32 w(weight);
    packed =
        ConvWeights::pack(w.data(), bp, c_out, c_in, k, k, weight_type(p), active_isa(), !strided);
  } else {
    WidenedBuffer w(weight.numel());
    read_param_f32(weight, w.data());
    for (int64_t i = 0; i < w.size(); ++i) w.data()[i] *= weight_scale;
    packed =
        ConvWeights::pack(w.data(), bp, c_out, c_in, k, k, weight_type(p), active_isa(), !strided);
  }
  release_param(weight);
  weight = Param();
}

void Conv2d::forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w, float* y,
                     const float* residual, int stride, int pt, int pl, int pb, int pr) const {
  if (!r.bf16() || packed.type() == WeightType::kBf16)
    return forward_scratch(r, const_cast<float*>(x), n, h, w, y, residual, stride, pt, pl, pb,
                           pr);  // fp32 / bf16 kernel: x is only read
  ScratchFrame frame(r);
  float* t = r.alloc(n * c_in * h * w);
  copy_floats(r, t, x, n * c_in * h * w);
  forward_scratch(r, t, n, h, w, y, residual, stride, pt, pl, pb, pr);
}

void Conv2d::forward_scratch(const Run& r, float* x, int64_t n, int64_t h, int64_t w, float* y,
                             const float* residual, int stride, int pt, int pl, int pb, int pr,
                             int64_t row_origin, int64_t y_plane) const {
  if (r.planning()) return;
  const int64_t oh = (h + pt + pb - k) / stride + 1, ow = (w + pl + pr - k) / stride + 1;
  op_profile::OpScope prof(k == 1        ? "conv 1x1"
                           : stride == 1 ? "conv 3x3"
                                         : "conv 3x3 stride 2",
                           2.0 * double(n * oh * ow) * double(c_in * c_out) * double(k * k));
  if (packed.type() != WeightType::kBf16) round_if_bf16(r, x, n * c_in * h * w);
  Conv2dShape s;
  s.n = n, s.c_in = c_in, s.h = h, s.w = w, s.c_out = c_out, s.kh = k, s.kw = k;
  s.stride = stride;
  s.pad_top = pt, s.pad_left = pl, s.pad_bottom = pb, s.pad_right = pr;
  s.row_origin = row_origin;
  s.y_plane = y_plane;
  conv2d(s, x, packed, residual, y, r.pool);
}

void Conv2d::forward_rows(const Run& r, const float* x, int64_t h, int64_t w, int64_t y0,
                          int64_t y1, float* in, float* y, const float* residual,
                          const GroupNorm::Stats* pre) const {
  rows(r, x, h, w, y0, y1, in, y, residual, pre, /*into_whole=*/false);
}

void Conv2d::forward_rows_into(const Run& r, const float* x, int64_t h, int64_t w, int64_t y0,
                               int64_t y1, float* in, float* y, const float* residual,
                               const GroupNorm::Stats* pre) const {
  rows(r, x, h, w, y0, y1, in, y, residual, pre, /*into_whole=*/true);
}

void Conv2d::rows(const Run& r, const float* x, int64_t h, int64_t w, int64_t y0, int64_t y1,
                  float* in, float* y, const float* residual, const GroupNorm::Stats* pre,
                  bool into_whole) const {
  const int hk = k / 2;
  const int64_t iy0 = std::max<int64_t>(0, y0 - hk), iy1 = std::min<int64_t>(h, y1 + hk);
  if (r.planning()) return;
  if (pre)
    GroupNorm::apply(r, *pre, in, (iy1 - iy0) * w, x + iy0 * w, h * w, (iy1 - iy0) * w);
  else
    gather_rows(r, in, x, c_in, h, w, iy0, iy1);
  const int64_t off = into_whole ? y0 * w : 0;  // a whole-image y: the band's rows, planes h*w
  forward_scratch(r, in, 1, iy1 - iy0, w, y + off, residual ? residual + off : nullptr, 1,
                  int(hk - (y0 - iy0)), hk, int(hk - (iy1 - y1)), hk, y0, into_whole ? h * w : 0);
}

// ---- norms -------------------------------------------------------------------------------------

void GroupNorm::init(int64_t channels, int num_groups, float epsilon) {
  c = channels;
  groups = num_groups;
  eps = epsilon;
}

void GroupNorm::visit(const std::string& prefix, ParamVisitor& v) {
  v.param(join_name(prefix, "weight"), weight, {c});
  v.param(join_name(prefix, "bias"), bias, {c});
}

void GroupNorm::pack() {
  take_vector(weight, gamma);
  take_vector(bias, beta);
}

void GroupNorm::forward(const Run& r, float* dst, const float* src, int64_t n, int64_t hw,
                        bool silu) const {
  if (r.planning()) return;
  op_profile::OpScope prof(silu ? "group norm + SiLU" : "group norm");
  GroupNormParams p;
  p.groups = groups;
  p.eps = eps;
  p.act = silu ? Act::kSilu : Act::kNone;
  group_norm(dst, src, gamma.data(), beta.data(), n, c, hw, p, r.pool);
}

// The statistics exactly as ops.cpp's group_norm computes them (same kernels, same order).
void GroupNorm::stats(const Run& r, const float* x, int64_t hw, bool silu, Stats* st) const {
  st->mean.assign(size_t(c), 0.0);
  st->a.assign(size_t(c), 0.0f);
  st->b.assign(size_t(c), 0.0f);
  st->silu = silu;
  if (r.planning()) return;
  op_profile::OpScope prof("group norm");
  const OpsKernels& k = ops_kernels();
  const int64_t cpg = c / groups, group_len = cpg * hw;
  parallel(r, size_t(groups), [&](size_t b0, size_t b1) {
    for (size_t g = b0; g < b1; ++g) {
      const float* xg = x + int64_t(g) * group_len;
      const double mean = group_len ? k.sum(xg, group_len) / double(group_len) : 0.0;
      const double var = group_len ? k.sum_sq_dev(xg, group_len, mean) / double(group_len) : 0.0;
      const double rstd = 1.0 / std::sqrt(var + double(eps));
      for (int64_t ci = 0; ci < cpg; ++ci) {
        const size_t ch = size_t(int64_t(g) * cpg + ci);
        st->mean[ch] = mean;
        st->a[ch] = float(rstd * gamma[ch]);
        st->b[ch] = beta[ch];
      }
    }
  });
}

void GroupNorm::apply(const Run& r, const Stats& st, float* dst, int64_t dst_plane,
                      const float* src, int64_t src_plane, int64_t len) {
  if (r.planning()) return;
  op_profile::OpScope prof(st.silu ? "group norm + SiLU" : "group norm");
  const OpsKernels& k = ops_kernels();
  const Act act = st.silu ? Act::kSilu : Act::kNone;
  parallel(r, st.mean.size(), [&](size_t b, size_t e) {
    for (size_t ch = b; ch < e; ++ch)
      k.affine_act(dst + int64_t(ch) * dst_plane, src + int64_t(ch) * src_plane, len, st.mean[ch],
                   st.a[ch], st.b[ch], act);
  });
}

void LayerNorm::init(int64_t features, float epsilon) {
  d = features;
  eps = epsilon;
}

void LayerNorm::visit(const std::string& prefix, ParamVisitor& v) {
  v.param(join_name(prefix, "weight"), weight, {d});
  v.param(join_name(prefix, "bias"), bias, {d});
}

void LayerNorm::pack() {
  take_vector(weight, gamma);
  take_vector(bias, beta);
}

void LayerNorm::forward(const Run& r, float* dst, const float* src, int64_t m) const {
  if (r.planning()) return;
  op_profile::OpScope prof("layer norm");
  layer_norm(dst, src, gamma.data(), beta.data(), m, d, eps, r.pool);
}

// ---- ResnetBlock2D -----------------------------------------------------------------------------

void ResnetBlock2D::init(int64_t cin, int64_t cout, int64_t temb_channels, int groups, float eps) {
  c_in = cin;
  c_out = cout;
  temb = temb_channels;
  norm1.init(cin, groups, eps);
  conv1.init(cin, cout, 3);
  norm2.init(cout, groups, eps);
  conv2.init(cout, cout, 3);
  if (temb > 0) time_emb_proj.init(temb, cout, true);
  has_shortcut = cin != cout;
  if (has_shortcut) conv_shortcut.init(cin, cout, 1);
}

void ResnetBlock2D::visit(const std::string& prefix, ParamVisitor& v) {
  norm1.visit(join_name(prefix, "norm1"), v);
  conv1.visit(join_name(prefix, "conv1"), v);
  if (temb > 0) time_emb_proj.visit(join_name(prefix, "time_emb_proj"), v);
  norm2.visit(join_name(prefix, "norm2"), v);
  conv2.visit(join_name(prefix, "conv2"), v);
  if (has_shortcut) conv_shortcut.visit(join_name(prefix, "conv_shortcut"), v);
}

void ResnetBlock2D::pack(Precision p) {
  norm1.pack();
  norm2.pack();
  conv1.pack(p);
  conv2.pack(p);
  if (temb > 0) time_emb_proj.pack(p);
  if (has_shortcut) conv_shortcut.pack(p);
}

void ResnetBlock2D::forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w,
                            const float* temb_silu, float* out, bool x_is_scratch,
                            int64_t out_capacity) const {
  const int64_t hw = h * w;
  ScratchFrame frame(r);
  // t1 = SiLU(GN1(x)), conv1's input (rounded in place on the fp32-kernel bf16 path). It lives
  // until conv1 has run, so it can borrow `out` whenever the shortcut is written after conv1.
  const bool t1_in_out = c_in <= c_out;
  const bool t1_in_x = !t1_in_out && x_is_scratch;
  float* t1 = t1_in_out ? out : t1_in_x ? const_cast<float*>(x) : r.alloc(n * c_in * hw);
  // t2 = conv1 output (+ temb), then SiLU(GN2(.)).
  const int64_t out_n = n * c_out * hw;
  float* t2 = out_capacity < 2 * out_n ? r.alloc(out_n) : r.planning() ? nullptr : out + out_n;
  float* tp = temb > 0 ? r.alloc(c_out) : nullptr;
  const float* residual = has_shortcut ? out : x;
  if (has_shortcut && !t1_in_out)
    conv_shortcut.forward(r, x, n, h, w, out, nullptr, 1, 0, 0, 0, 0);  // out = shortcut(x)
  norm1.forward(r, t1, x, n, hw, /*silu=*/true);
  conv1.forward_scratch(r, t1, n, h, w, t2, nullptr, 1, 1, 1, 1, 1);
  if (temb > 0) {
    MACRO_CHECK(temb_silu != nullptr || r.planning());
    time_emb_proj.forward(r, 1, temb_silu, temb, tp, c_out);  // [Cout]
    if (!r.planning())
      for (int64_t i = 0; i < n; ++i)
        add_channel_broadcast(t2 + i * c_out * hw, t2 + i * c_out * hw, tp, c_out, hw, r.pool);
  }
  if (has_shortcut && t1_in_out)
    conv_shortcut.forward(r, x, n, h, w, out, nullptr, 1, 0, 0, 0, 0);  // out = shortcut(x)
  norm2.forward(r, t2, t2, n, hw, /*silu=*/true);
  conv2.forward_scratch(r, t2, n, h, w, out, residual, 1, 1, 1, 1, 1);  // out = residual + h
}

void ResnetBlock2D::forward_lean(const Run& r, float* x, int64_t h, int64_t w, float* t2,
                                 int64_t band_rows) const {
  MACRO_CHECK(temb == 0 && lean_ok(c_in, c_out) && band_rows >= 1);
  MACRO_CHECK(has_shortcut || t2 != nullptr || r.planning());
  const int64_t hw = h * w, rows = std::min(band_rows, h), band = c_out * rows * w;
  ScratchFrame frame(r);
  GroupNorm::Stats g1;
  norm1.stats(r, x, hw, /*silu=*/true, &g1);
  float* in = r.alloc(c_in * (rows + 2) * w);  // a band's conv input with its halo rows
  if (has_shortcut) {
    // conv1 -> planes [Cout, 2 Cout) of x, shortcut -> planes [0, Cout); band k is written after
    // band k + 1 has read x (its halo row above is band k's last row).
    float* t = r.planning() ? nullptr : x + c_out * hw;
    float* tb[2] = {r.alloc(band), r.alloc(band)};
    float* sb[2] = {r.alloc(band), r.alloc(band)};
    int64_t p0 = -1, p1 = -1, k = 0;
    for (int64_t y0 = 0; y0 < h; y0 += rows, ++k) {
      const int64_t y1 = std::min(h, y0 + rows);
      conv1.forward_rows(r, x, h, w, y0, y1, in, tb[k % 2], nullptr, &g1);
      conv_shortcut.forward_rows(r, x, h, w, y0, y1, in, sb[k % 2], nullptr);
      if (p0 >= 0) {
        scatter_rows(r, t, tb[(k - 1) % 2], c_out, h, w, p0, p1);
        scatter_rows(r, x, sb[(k - 1) % 2], c_out, h, w, p0, p1);
      }
      p0 = y0, p1 = y1;
    }
    scatter_rows(r, t, tb[(k - 1) % 2], c_out, h, w, p0, p1);
    scatter_rows(r, x, sb[(k - 1) % 2], c_out, h, w, p0, p1);
    norm2.forward(r, t, t, 1, hw, /*silu=*/true);
    conv2.forward_scratch(r, t, 1, h, w, x, /*residual=*/x, 1, 1, 1, 1, 1);  // x = shortcut + h
    return;
  }
  // Each band of conv1 goes straight into its rows of t2; conv2 reads its band of SiLU(GN2(t2))
  // through GN2's whole-image statistics and adds into x's rows in place (x is not read again).
  for (int64_t y0 = 0; y0 < h; y0 += rows)
    conv1.forward_rows_into(r, x, h, w, y0, std::min(h, y0 + rows), in, t2, nullptr, &g1);
  GroupNorm::Stats g2;
  norm2.stats(r, t2, hw, /*silu=*/true, &g2);
  for (int64_t y0 = 0; y0 < h; y0 += rows)
    conv2.forward_rows_into(r, t2, h, w, y0, std::min(h, y0 + rows), in, x, /*residual=*/x, &g2);
}

// ---- resampling --------------------------------------------------------------------------------

void Downsample2D::init(int64_t channels, bool vae_pad) {
  conv.init(channels, channels, 3);
  conv.strided = true;
  vae_padding = vae_pad;
}

void Downsample2D::out_size(int64_t h, int64_t w, int64_t* oh, int64_t* ow) const {
  if (vae_padding) {
    *oh = (h + 1 - 3) / 2 + 1;
    *ow = (w + 1 - 3) / 2 + 1;
  } else {
    *oh = (h + 2 - 3) / 2 + 1;
    *ow = (w + 2 - 3) / 2 + 1;
  }
}

void Downsample2D::forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w,
                           float* out) const {
  if (vae_padding)
    conv.forward(r, x, n, h, w, out, nullptr, 2, 0, 0, 1, 1);
  else
    conv.forward(r, x, n, h, w, out, nullptr, 2, 1, 1, 1, 1);
}

void Upsample2D::init(int64_t channels) {
  conv.init(channels, channels, 3);
}

void Upsample2D::pack(Precision p) {
  MACRO_CHECK(conv.weight.loaded() && conv.k == 3 && conv.c_in == conv.c_out);
  const int64_t c = conv.c_in;
  // conv.pack unbinds its params; keep them to read the taps again only if the phases are built
  // (their file pages fault back in).
  const Param weight = conv.weight, bias_param = conv.bias;
  conv.pack(p);
  // The phases only where the conv runs direct: a Winograd conv of the resized image (<= 640
  // channels) is as fast (bench difix --stage decode, 2026-12-07) and needs no second pack.
  if (!conv.packed.winograd().empty()) return;
  std::vector<float> w(size_t(weight.numel())), bias;
  read_param_f32(weight, w.data());  // [C, C, 3, 3]
  release_param(weight);
  if (conv.has_bias) {
    bias.resize(size_t(c));
    read_param_f32(bias_param, bias.data());
    release_param(bias_param);
  }
  // Tap rows (columns) of the 3x3 kernel that fall on 2x2 row (column) r of parity a: [a][r].
  static constexpr int kFirst[2][2] = {{0, 1}, {0, 2}}, kLast[2][2] = {{0, 2}, {1, 2}};
  std::vector<float> k2(size_t(c * c * 4));
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b) {
      for (int64_t o = 0; o < c * c; ++o)
        for (int ry = 0; ry < 2; ++ry)
          for (int rx = 0; rx < 2; ++rx) {
            double sum = 0.0;
            for (int dy = kFirst[a][ry]; dy <= kLast[a][ry]; ++dy)
              for (int dx = kFirst[b][rx]; dx <= kLast[b][rx]; ++dx)
                sum += double(w[size_t(o * 9 + dy * 3 + dx)]);
            k2[size_t(o * 4 + ry * 2 + rx)] = float(sum * double(conv.weight_scale));
          }
      phase[a * 2 + b] =
          ConvWeights::pack(k2.data(), conv.has_bias ? bias.data() : nullptr, c, c, 2, 2,
                            p == Precision::kBf16 ? WeightType::kBf16 : WeightType::kF32,
                            active_isa(), true);
    }
}

size_t Upsample2D::bytes() const {
  size_t n = conv.bytes();
  for (const ConvWeights& cw : phase) n += packed_bytes(cw);
  return n;
}

namespace {

// The four phase convs (Upsample2D): rows of parity a read in[a] ([n, C, rows[a], w]) with
// pad_top[a] / pad_bottom[a] rows of zeros; phase a * 2 + b writes [n, C, out_rows, w] at
// ph + (a * 2 + b) * stride. bf16 on the fp32 kernel: the inputs are rounded in place first, as
// the resized copy would be (in[1] may be in[0]).
void run_phases(const Run& r, const ConvWeights (&phase)[4], float* const (&in)[2],
                const int64_t (&rows)[2], const int (&pad_top)[2], const int (&pad_bottom)[2],
                int64_t n, int64_t c, int64_t w, int64_t out_rows, float* ph, int64_t stride) {
  op_profile::OpScope prof("conv 3x3 upsample (2x2 phases)",
                           2.0 * double(n * 4 * out_rows * w) * double(c * c) * 4.0);
  if (phase[0].type() != WeightType::kBf16) {
    round_if_bf16(r, in[0], n * c * rows[0] * w);
    if (in[1] != in[0]) round_if_bf16(r, in[1], n * c * rows[1] * w);
  }
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b) {
      Conv2dShape s;
      s.n = n, s.c_in = c, s.h = rows[a], s.w = w, s.c_out = c, s.kh = 2, s.kw = 2;
      s.stride = 1;
      s.pad_top = pad_top[a], s.pad_bottom = pad_bottom[a], s.pad_left = 1 - b, s.pad_right = b;
      conv2d(s, in[a], phase[a * 2 + b], nullptr, ph + (a * 2 + b) * stride, r.pool);
    }
}

// Interleave the phases (run_phases' layout, `planes` planes of `rows` x w each) into rows
// 2 (row0 + i) + a, columns 2 j + b of y's planes (y_plane floats apart, 2w wide).
void interleave_phases(const Run& r, const float* ph, int64_t stride, int64_t planes,
                       int64_t rows, int64_t w, float* y, int64_t y_plane, int64_t row0) {
  op_profile::OpScope prof("copy");
  parallel(r, size_t(planes), [&](size_t b0, size_t b1) {
    for (size_t pc = b0; pc < b1; ++pc)
      for (int64_t i = 0; i < rows; ++i)
        for (int a = 0; a < 2; ++a) {
          const float* p0 = ph + (a * 2) * stride + (int64_t(pc) * rows + i) * w;
          const float* p1 = p0 + stride;
          float* d = y + int64_t(pc) * y_plane + (2 * (row0 + i) + a) * 2 * w;
          for (int64_t j = 0; j < w; ++j) {
            d[2 * j] = p0[j];
            d[2 * j + 1] = p1[j];
          }
        }
  });
}

// y [n, C, 2h, 2w] from x [n, C, h, w] (y may be x: x is read only by the convs); ph holds 4 x
// [n, C, h, w].
void upsample_phases(const Run& r, const ConvWeights (&phase)[4], float* x, int64_t n, int64_t c,
                     int64_t h, int64_t w, float* ph, float* y) {
  if (r.planning()) return;
  float* const in[2] = {x, x};
  const int64_t rows[2] = {h, h};
  const int pad_top[2] = {1, 0}, pad_bottom[2] = {0, 1};
  const int64_t stride = n * c * h * w;
  run_phases(r, phase, in, rows, pad_top, pad_bottom, n, c, w, h, ph, stride);
  interleave_phases(r, ph, stride, n * c, h, w, y, 4 * h * w, 0);
}

}  // namespace

void Upsample2D::forward(const Run& r, const float* x, int64_t n, int64_t c, int64_t h, int64_t w,
                         int64_t oh, int64_t ow, float* out) const {
  ScratchFrame frame(r);
  float* t = r.alloc(n * c * oh * ow);
  if (phased(c, h, w, oh, ow)) {
    float* xs = const_cast<float*>(x);  // only read, unless the rounding below needs a copy
    if (r.bf16() && phase[0].type() != WeightType::kBf16) {
      xs = r.alloc(n * c * h * w);
      copy_floats(r, xs, x, n * c * h * w);
    }
    upsample_phases(r, phase, xs, n, c, h, w, t, out);
    return;
  }
  if (!r.planning()) upsample_nearest(t, x, n * c, h, w, oh, ow, r.pool);
  conv.forward_scratch(r, t, n, oh, ow, out, nullptr, 1, 1, 1, 1, 1);
}

void Upsample2D::forward_in_place(const Run& r, float* x, int64_t n, int64_t c, int64_t h,
                                  int64_t w, int64_t oh, int64_t ow, float* tmp) const {
  if (phased(c, h, w, oh, ow)) {
    upsample_phases(r, phase, x, n, c, h, w, tmp, x);
    return;
  }
  if (!r.planning()) upsample_nearest(tmp, x, n * c, h, w, oh, ow, r.pool);
  conv.forward_scratch(r, tmp, n, oh, ow, x, nullptr, 1, 1, 1, 1, 1);
}

void Upsample2D::forward_lean(const Run& r, const float* x, int64_t c, int64_t h, int64_t w,
                              int64_t oh, int64_t ow, float* out, int64_t band_rows) const {
  MACRO_CHECK(band_rows >= 1 && h > 0 && w > 0);
  if (phased(c, h, w, oh, ow)) {
    // Bands of lb input rows [i0, i1) -> output rows [2 i0, 2 i1): row parity 0 reads input rows
    // [i0 - 1, i1), parity 1 rows [i0, i1 + 1) (clipped; the image's edge is the conv's padding),
    // each gathered into its own buffer; the four phase outputs then interleave into out.
    const int64_t lb = std::max<int64_t>(1, std::min(band_rows, oh) / 2);
    ScratchFrame frame(r);
    float* const in[2] = {r.alloc(c * (lb + 1) * w), r.alloc(c * (lb + 1) * w)};
    float* ph = r.alloc(4 * c * lb * w);
    if (r.planning()) return;
    for (int64_t i0 = 0; i0 < h; i0 += lb) {
      const int64_t i1 = std::min(h, i0 + lb), nb = i1 - i0;
      const int64_t first[2] = {std::max<int64_t>(0, i0 - 1), i0};
      const int64_t count[2] = {i1 - first[0], std::min(h, i1 + 1) - i0};
      const int pad_top[2] = {i0 == 0 ? 1 : 0, 0}, pad_bottom[2] = {0, i1 == h ? 1 : 0};
      for (int a = 0; a < 2; ++a)
        parallel(r, size_t(c), [&](size_t b0, size_t b1) {
          for (size_t ch = b0; ch < b1; ++ch)
            std::memcpy(in[a] + int64_t(ch) * count[a] * w, x + (int64_t(ch) * h + first[a]) * w,
                        size_t(count[a] * w) * sizeof(float));
        });
      run_phases(r, phase, in, count, pad_top, pad_bottom, 1, c, w, nb, ph, c * nb * w);
      interleave_phases(r, ph, c * nb * w, c, nb, w, out, oh * ow, i0);
    }
    return;
  }
  const int64_t rows = std::min(band_rows, oh);
  ScratchFrame frame(r);
  float* in = r.alloc(c * (rows + 2) * ow);
  if (r.planning()) return;
  const bool twice = ow == 2 * w;
  for (int64_t y0 = 0; y0 < oh; y0 += rows) {
    const int64_t y1 = std::min(oh, y0 + rows);
    const int64_t iy0 = std::max<int64_t>(0, y0 - 1), iy1 = std::min(oh, y1 + 1);
    const int64_t n = iy1 - iy0;
    // Nearest rows, with ops.cpp's upsample_nearest source index floor(y * h / oh).
    parallel(r, size_t(c), [&](size_t b, size_t e) {
      for (size_t ch = b; ch < e; ++ch)
        for (int64_t y = iy0; y < iy1; ++y) {
          const float* src = x + (int64_t(ch) * h + std::min(h - 1, y * h / oh)) * w;
          float* d = in + (int64_t(ch) * n + (y - iy0)) * ow;
          if (twice) {
            for (int64_t i = 0; i < w; ++i) d[2 * i] = d[2 * i + 1] = src[i];
          } else {
            for (int64_t i = 0; i < ow; ++i) d[i] = src[std::min(w - 1, i * w / ow)];
          }
        }
    });
    conv.forward_scratch(r, in, 1, n, ow, out + y0 * ow, nullptr, 1, int(1 - (y0 - iy0)), 1,
                         int(1 - (iy1 - y1)), 1, y0, oh * ow);  // straight into out's rows
  }
}

// ---- VAE attention -----------------------------------------------------------------------------

void VaeAttention::init(int64_t channels, int groups, float eps) {
  c = channels;
  group_norm.init(channels, groups, eps);
  to_q.init(c, c, true);
  to_k.init(c, c, true);
  to_v.init(c, c, true);
  to_out.init(c, c, true);
}

void VaeAttention::visit(const std::string& prefix, ParamVisitor& v) {
  group_norm.visit(join_name(prefix, "group_norm"), v);
  to_q.visit(join_name(prefix, "to_q"), v);
  to_k.visit(join_name(prefix, "to_k"), v);
  to_v.visit(join_name(prefix, "to_v"), v);
  to_out.visit(join_name(prefix, "to_out.0"), v);
}

void VaeAttention::pack(Precision p) {
  group_norm.pack();
  qkv.pack({&to_q, &to_k, &to_v}, p);
  to_q = Linear();
  to_k = Linear();
  to_v = Linear();
  to_out.pack(p);
}

void VaeAttention::forward(const Run& r, float* x, int64_t n, int64_t hw) const {
  ScratchFrame frame(r);
  float* g = r.alloc(n * c * hw);  // GN(x), NCHW
  float* q = r.alloc(hw * 3 * c);  // [HW, 3C] q | k | v of one item
  float* a = r.alloc(hw * c);      // attention output [HW, C]
  float* o = r.alloc(hw * c);      // to_out [HW, C]
  group_norm.forward(r, g, x, n, hw, false);
  for (int64_t i = 0; i < n; ++i) {
    qkv.forward(r, hw, g + i * c * hw, hw, q, 3 * c, /*trans_x=*/true);
    round_if_bf16(r, q, hw * 3 * c);
    AttentionArgs args = packed_qkv_attention(q, a, hw, c, /*heads=*/1);
    args.scale = float(1.0 / std::sqrt(double(c)));
    run_attention(r, args);
    to_out.forward(r, hw, a, c, o, c);
    tokens_to_nchw_add(r, x + i * c * hw, x + i * c * hw, o, c, 1, c, hw);
  }
}

}  // namespace macro::nets
