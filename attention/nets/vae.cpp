// The Difix VAE (see vae.h): module tree, weight walk, encode with skips, decode with skip adds.
//
// Legend (the letters of vae.h): N images (views; encode_impl / decode_impl run one image, so
// their shapes drop the N), C channels, C_i = block_out_channels[i] (Difix: 128, 256, 512, 512),
// n levels (4), Cin / Cout image channels (3), H x W image, H_i x W_i = H/2^i x W/2^i (encoder
// level i, decoder up block n-1-i), h x w = H_{n-1} x W_{n-1} latent (H/8 x W/8), L latent
// channels (4; the moments have 2L), K images whose skips are kept, Cs a skip's channels, HW
// tokens of the mid attention (one head of C). S_i, the skip entering encoder down block i:
// S_0 [C_0, H, W], S_i [C_{i-1}, H_i, W_i] (Difix: [128, H, W], [128, H/2, W/2],
// [256, H/4, W/4], [512, H/8, W/8]). Activations are NCHW.
#include "attention/nets/vae.h"

#include <algorithm>

#include "attention/runtime/ops.h"

namespace macro::nets {
namespace {
constexpr float kVaeEps = 1e-6f;  // every VAE GroupNorm (docs/spec/difix-spec.md §5 item 1)
}

void VaeBlock::visit(const std::string& prefix, ParamVisitor& v) {
  for (size_t j = 0; j < resnets.size(); ++j)
    resnets[j].visit(join_name(prefix, "resnets." + std::to_string(j)), v);
  if (has_down) downsampler.visit(join_name(prefix, "downsamplers.0"), v);
  if (has_up) upsampler.visit(join_name(prefix, "upsamplers.0"), v);
}

void VaeBlock::pack(Precision p) {
  for (auto& rb : resnets) rb.pack(p);
  if (has_down) downsampler.pack(p);
  if (has_up) upsampler.pack(p);
}

void VaeMidBlock::init(int64_t c, int groups) {
  resnet0.init(c, c, 0, groups, kVaeEps);
  resnet1.init(c, c, 0, groups, kVaeEps);
  attention.init(c, groups, kVaeEps);
}

void VaeMidBlock::visit(const std::string& prefix, ParamVisitor& v) {
  resnet0.visit(join_name(prefix, "resnets.0"), v);
  attention.visit(join_name(prefix, "attentions.0"), v);
  resnet1.visit(join_name(prefix, "resnets.1"), v);
}

void VaeMidBlock::pack(Precision p) {
  resnet0.pack(p);
  attention.pack(p);
  resnet1.pack(p);
}

void VaeMidBlock::forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w, float* a,
                          float* out) const {
  resnet0.forward(r, x, n, h, w, nullptr, a);    // a [N, C, H, W]
  attention.forward(r, a, n, h * w);             // in place; tokens [HW, C] per image
  resnet1.forward(r, a, n, h, w, nullptr, out);  // out [N, C, H, W]
}

int64_t DifixVae::skip_channels(int i) const {
  const auto& boc = cfg_.block_out_channels;
  return i == 0 ? boc[0] : boc[size_t(i - 1)];
}

