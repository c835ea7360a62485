// Vision Transformer (see vit.h): config, weight walk, LayerScale folding, position-embedding
// resampling and the forward.
#include "attention/nets/vit.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "attention/runtime/ops.h"

namespace macro::nets {

VitConfig VitConfig::dinov2_small() {
  return VitConfig{};  // the defaults are timm vit_small_patch14_dinov2
}

// ---- one block ---------------------------------------------------------------------------------

void VitBlock::init(const VitConfig& cfg) {
  d = cfg.width;
  ff = cfg.mlp_hidden;
  heads = cfg.heads;
  layer_scale = cfg.layer_scale;
  norm1.init(d, cfg.ln_eps);
  norm2.init(d, cfg.ln_eps);
  qkv.init(d, 3 * d, cfg.qkv_bias);
  proj.init(d, d, true);
  fc1.init(d, ff, true);
  fc2.init(ff, d, true);
}

void VitBlock::visit(const std::string& prefix, ParamVisitor& v) {
  norm1.visit(join_name(prefix, "norm1"), v);
  qkv.visit(join_name(prefix, "attn.qkv"), v);
  proj.visit(join_name(prefix, "attn.proj"), v);
  if (layer_scale) v.param(join_name(prefix, "ls1.gamma"), ls1, {d});
  norm2.visit(join_name(prefix, "norm2"), v);
  fc1.visit(join_name(prefix, "mlp.fc1"), v);
  fc2.visit(join_name(prefix, "mlp.fc2"), v);
  if (layer_scale) v.param(join_name(prefix, "ls2.gamma"), ls2, {d});
}

namespace {

WeightType weight_type(Precision p) {
  return p == Precision::kBf16 ? WeightType::kBf16 : WeightType::kF32;
}

// l.pack() with the output rows (and bias) scaled by gamma [out]: ls * (x W^T + b).
void pack_scaled(Linear& l, Param& gamma, Precision p) {
  std::vector<float> g(size_t(l.out));
  read_param_f32(gamma, g.data());
  release_param(gamma);
  gamma = Param();
  {
    WidenedBuffer w(l.out * l.in);
    read_param_f32(l.weight, w.data());
    for (int64_t o = 0; o < l.out; ++o)
      for (int64_t i = 0; i < l.in; ++i) w.data()[o * l.in + i] *= g[size_t(o)];
    l.packed = PackedWeights::pack(w.data(), l.out, l.in, l.in, weight_type(p));
  }
  release_param(l.weight);
  l.weight = Param();
  if (l.has_bias) {
    l.b.resize(size_t(l.out));
    read_param_f32(l.bias, l.b.data());
    release_param(l.bias);
    l.bias = Param();
    for (int64_t o = 0; o < l.out; ++o) l.b[size_t(o)] *= g[size_t(o)];
  }
}

}  // namespace

void VitBlock::pack(Precision p) {
  norm1.pack();
  norm2.pack();
  qkv.pack(p);
  fc1.pack(p);
  if (layer_scale) {
    pack_scaled(proj, ls1, p);
    pack_scaled(fc2, ls2, p);
  } else {
    proj.pack(p);
    fc2.pack(p);
  }
}

// ---- position embedding resampling -------------------------------------------------------------

namespace {

double cubic_near(double x, double a) {  // |x| <= 1
  return ((a + 2) * x - (a + 3)) * x * x + 1;
}
double cubic_far(double x, double a) {  // 1 < |x| < 2
  return ((a * x - 5 * a) * x + 8 * a) * x - 4 * a;
}

// Dense [out, in] weights of one axis of torch's bicubic F.interpolate (align_corners=False).
std::vector<double> bicubic_axis(int64_t in, int64_t out, bool antialias) {
  std::vector<double> m(size_t(out * in), 0.0);
  const double scale = double(in) / double(out);
  for (int64_t o = 0; o < out; ++o) {
    double* row = m.data() + o * in;
    if (!antialias) {
      // Source coordinate without clamping (cubic), 4 taps at floor-1 .. floor+2, indices clamped.
      const double real = scale * (double(o) + 0.5) - 0.5;
      const double f = std::floor(real);
      const double t = real - f;
      const double c[4] = {cubic_far(t + 1, -0.75), cubic_near(t, -0.75), cubic_near(1 - t, -0.75),
                           cubic_far(2 - t, -0.75)};
      for (int k = 0; k < 4; ++k) {
        const int64_t i = std::clamp(int64_t(f) - 1 + k, int64_t(0), in - 1);
        row[i] += c[k];
      }
    } else {
      // Antialiased: Keys a = -0.5, support 2 (times the scale when shrinking), taps truncated at
      // the borders and the weights renormalised.
      const double support = scale >= 1.0 ? 2.0 * scale : 2.0;
      const double inv = scale >= 1.0 ? 1.0 / scale : 1.0;
      const double center = scale * (double(o) + 0.5);
      const int64_t lo = std::max<int64_t>(int64_t(center - support + 0.5), 0);
      const int64_t hi = std::min<int64_t>(int64_t(center + support + 0.5), in);
      double total = 0;
      for (int64_t i = lo; i < hi; ++i) {
        const double x = std::abs((double(i) - center + 0.5) * inv);
        const double w = x < 1 ? cubic_near(x, -0.5) : x < 2 ? cubic_far(x, -0.5) : 0.0;
        row[i] = w;
        total += w;
      }
      if (total != 0)
        for (int64_t i = lo; i < hi; ++i) row[i] /= total;
    }
  }
  return m;
}

}  // namespace

void resample_pos_grid(const float* src, int64_t h0, int64_t w0, float* dst, int64_t h, int64_t w,
                       int64_t d, bool antialias) {
  const std::vector<double> mx = bicubic_axis(w0, w, antialias);  // [w, w0]
  const std::vector<double> my = bicubic_axis(h0, h, antialias);  // [h, h0]
  std::vector<double> tmp(size_t(h0 * w * d), 0.0);               // width pass first
  for (int64_t y = 0; y < h0; ++y)
    for (int64_t x = 0; x < w; ++x) {
      double* t = tmp.data() + (y * w + x) * d;
      for (int64_t i = 0; i < w0; ++i) {
        const double c = mx[size_t(x * w0 + i)];
        if (c == 0) continue;
        const float* s = src + (y * w0 + i) * d;
        for (int64_t k = 0; k < d; ++k) t[k] += c * double(s[k]);
      }
    }
  std::vector<double> acc(static_cast<size_t>(d));
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) {
      std::fill(acc.begin(), acc.end(), 0.0);
      for (int64_t j = 0; j < h0; ++j) {
        const double c = my[size_t(y * h0 + j)];
        if (c == 0) continue;
        const double* t = tmp.data() + (j * w + x) * d;
        for (int64_t k = 0; k < d; ++k) acc[size_t(k)] += c * t[k];
      }
      float* o = dst + (y * w + x) * d;
      for (int64_t k = 0; k < d; ++k) o[k] = float(acc[size_t(k)]);
    }
}