Result<std::unique_ptr<DifixVae>> DifixVae::build(const VaeConfig& cfg) {
  auto m = std::make_unique<DifixVae>();
  m->cfg_ = cfg;
  const auto& boc = cfg.block_out_channels;
  const int n = int(boc.size());
  const int g = cfg.norm_num_groups;
  for (int c : boc)
    if (c % g != 0)
      return Status::error("VAE config: block_out_channels " + std::to_string(c) +
                           " is not a multiple of norm_num_groups " + std::to_string(g));
  if (boc.back() > attention_detail::kMaxHeadDim)
    return Status::error("VAE config: mid attention width " + std::to_string(boc.back()) +
                         " exceeds the attention kernel's head dim limit " +
                         std::to_string(attention_detail::kMaxHeadDim));
  const int64_t lat = cfg.latent_channels;
  // Encoder.
  m->enc_conv_in.init(cfg.in_channels, boc[0], 3);
  m->down_blocks.resize(size_t(n));
  int64_t out = boc[0];
  for (int i = 0; i < n; ++i) {
    VaeBlock& b = m->down_blocks[size_t(i)];
    b.c_in = out;
    out = boc[size_t(i)];
    b.c_out = out;
    b.resnets.resize(size_t(cfg.layers_per_block));
    for (int j = 0; j < cfg.layers_per_block; ++j)
      b.resnets[size_t(j)].init(j == 0 ? b.c_in : out, out, 0, g, kVaeEps);
    b.has_down = i + 1 < n;
    if (b.has_down) b.downsampler.init(out, /*vae_pad=*/true);
  }
  m->enc_mid.init(boc.back(), g);
  m->enc_norm_out.init(boc.back(), g, kVaeEps);
  m->enc_conv_out.init(boc.back(), 2 * lat, 3);
  m->quant_conv.init(2 * lat, 2 * lat, 1);
  // Decoder.
  m->post_quant_conv.init(lat, lat, 1);
  m->dec_conv_in.init(lat, boc.back(), 3);
  m->dec_mid.init(boc.back(), g);
  std::vector<int> rev(boc.rbegin(), boc.rend());
  m->up_blocks.resize(size_t(n));
  m->skip_convs.resize(size_t(n));
  out = rev[0];
  for (int i = 0; i < n; ++i) {
    VaeBlock& b = m->up_blocks[size_t(i)];
    b.c_in = out;
    Conv2d& sc = m->skip_convs[size_t(i)];
    sc.init(m->skip_channels(n - 1 - i), b.c_in, 1, /*bias=*/false);
    sc.weight_scale = float(cfg.gamma);
    out = rev[size_t(i)];
    b.c_out = out;
    b.resnets.resize(size_t(cfg.layers_per_block + 1));
    for (int j = 0; j <= cfg.layers_per_block; ++j)
      b.resnets[size_t(j)].init(j == 0 ? b.c_in : out, out, 0, g, kVaeEps);
    b.has_up = i + 1 < n;
    if (b.has_up) b.upsampler.init(out);
  }
  m->dec_norm_out.init(boc[0], g, kVaeEps);
  m->dec_conv_out.init(boc[0], cfg.out_channels, 3);
  return m;
}

void DifixVae::visit(ParamVisitor& v) {
  enc_conv_in.visit("encoder.conv_in", v);
  for (size_t i = 0; i < down_blocks.size(); ++i)
    down_blocks[i].visit("encoder.down_blocks." + std::to_string(i), v);
  enc_mid.visit("encoder.mid_block", v);
  enc_norm_out.visit("encoder.conv_norm_out", v);
  enc_conv_out.visit("encoder.conv_out", v);
  quant_conv.visit("quant_conv", v);
  post_quant_conv.visit("post_quant_conv", v);
  dec_conv_in.visit("decoder.conv_in", v);
  dec_mid.visit("decoder.mid_block", v);
  for (size_t i = 0; i < up_blocks.size(); ++i)
    up_blocks[i].visit("decoder.up_blocks." + std::to_string(i), v);
  if (cfg_.has_skip_convs)
    for (size_t i = 0; i < skip_convs.size(); ++i)
      skip_convs[i].visit("decoder.skip_conv_" + std::to_string(i + 1), v);
  dec_norm_out.visit("decoder.conv_norm_out", v);
  dec_conv_out.visit("decoder.conv_out", v);
}

void DifixVae::pack(Precision p) {
  precision_ = p;
  enc_conv_in.pack(p);
  for (auto& b : down_blocks) b.pack(p);
  enc_mid.pack(p);
  enc_norm_out.pack();
  enc_conv_out.pack(p);
  quant_conv.pack(p);
  post_quant_conv.pack(p);
  dec_conv_in.pack(p);
  dec_mid.pack(p);
  for (auto& b : up_blocks) b.pack(p);
  if (cfg_.has_skip_convs)
    for (auto& s : skip_convs) s.pack(p);
  dec_norm_out.pack();
  dec_conv_out.pack(p);
}

size_t DifixVae::weight_bytes() const {
  size_t n = enc_conv_in.bytes() + enc_conv_out.bytes() + quant_conv.bytes() + enc_mid.bytes() +
             enc_norm_out.bytes() + post_quant_conv.bytes() + dec_conv_in.bytes() +
             dec_conv_out.bytes() + dec_mid.bytes() + dec_norm_out.bytes();
  for (const auto& b : down_blocks) n += b.bytes();
  for (const auto& b : up_blocks) n += b.bytes();
  for (const auto& s : skip_convs) n += s.bytes();
  return n;
}

Result<std::unique_ptr<DifixVae>> DifixVae::load(const std::string& folder, Precision precision) {
  MACRO_ASSIGN_OR_RETURN(VaeConfig cfg, load_vae_config(folder + "/config.json"));
  MACRO_ASSIGN_OR_RETURN(std::string weights, component_weights_path(folder));
  MACRO_ASSIGN_OR_RETURN(auto model, build(cfg));
  WeightStoreOptions opt;
  opt.lora_scale = cfg.lora_rank > 0 ? cfg.lora_scale : 0.0;  // merged when its module packs
  MACRO_TRY(load_weights(*model, weights, opt, precision));
  return model;
}

// ---- encode ------------------------------------------------------------------------------------

int64_t DifixVae::band_rows(int64_t width) const {
  if (band_rows_ >= 0) return band_rows_;
  return std::max<int64_t>(4, kBandPixels / std::max<int64_t>(1, width));
}

namespace {

// dst (bf16) = RNE(src), by chunks on the run's pool.
void store_bf16(const Run& r, uint16_t* dst, const float* src, int64_t n) {
  if (r.planning()) return;
  constexpr int64_t kChunk = 1 << 16;
  const int64_t chunks = (n + kChunk - 1) / kChunk;
  auto fn = [&](size_t b, size_t e, int) {
    for (size_t c = b; c < e; ++c) {
      const int64_t lo = int64_t(c) * kChunk, hi = std::min(n, lo + kChunk);
      f32_to_bf16(src + lo, dst + lo, hi - lo);
    }
  };
  if (r.pool && r.pool->size() > 1)
    r.pool->parallel_for(size_t(chunks), fn, 1);
  else
    fn(0, size_t(chunks), 0);
}

}  // namespace

void DifixVae::encode_impl(const Run& r, const float* x, int64_t h, int64_t w, float* moments,
                           const std::vector<SkipOut>& skip_out) const {
  // One image: x [Cin, H, W] (this h, w are the image's H, W) -> moments [2L, H/8, W/8];
  // skip_out[i] receives S_i.
  const int n = levels();
  const auto& boc = cfg_.block_out_channels;
  // Ping-pong buffers for the largest level activation: max over i of [max(c_in, c_out), H_i, W_i].
  int64_t max_act = 0;
  {
    int64_t hh = h, ww = w;
    for (int i = 0; i < n; ++i) {
      const VaeBlock& b = down_blocks[size_t(i)];
      max_act = std::max(max_act, std::max(b.c_in, b.c_out) * hh * ww);
      if (b.has_down) b.downsampler.out_size(hh, ww, &hh, &ww);
    }
  }
  // Banded full-resolution level: its resnets need x and t2 only (both fit the ping-pong pair).
  const int64_t rows = band_rows(w);
  bool lean = rows > 0;
  for (const ResnetBlock2D& rb : down_blocks[0].resnets)
    lean = lean && rb.c_in == rb.c_out && rb.temb == 0;
  float* buf[2] = {r.alloc(max_act), r.alloc(max_act)};
  auto other = [&](const float* cur) { return cur == buf[0] ? buf[1] : buf[0]; };
  int64_t hh = h, ww = w, cc = boc[0];
  float* cur = skip_out[0].f32 ? skip_out[0].f32 : buf[0];
  enc_conv_in.forward_same(r, x, 1, hh, ww, cur);  // S_0: [Cin, H, W] -> [C_0, H, W]
  if (skip_out[0].bf16) store_bf16(r, skip_out[0].bf16, cur, cc * hh * ww);
  for (int i = 0; i < n; ++i) {  // cur = S_i (hh x ww = H_i x W_i)
    const VaeBlock& b = down_blocks[size_t(i)];
    if (i == 0 && lean) {
      if (cur != buf[0] && cur != buf[1]) {  // S_0 is the caller's skip: work on a copy
        copy_floats(r, buf[0], cur, cc * hh * ww);
        cur = buf[0];
      }
      // [C_0, H, W] in place, by bands (t2 [C_0, H, W] in the other buffer)
      for (const ResnetBlock2D& rb : b.resnets) rb.forward_lean(r, cur, hh, ww, other(cur), rows);
    } else {
      for (const ResnetBlock2D& rb : b.resnets) {
        float* o = other(cur);
        // [rb.c_in, H_i, W_i] -> o [C_i, H_i, W_i]
        rb.forward(r, cur, 1, hh, ww, nullptr, o, /*x_is_scratch=*/false,
                   /*out_capacity=*/lean ? max_act : 0);
        cur = o;
        cc = rb.c_out;
      }
    }
    if (b.has_down) {  // pad right/bottom 1, stride 2: [C_i, H_i, W_i] -> [C_i, H_i/2, W_i/2]
      int64_t oh, ow;
      b.downsampler.out_size(hh, ww, &oh, &ow);
      const SkipOut& so = skip_out[size_t(i + 1)];
      float* o = so.f32 ? so.f32 : other(cur);  // S_{i+1} [C_i, H_{i+1}, W_{i+1}]
      b.downsampler.forward(r, cur, 1, hh, ww, o);
      cur = o;
      hh = oh, ww = ow;
      if (so.bf16) store_bf16(r, so.bf16, cur, cc * hh * ww);
    }
  }
  // Here hh x ww = h x w (H/8 x W/8) and cur [C_{n-1}, h, w] ([512, h, w]).
  float* a = other(cur);
  float* mid = r.alloc(cc * hh * ww);                          // [C_{n-1}, h, w]
  enc_mid.forward(r, cur, 1, hh, ww, a, mid);                  // [C_{n-1}, h, w]
  enc_norm_out.forward(r, a, mid, 1, hh * ww, /*silu=*/true);  // a [C_{n-1}, h, w]
  float* e = r.alloc(2 * cfg_.latent_channels * hh * ww);      // [2L, h, w]
  // 3x3: a [C_{n-1}, h, w] -> e [2L, h, w]; 1x1: moments [2L, h, w] = mean [L] | logvar [L]
  enc_conv_out.forward_scratch(r, a, 1, hh, ww, e, nullptr, 1, 1, 1, 1, 1);
  quant_conv.forward_scratch(r, e, 1, hh, ww, moments, nullptr, 1, 0, 0, 0, 0);
}