// ---- the model ---------------------------------------------------------------------------------

Result<std::unique_ptr<VitModel>> VitModel::build(const VitConfig& cfg) {
  auto bad = [](const std::string& field, const std::string& expected, int64_t found) {
    return Status::error("vit config: " + field + ": expected " + expected + ", found " +
                         std::to_string(found));
  };
  if (cfg.width < 1) return bad("width", "at least 1", cfg.width);
  if (cfg.depth < 0) return bad("depth", "at least 0", cfg.depth);
  if (cfg.heads < 1 || cfg.width % cfg.heads != 0 || cfg.width / cfg.heads > 512)
    return bad(
        "heads",
        "a divisor of the width " + std::to_string(cfg.width) + " giving a head dim of at most 512",
        cfg.heads);
  if (cfg.mlp_hidden < 1) return bad("mlp_hidden", "at least 1", cfg.mlp_hidden);
  if (cfg.patch < 1 || cfg.patch > 64) return bad("patch", "1..64", cfg.patch);
  if (cfg.grid_h < 1 || cfg.grid_w < 1 || cfg.grid_h * cfg.grid_w > (1 << 20))
    return bad("grid_h x grid_w", "a grid of 1 .. 2^20 tokens", cfg.grid_h * cfg.grid_w);
  if (!(cfg.ln_eps > 0)) return Status::error("vit config: ln_eps: expected > 0");
  if (cfg.proj_dim < 0) return bad("proj_dim", "0 (none) or more", cfg.proj_dim);
  auto m = std::make_unique<VitModel>();
  m->cfg_ = cfg;
  const int64_t d = cfg.width;
  m->patch_embed.init(3 * int64_t(cfg.patch) * cfg.patch, d, cfg.patch_bias);
  if (cfg.norm_pre) m->norm_pre.init(d, cfg.ln_eps);
  if (cfg.final_norm) m->norm.init(d, cfg.ln_eps);
  m->blocks.resize(size_t(cfg.depth));
  for (VitBlock& b : m->blocks) b.init(cfg);
  return m;
}