size_t DifixVae::encode_workspace_bytes(int64_t h, int64_t w) const {
  Workspace plan;
  encode_impl(Run{&plan, nullptr, precision_}, nullptr, h, w, nullptr,
              std::vector<SkipOut>(size_t(levels())));
  return plan.peak();
}

size_t DifixVae::decode_workspace_bytes(int64_t h, int64_t w) const {
  Workspace plan;
  decode_impl(Run{&plan, nullptr, precision_}, nullptr, h / downscale(), w / downscale(),
              std::vector<SkipIn>(size_t(levels())), nullptr);
  return plan.peak();
}

Result<VaeEncoding> DifixVae::encode(const TensorView& images, int64_t keep_skips, ThreadPool* pool,
                                     Arena* arena, bool bf16_skips) const {
  const int64_t f = downscale();
  if (images.dtype != DType::kF32 || images.rank != 4 || !images.is_contiguous() ||
      images.dim(1) != cfg_.in_channels || images.dim(0) < 1 || images.dim(2) < f ||
      images.dim(3) < f || images.dim(2) % f || images.dim(3) % f)
    return Status::error("vae: images: expected contiguous F32 [N," +
                         std::to_string(cfg_.in_channels) +
                         ",H,W] with H, W positive multiples of " + std::to_string(f) + ", found " +
                         images.describe());
  const int64_t n = images.dim(0), H = images.dim(2), W = images.dim(3);
  if (keep_skips < 0 || keep_skips > n) return Status::error("vae: keep_skips out of range");
  if (bf16_skips && precision_ != Precision::kBf16)
    return Status::error("vae: bf16 skips need a bf16 model, this one is " +
                         std::string(precision_name(precision_)));
  const int64_t h = H / f, w = W / f, lat = cfg_.latent_channels;  // images [N, Cin, H, W]
  VaeEncoding enc;
  enc.moments = Tensor::f32({n, 2 * lat, h, w});  // [N, 2L, h, w]
  enc.z = Tensor::f32({n, lat, h, w});            // [N, L, h, w]
  {
    int64_t hh = H, ww = W;
    for (int i = 0; i < levels(); ++i) {
      const Shape shape{keep_skips, skip_channels(i), hh, ww};  // S_i [K, Cs, H_i, W_i]
      enc.skips.push_back(bf16_skips ? Tensor(DType::kBF16, shape) : Tensor::f32(shape));
      if (down_blocks[size_t(i)].has_down)
        down_blocks[size_t(i)].downsampler.out_size(hh, ww, &hh, &ww);
    }
  }
  auto skip_ptrs = [&](int64_t img) {
    std::vector<SkipOut> p(static_cast<size_t>(levels()));
    if (img < keep_skips)
      for (int i = 0; i < levels(); ++i) {
        Tensor& s = enc.skips[size_t(i)];
        const int64_t off = img * (s.numel() / keep_skips);  // image img's S_i [Cs, H_i, W_i]
        if (bf16_skips)
          p[size_t(i)].bf16 = s.view().u16() + off;
        else
          p[size_t(i)].f32 = s.f32() + off;
      }
    return p;
  };
  Workspace plan;
  encode_impl(Run{&plan, pool, precision_}, nullptr, H, W, nullptr,
              std::vector<SkipOut>(size_t(levels())));
  Arena local;
  Arena& a = prepare_arena(arena, local, plan.peak());
  const int64_t in_img = cfg_.in_channels * H * W;  // one image [Cin, H, W]
  for (int64_t img = 0; img < n; ++img) {
    Workspace ws(&a);
    encode_impl(Run{&ws, pool, precision_}, images.f32() + img * in_img, H, W,
                enc.moments.f32() + img * 2 * lat * h * w, skip_ptrs(img));
    a.reset();
  }
  // z = scaling * mean (first L channels of the moments): [N, L, h, w] from [N, 2L, h, w].
  const float s = float(cfg_.scaling_factor);
  for (int64_t img = 0; img < n; ++img)
    scale(enc.z.f32() + img * lat * h * w, enc.moments.f32() + img * 2 * lat * h * w, s,
          lat * h * w, nullptr);
  return enc;
}