void VitModel::visit(ParamVisitor& v) {
  const std::string& pre = cfg_.prefix;
  const int64_t d = cfg_.width, p = cfg_.patch;
  v.param(pre + "cls_token", cls_token, {1, 1, d});
  v.param(pre + "pos_embed", pos_embed, {1, 1 + cfg_.grid_h * cfg_.grid_w, d});
  // The conv weight [D, 3, p, p] is the GEMM weight [D, 3 p p] (same row-major order).
  v.param(pre + "patch_embed.proj.weight", patch_embed.weight, {d, 3, p, p});
  if (cfg_.patch_bias) v.param(pre + "patch_embed.proj.bias", patch_embed.bias, {d});
  if (cfg_.norm_pre) norm_pre.visit(pre + "norm_pre", v);
  for (size_t i = 0; i < blocks.size(); ++i)
    blocks[i].visit(pre + "blocks." + std::to_string(i), v);
  if (cfg_.final_norm) norm.visit(pre + "norm", v);
  if (cfg_.proj_dim > 0) v.param(pre + "proj", proj_param, {d, cfg_.proj_dim});
}

void VitModel::pack(Precision p) {
  precision_ = p;
  take_vector(cls_token, cls_);
  take_vector(pos_embed, pos_);
  patch_embed.pack(p);
  if (cfg_.norm_pre) norm_pre.pack();
  for (VitBlock& b : blocks) b.pack(p);
  if (cfg_.final_norm) norm.pack();
  if (cfg_.proj_dim > 0) {
    ParamF32 w(proj_param);  // [D, P] = W^T of a Linear
    proj_ =
        PackedWeights::pack_kn(w.data(), cfg_.width, cfg_.proj_dim, cfg_.proj_dim, weight_type(p));
    release_param(proj_param);
    proj_param = Param();
  }
}

size_t VitModel::weight_bytes() const {
  size_t n = (cls_.size() + pos_.size()) * sizeof(float) + patch_embed.bytes() + norm_pre.bytes() +
             norm.bytes() + proj_.bytes();
  for (const VitBlock& b : blocks)
    n += b.norm1.bytes() + b.norm2.bytes() + b.qkv.bytes() + b.proj.bytes() + b.fc1.bytes() +
         b.fc2.bytes();
  return n;
}

Result<std::unique_ptr<VitModel>> VitModel::load(const std::string& path, const VitConfig& cfg,
                                                 const VitLoadOptions& options) {
  MACRO_ASSIGN_OR_RETURN(auto model, build(cfg));
  WeightStoreOptions opt;
  opt.lora_scale = options.lora_scale;
  opt.ignored = options.ignored;
  if (!options.ignored_prefixes.empty() || options.overrides) {
    // Names to leave out of the walk: the file's names under an ignored prefix, and the file's
    // own copies of overridden tensors.
    MACRO_ASSIGN_OR_RETURN(SafeTensors file, SafeTensors::open_checkpoint(path));
    for (const std::string& name : file.names()) {
      for (const std::string& pre : options.ignored_prefixes)
        if (name.compare(0, pre.size(), pre) == 0) opt.ignored.insert(name);
      if (options.overrides && options.overrides->count(name)) opt.ignored.insert(name);
    }
  }
  MACRO_TRY(load_weights(*model, path, opt, options.precision, options.overrides));
  return model;
}