// ---- decode ------------------------------------------------------------------------------------

void DifixVae::add_skip(const Run& r, const Conv2d& sc, const SkipIn& s, int64_t hh, int64_t ww,
                        float* h) const {
  // h [C, hh, ww] += 1x1 conv of S [Cs, hh, ww] (C = sc.c_out, Cs = sc.c_in).
  if (!s.bf16) {  // h += skip_conv(S): the residual is h itself
    sc.forward(r, s.f32, 1, hh, ww, h, /*residual=*/h, 1, 0, 0, 0, 0);
    return;
  }
  // bf16 skips, widened by row bands (the 1x1 conv rounds them back to the same bf16 values).
  const int64_t rows = std::max<int64_t>(1, band_rows(ww) > 0 ? band_rows(ww) : hh);
  const int64_t bh = std::min(rows, hh);
  ScratchFrame frame(r);
  float* in = r.alloc(sc.c_in * bh * ww);   // band of S widened [Cs, bh, ww]
  float* yb = r.alloc(sc.c_out * bh * ww);  // band of h [C, bh, ww]
  if (r.planning()) return;
  for (int64_t y0 = 0; y0 < hh; y0 += bh) {
    const int64_t y1 = std::min(hh, y0 + bh), n = (y1 - y0) * ww;
    for (int64_t c = 0; c < sc.c_in; ++c)
      bf16_to_f32(s.bf16 + c * hh * ww + y0 * ww, in + c * n, n);
    gather_rows(r, yb, h, sc.c_out, hh, ww, y0, y1);
    sc.forward_scratch(r, in, 1, y1 - y0, ww, yb, /*residual=*/yb, 1, 0, 0, 0, 0);
    scatter_rows(r, h, yb, sc.c_out, hh, ww, y0, y1);
  }
}