// One image: image [3, H, W] -> tokens_out [T, D] (optional) and cls_out [out_dim].
void VitModel::forward_impl(const Run& r, const float* image, int64_t gh, int64_t gw,
                            float* tokens_out, float* cls_out) const {
  const int64_t d = cfg_.width, ff = cfg_.mlp_hidden, p = cfg_.patch;
  const int64_t n_patch = gh * gw, t = 1 + n_patch, kp = 3 * p * p;
  const int64_t img_w = gw * p, img_h = gh * p;
  const bool resample = gh != cfg_.grid_h || gw != cfg_.grid_w;
  ScratchFrame frame(r);
  float* x = r.alloc(t * d);                               // residual stream [T, D]
  float* n = r.alloc(t * d);                               // LN output, attention output [T, D]
  float* big = r.alloc(t * std::max<int64_t>(3 * d, ff));  // qkv [T, 3D], fc1 [T, F]
  float* patches = r.alloc(n_patch * kp);                  // unfolded patches [N, 3 p p]
  float* pos_r = resample ? r.alloc(t * d) : nullptr;      // resampled pos_embed [T, D]
  float* row = r.alloc(d);                                 // final-normed CLS [D]
  const float* pos = pos_.data();
  if (!r.planning()) {
    for (int64_t py = 0; py < gh; ++py)
      for (int64_t px = 0; px < gw; ++px) {
        float* dst = patches + (py * gw + px) * kp;
        for (int64_t c = 0; c < 3; ++c)
          for (int64_t ky = 0; ky < p; ++ky) {
            const float* s = image + (c * img_h + py * p + ky) * img_w + px * p;
            std::memcpy(dst + (c * p + ky) * p, s, size_t(p) * sizeof(float));
          }
      }
    if (resample) {
      std::memcpy(pos_r, pos_.data(), size_t(d) * sizeof(float));  // the CLS entry is kept
      resample_pos_grid(pos_.data() + d, cfg_.grid_h, cfg_.grid_w, pos_r + d, gh, gw, d,
                        cfg_.pos_resample == PosEmbedResample::kBicubicAntialias);
      pos = pos_r;
    }
    for (int64_t c = 0; c < d; ++c) x[c] = cls_[size_t(c)] + pos[c];
  }
  // Patch tokens: x[1..T) = patches W^T + b + pos[1..T).
  patch_embed.forward(r, n_patch, patches, kp, x + (r.planning() ? 0 : d), d,
                      r.planning() ? nullptr : pos + d);
  if (cfg_.norm_pre) norm_pre.forward(r, x, x, t);
  for (const VitBlock& b : blocks) {
    b.norm1.forward(r, n, x, t);
    b.qkv.forward(r, t, n, d, big, 3 * d);  // [T, 3D]
    round_if_bf16(r, big, t * 3 * d);
    run_attention(r, packed_qkv_attention(big, n, t, d, b.heads));
    b.proj.forward(r, t, n, d, x, d, /*residual=*/x);  // x += ls1 * proj(attn)
    b.norm2.forward(r, n, x, t);
    b.fc1.forward(r, t, n, d, big, ff);  // [T, F]
    if (cfg_.act == VitAct::kQuickGelu)
      quick_gelu(r, big, t * ff);
    else if (!r.planning())
      activation(big, big, t * ff, Act::kGelu, r.pool);
    b.fc2.forward(r, t, big, ff, x, d, /*residual=*/x);  // x += ls2 * fc2(act)
  }
  // Final norm: every token when asked for, else the CLS row only.
  const float* cls = row;
  if (tokens_out) {
    if (cfg_.final_norm)
      norm.forward(r, tokens_out, x, t);
    else
      copy_floats(r, tokens_out, x, t * d);
    cls = tokens_out;
  } else if (cfg_.final_norm) {
    norm.forward(r, row, x, 1);
  } else {
    copy_floats(r, row, x, d);
  }
  if (r.planning()) return;
  if (cfg_.proj_dim > 0)
    gemm_packed(1, cls, d, proj_, cls_out, cfg_.proj_dim, GemmParams{}, r.pool);
  else
    std::memcpy(cls_out, cls, size_t(d) * sizeof(float));
}