void DifixVae::decode_impl(const Run& r, const float* z, int64_t h, int64_t w,
                           const std::vector<SkipIn>& skips, float* out) const {
  // One image: z [L, h, w] (this h, w are the latent's) with S_i [Cs, H_i, W_i]
  // -> out [Cout, H, W], H = h*2^(n-1). Up block i runs at H_{n-1-i} x W_{n-1-i} = h*2^i x w*2^i,
  // in channels C_{n-i} (C_{n-1} for i = 0), out C_{n-1-i}: Difix 512 -> 512 @ h,
  // 512 -> 512 @ 2h, 512 -> 256 @ 4h, 256 -> 128 @ 8h = H.
  const int n = levels();
  const int64_t lat = cfg_.latent_channels;
  // Banded full-resolution level (the last): the transition upsample goes by bands from a copy
  // of its input into the level's one buffer R, whose resnets then need x and t2 only (x alone
  // with a shortcut); the lower levels ping-pong in R's two halves.
  const int64_t rows = band_rows(w << (n - 1));
  bool lean = rows > 0 && n >= 2;
  for (const ResnetBlock2D& rb : up_blocks[size_t(n - 1)].resnets)
    lean = lean && ResnetBlock2D::lean_ok(rb.c_in, rb.c_out) && rb.temb == 0;
  int64_t max_act = 0;  // lean: without the full-resolution level
  {
    int64_t hh = h, ww = w;
    for (int i = 0; i < n; ++i) {
      const VaeBlock& b = up_blocks[size_t(i)];
      if (!(lean && i == n - 1)) max_act = std::max(max_act, std::max(b.c_in, b.c_out) * hh * ww);
      if (b.has_up) hh *= 2, ww *= 2;
      if (!(lean && i == n - 2)) max_act = std::max(max_act, b.c_out * hh * ww);
    }
  }
  float* buf[2];
  if (lean) {
    const VaeBlock& last = up_blocks[size_t(n - 1)];
    const int64_t full = (h << (n - 1)) * (w << (n - 1));  // H*W
    // R holds the lower levels' two max_act halves, then [last.c_in, H, W] ([256, H, W]), then
    // the result and t2, 2 x [last.c_out, H, W] (2 x [128, H, W]).
    const int64_t region = std::max({2 * max_act, last.c_in * full, 2 * last.c_out * full});
    buf[0] = r.alloc(region);
    buf[1] = r.planning() ? nullptr : buf[0] + max_act;
  } else {
    buf[0] = r.alloc(max_act);
    buf[1] = r.alloc(max_act);
  }
  auto other = [&](const float* cur) { return cur == buf[0] ? buf[1] : buf[0]; };
  float* d = r.alloc(lat * h * w);  // [L, h, w]
  float* p = r.alloc(lat * h * w);  // [L, h, w]
  if (!r.planning()) scale(d, z, float(1.0 / cfg_.scaling_factor), lat * h * w, nullptr);
  post_quant_conv.forward_scratch(r, d, 1, h, w, p, nullptr, 1, 0, 0, 0, 0);  // 1x1 [L, h, w]
  float* cur = buf[0];
  dec_conv_in.forward_scratch(r, p, 1, h, w, cur, nullptr, 1, 1, 1, 1, 1);  // [C_{n-1}, h, w]
  dec_mid.forward(r, cur, 1, h, w, other(cur), cur);  // in place: x is dead after resnet0
  int64_t hh = h, ww = w, cc = up_blocks[0].c_in;     // cur [C_{n-1}, h, w] ([512, h, w])
  for (int i = 0; i < n; ++i) {
    const VaeBlock& b = up_blocks[size_t(i)];  // hh x ww = H_{n-1-i} x W_{n-1-i}
    // h += skip_conv_{i+1}(gamma * S_{n-1-i}); gamma is in the weights
    // cur [b.c_in, hh, ww] += 1x1 conv of S_{n-1-i} [Cs, hh, ww]
    if (!cfg_.ignore_skip)
      add_skip(r, skip_convs[size_t(i)], skips[size_t(n - 1 - i)], hh, ww, cur);
    if (lean && i == n - 1) {
      for (const ResnetBlock2D& rb : b.resnets) {  // [rb.c_in, H, W] -> [rb.c_out, H, W]
        MACRO_CHECK(cur == buf[0]);
        // Without a shortcut, t2 [rb.c_out, H, W] goes right behind the result in R.
        float* t2 = rb.has_shortcut || r.planning() ? nullptr : cur + rb.c_out * hh * ww;
        rb.forward_lean(r, cur, hh, ww, t2, rows);  // the result replaces x
        cc = rb.c_out;
      }
      break;
    }
    for (const ResnetBlock2D& rb : b.resnets) {
      float* o = other(cur);
      // At the full-resolution level the ping-pong buffers (sized for the widest upsampled
      // tensor) have room for conv1's output behind the block output.
      // [rb.c_in, hh, ww] -> o [C_{n-1-i}, hh, ww]
      rb.forward(r, cur, 1, hh, ww, nullptr, o, /*x_is_scratch=*/true, /*out_capacity=*/max_act);
      cur = o;
      cc = rb.c_out;
    }
    // Upsample (nearest x2, 3x3 conv): [C_{n-1-i}, hh, ww] -> [C_{n-1-i}, 2 hh, 2 ww]
    if (b.has_up && lean && i == n - 2) {  // into R by bands, from a copy of the input
      ScratchFrame frame(r);
      float* src = r.alloc(cc * hh * ww);  // [C, H/2, W/2]
      copy_floats(r, src, cur, cc * hh * ww);
      b.upsampler.forward_lean(r, src, cc, hh, ww, 2 * hh, 2 * ww, buf[0], rows);
      cur = buf[0];
      hh *= 2, ww *= 2;
    } else if (b.has_up) {  // both ping-pong buffers hold max_act: resize into the other one
      MACRO_CHECK(cur == buf[0] || cur == buf[1]);
      b.upsampler.forward_in_place(r, cur, 1, cc, hh, ww, 2 * hh, 2 * ww, other(cur));
      hh *= 2, ww *= 2;
    }
  }
  // Here cur [C_0, H, W] ([128, H, W]); out [Cout, H, W].
  if (lean) {  // in place: GroupNorm reads each group whole before writing it
    dec_norm_out.forward(r, cur, cur, 1, hh * ww, /*silu=*/true);                  // [C_0, H, W]
    dec_conv_out.forward_scratch(r, cur, 1, hh, ww, out, nullptr, 1, 1, 1, 1, 1);  // [Cout, H, W]
    return;
  }
  float* t = other(cur);
  dec_norm_out.forward(r, t, cur, 1, hh * ww, /*silu=*/true);                  // [C_0, H, W]
  dec_conv_out.forward_scratch(r, t, 1, hh, ww, out, nullptr, 1, 1, 1, 1, 1);  // [Cout, H, W]
}

Result<Tensor> DifixVae::decode(const TensorView& z, const std::vector<TensorView>& skips,
                                ThreadPool* pool, Arena* arena) const {
  const int64_t lat = cfg_.latent_channels, f = downscale();
  if (z.dtype != DType::kF32 || z.rank != 4 || !z.is_contiguous() || z.dim(0) != 1 ||
      z.dim(1) != lat || z.dim(2) < 1 || z.dim(3) < 1)
    return Status::error("vae: z: expected contiguous F32 [1," + std::to_string(lat) +
                         ",h,w], found " + z.describe());
  const int64_t h = z.dim(2), w = z.dim(3);  // z [1, L, h, w]
  if (int(skips.size()) != levels())
    return Status::error("vae: expected " + std::to_string(levels()) + " skip tensors, found " +
                         std::to_string(skips.size()));
  const bool bf16_ok = precision_ == Precision::kBf16;
  std::vector<SkipIn> ptrs;
  for (int i = 0; i < levels(); ++i) {
    const TensorView& s = skips[size_t(i)];
    const int64_t scale_i = f >> i;  // S_i [1, Cs, H/2^i, W/2^i] = [1, Cs, h*scale_i, w*scale_i]
    const bool dtype_ok = s.dtype == DType::kF32 || (bf16_ok && s.dtype == DType::kBF16);
    if (!dtype_ok || s.rank != 4 || !s.is_contiguous() || s.dim(0) != 1 ||
        s.dim(1) != skip_channels(i) || s.dim(2) != h * scale_i || s.dim(3) != w * scale_i)
      return Status::error("vae: skip" + std::to_string(i) + ": expected contiguous " +
                           (bf16_ok ? "F32 or BF16" : "F32") + " [1," +
                           std::to_string(skip_channels(i)) + "," + std::to_string(h * scale_i) +
                           "," + std::to_string(w * scale_i) + "], found " + s.describe());
    SkipIn in;
    if (s.dtype == DType::kF32)
      in.f32 = s.f32();
    else
      in.bf16 = s.u16();
    ptrs.push_back(in);
  }
  Tensor out = Tensor::f32({1, cfg_.out_channels, h * f, w * f});  // [1, Cout, H, W]
  Workspace plan;
  decode_impl(Run{&plan, pool, precision_}, nullptr, h, w, ptrs, nullptr);
  Arena local;
  Arena& a = prepare_arena(arena, local, plan.peak());
  Workspace ws(&a);
  decode_impl(Run{&ws, pool, precision_}, z.f32(), h, w, ptrs, out.f32());
  a.reset();
  return out;
}

}  // namespace macro::nets