Result<VitModel::Output> VitModel::forward(const float* image, int64_t h, int64_t w,
                                           ThreadPool* pool, bool all_tokens, Arena* arena) const {
  const int64_t p = cfg_.patch;
  if (!image || h < p || w < p || h % p != 0 || w % p != 0)
    return Status::error(
        "vit: input image: expected [3, H, W] with H and W positive multiples "
        "of the patch size " +
        std::to_string(p) + ", found " + std::to_string(h) + "x" + std::to_string(w));
  const int64_t gh = h / p, gw = w / p;
  if (gh * gw > (1 << 20))
    return Status::error("vit: input image: expected at most 2^20 patches, found " +
                         std::to_string(gh * gw));
  if ((gh != cfg_.grid_h || gw != cfg_.grid_w) && cfg_.pos_resample == PosEmbedResample::kRefuse)
    return Status::error("vit: input image " + std::to_string(h) + "x" + std::to_string(w) +
                         ": token grid " + std::to_string(gh) + "x" + std::to_string(gw) +
                         " differs from the pos_embed grid " + std::to_string(cfg_.grid_h) + "x" +
                         std::to_string(cfg_.grid_w) + " and resampling is disabled");
  Output out;
  out.grid_h = gh;
  out.grid_w = gw;
  out.cls.resize(size_t(cfg_.out_dim()));
  if (all_tokens) out.tokens.resize(size_t((1 + gh * gw) * cfg_.width));
  Workspace plan;
  forward_impl(Run{&plan, pool, precision_}, nullptr, gh, gw, nullptr, nullptr);
  Arena local;
  Arena& a = prepare_arena(arena, local, plan.peak());
  Workspace ws(&a);
  forward_impl(Run{&ws, pool, precision_}, image, gh, gw, all_tokens ? out.tokens.data() : nullptr,
               out.cls.data());
  a.reset();
  return out;
}

// ---- random weights (tests, benchmarks) ---------------------------------------------------------

namespace {

// A visitor that records every requested name and shape.
struct ShapeLister : ParamVisitor {
  std::vector<std::pair<std::string, std::vector<int64_t>>> items;
  void param(const std::string& name, Param&, const std::vector<int64_t>& shape) override {
    items.emplace_back(name, shape);
  }
};

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

}  // namespace

std::map<std::string, OverrideTensor> vit_random_weights(const VitConfig& cfg, uint64_t seed) {
  std::map<std::string, OverrideTensor> out;
  auto model = VitModel::build(cfg);
  if (!model) return out;
  ShapeLister lister;
  (*model)->visit(lister);
  uint64_t state = seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull;
  auto uniform = [&state]() {  // [-1, 1), SplitMix64
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return float(double(z >> 11) * (2.0 / 9007199254740992.0) - 1.0);
  };
  for (const auto& [name, shape] : lister.items) {
    OverrideTensor t;
    t.shape = shape;
    int64_t n = 1;
    for (int64_t s : shape) n *= s;
    t.values.resize(size_t(n));
    const bool norm = name.find("norm") != std::string::npos;
    float base = 0, amp = 0.02f;
    if (ends_with(name, "gamma")) {
      base = 0.15f, amp = 0.1f;
    } else if (norm && ends_with(name, ".weight")) {
      base = 1.0f, amp = 0.1f;
    } else if (ends_with(name, "cls_token") || ends_with(name, "pos_embed")) {
      amp = 0.1f;
    } else if (ends_with(name, ".weight") || name == cfg.prefix + "proj") {
      const int64_t fan_in = name == cfg.prefix + "proj" ? shape[0]  // CLIP proj [D, P]
                                                         : n / std::max<int64_t>(shape[0], 1);
      amp = float(std::sqrt(3.0 / double(std::max<int64_t>(fan_in, 1))));
    }
    for (float& v : t.values) v = base + amp * uniform();
    out.emplace(name, std::move(t));
  }
  return out;
}

}  // namespace macro::nets
