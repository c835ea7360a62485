// PFT-SR: module tree, loading by state-dict name, and the forward (see pft.h, docs/pft.md).
#include "attention/nets/pft.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <set>

#include "attention/nets/weights.h"
#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/ops.h"

namespace macro::nets {
namespace {

constexpr float kPfaEps = 1e-20f;          // WindowAttention.eps: (a + eps) / (sum a + eps)
constexpr float kShiftMaskValue = -100.f;  // calculate_mask: -100 between different regions
// From this many kept keys per query on, sparse scores come from one dense Q K^T GEMM (then
// gathered): its n x n x d work is cheaper than K gathered d-long dots at K >= 64 with d = 13.
constexpr int kGemmMinKeys = 64;

int64_t round_up(int64_t v, int64_t m) {
  return (v + m - 1) / m * m;
}

// Padded index i >= 0 of a side of length n: torch.cat([x, flip(x)]) read periodically (the
// reference needs pad <= n; beyond that we keep mirroring).
int64_t mirror_index(int64_t i, int64_t n) {
  const int64_t r = i % (2 * n);
  return r < n ? r : 2 * n - 1 - r;
}

// Run fn(begin, end, worker) over [0, n) on the pool, or on the calling thread.
void par(ThreadPool* pool, size_t n, const ThreadPool::RangeFn& fn, size_t grain = 0) {
  if (n == 0) return;
  if (pool)
    pool->parallel_for(n, fn, grain);
  else
    fn(0, n, 0);
}

// tokens [N, C] <-> planes [C, N]
void tokens_to_planes(const float* t, int64_t n, int64_t c, float* planes, ThreadPool* pool) {
  const int64_t blk = 256;
  par(pool, size_t((n + blk - 1) / blk), [&](size_t b0, size_t b1, int) {
    for (size_t b = b0; b < b1; ++b) {
      const int64_t p0 = int64_t(b) * blk, p1 = std::min(n, p0 + blk);
      for (int64_t ch = 0; ch < c; ++ch)
        for (int64_t p = p0; p < p1; ++p) planes[ch * n + p] = t[p * c + ch];
    }
  });
}
void planes_to_tokens(const float* planes, int64_t n, int64_t c, float* t, ThreadPool* pool) {
  const int64_t blk = 256;
  par(pool, size_t((n + blk - 1) / blk), [&](size_t b0, size_t b1, int) {
    for (size_t b = b0; b < b1; ++b) {
      const int64_t p0 = int64_t(b) * blk, p1 = std::min(n, p0 + blk);
      for (int64_t p = p0; p < p1; ++p)
        for (int64_t ch = 0; ch < c; ++ch) t[p * c + ch] = planes[ch * n + p];
    }
  });
}

void run_conv(const PftConv& cv, const float* x, int64_t h, int64_t w, const float* residual,
              float* y, ThreadPool* pool) {
  const Conv2dShape s = Conv2dShape::make(1, cv.c_in, h, w, cv.c_out, cv.k, 1, cv.k / 2);
  conv2d(s, x, cv.packed, residual, y, pool);
}

// y [H*W, C] (row stride ldy) = depthwise conv (pad k/2, zero outside) of x [H*W, C] (stride ldx),
// one output row per kernel call (pft_dw_row, chosen once per call from the active path).
void depthwise(const PftDwConv& dw, const float* x, int64_t ldx, int64_t h, int64_t w, float* y,
               int64_t ldy, ThreadPool* pool) {
  const PftDwRow row = pft_dw_row(active_isa());
  par(pool, size_t(h), [&](size_t y0, size_t y1, int) {
    for (int64_t oy = int64_t(y0); oy < int64_t(y1); ++oy)
      row(y + oy * w * ldy, ldy, x, ldx, h, w, oy, dw.taps.data(), dw.b.data(), dw.c, dw.k);
  });
}

// a[i] = (a[i] * prev[i] + eps) / (sum_i a[i] * prev[i] + eps) over one row (8 float partial
// sums, as a vector reduction would).
void focus_row(float* a, const float* prev, int64_t len) {
  float part[8] = {};
  int64_t j = 0;
  for (; j + 8 <= len; j += 8)
    for (int l = 0; l < 8; ++l) part[l] += (a[j + l] *= prev[j + l]);
  for (; j < len; ++j) part[0] += (a[j] *= prev[j]);
  const float sum =
      ((part[0] + part[4]) + (part[1] + part[5])) + ((part[2] + part[6]) + (part[3] + part[7]));
  const float den = sum + kPfaEps;
  for (j = 0; j < len; ++j) a[j] = (a[j] + kPfaEps) / den;
}

// Order-preserving unsigned key of a float (NaN lowest).
inline uint32_t order_key(float v) {
  uint32_t b;
  std::memcpy(&b, &v, 4);
  if (v != v) return 0;
  return (b & 0x80000000u) ? ~b : (b | 0x80000000u);
}

// The positions of the `keep` largest values of row[0, len) in ascending order. Ties: the smaller
// position wins. NaN ranks below everything. Scratch: keys (len words), cand (len ints).
// Radix select on the order keys: each round histograms 8 bits just below the candidates' common
// prefix (so the first round already spreads the values), keeps the bin holding the wanted rank,
// and stops when the remaining candidates are all equal: that key is the threshold. One ascending
// pass then takes every larger key and the first `need` ties, so nothing is sorted.
void select_topk(const float* row, int len, int keep, int* pos, uint32_t* keys, int* cand) {
  if (keep >= len) {
    std::iota(pos, pos + len, 0);
    return;
  }
  for (int j = 0; j < len; ++j) keys[j] = order_key(row[j]);
  int nc = len;
  for (int j = 0; j < len; ++j) cand[j] = j;
  int need = keep;  // rank (from the top) of the threshold key among the candidates
  uint32_t thr = 0;
  for (;;) {
    uint32_t lo = keys[cand[0]], hi = lo;
    for (int c = 1; c < nc; ++c) {
      const uint32_t k = keys[cand[c]];
      lo = std::min(lo, k), hi = std::max(hi, k);
    }
    if (lo == hi) {
      thr = lo;
      break;
    }
    const int top = 31 - __builtin_clz(lo ^ hi);
    const int shift = std::max(0, top - 7);
    int hist[256] = {};
    for (int c = 0; c < nc; ++c) ++hist[(keys[cand[c]] >> shift) & 255u];
    int bin = 255;
    for (; bin > 0 && hist[bin] < need; --bin) need -= hist[bin];
    int m = 0;
    for (int c = 0; c < nc; ++c)
      if (((keys[cand[c]] >> shift) & 255u) == uint32_t(bin)) cand[m++] = cand[c];
    nc = m;
  }
  int m = 0;  // branch-free: pos always has room for len entries
  for (int j = 0; j < len; ++j) {
    const uint32_t k = keys[j];
    const int eq = k == thr, take = (k > thr) | (eq & (need > 0));
    pos[m] = j;
    m += take;
    need -= eq & take;
  }
}

}  // namespace

// ---- depthwise row kernels ---------------------------------------------------------------------

namespace detail {
void pft_dw_row_avx512(float* y, int64_t ldy, const float* x, int64_t ldx, int64_t h, int64_t w,
                       int64_t oy, const float* taps, const float* bias, int64_t c, int k);
}  // namespace detail

void pft_dw_row_scalar(float* y, int64_t ldy, const float* x, int64_t ldx, int64_t h, int64_t w,
                       int64_t oy, const float* taps, const float* bias, int64_t c, int k) {
  const int r = k / 2;
  for (int64_t ox = 0; ox < w; ++ox) {
    float* yp = y + ox * ldy;
    for (int64_t ch = 0; ch < c; ++ch) yp[ch] = bias[ch];
    for (int dy = 0; dy < k; ++dy) {
      const int64_t iy = oy + dy - r;
      if (iy < 0 || iy >= h) continue;
      for (int dx = 0; dx < k; ++dx) {
        const int64_t ix = ox + dx - r;
        if (ix < 0 || ix >= w) continue;
        const float* xp = x + (iy * w + ix) * ldx;
        const float* tp = taps + (dy * k + dx) * c;
        for (int64_t ch = 0; ch < c; ++ch) yp[ch] += tp[ch] * xp[ch];
      }
    }
  }
}

namespace detail {
void pft_av_rows_avx512(float* o, const float* a, const uint16_t* idx, const float* v, int rows,
                        int kk, int64_t d);
}  // namespace detail

void pft_av_rows_scalar(float* o, const float* a, const uint16_t* idx, const float* v, int rows,
                        int kk, int64_t d) {
  for (int i = 0; i < rows; ++i) {
    float* oi = o + int64_t(i) * d;
    for (int64_t e = 0; e < d; ++e) oi[e] = 0.f;
    const float* ar = a + int64_t(i) * kk;
    const uint16_t* ir = idx ? idx + int64_t(i) * kk : nullptr;
    for (int j = 0; j < kk; ++j) {
      const float w = ar[j];
      const float* vj = v + int64_t(ir ? ir[j] : j) * d;
      for (int64_t e = 0; e < d; ++e) oi[e] += w * vj[e];
    }
  }
}

PftAvRows pft_av_rows(Isa isa) {
  if (isa >= Isa::kAvx512 && isa_supported(Isa::kAvx512)) return detail::pft_av_rows_avx512;
  return pft_av_rows_scalar;
}

PftDwRow pft_dw_row(Isa isa) {
  if (isa >= Isa::kAvx512 && isa_supported(Isa::kAvx512)) return detail::pft_dw_row_avx512;
  return pft_dw_row_scalar;
}

// ---- config ------------------------------------------------------------------------------------

PftConfig PftConfig::light(int upscale) {
  PftConfig c;
  c.upscale = upscale;
  c.topk = {1024, 1024};
  for (int k : {256, 128, 64, 32})
    for (int i = 0; i < (k == 256 ? 4 : 6); ++i) c.topk.push_back(k);
  return c;
}

int PftConfig::layers() const {
  int n = 0;
  for (int d : depths) n += d;
  return n;
}

Status PftConfig::validate() const {
  auto bad = [](const std::string& m) { return Status::error("pft config: " + m); };
  if (embed <= 0 || heads <= 0 || embed % heads != 0)
    return bad("embed " + std::to_string(embed) + " must be a positive multiple of heads " +
               std::to_string(heads));
  if (window < 2 || window % 2 != 0 || window > 256)
    return bad("window " + std::to_string(window) + " must be even, in [2, 256]");
  if (depths.empty()) return bad("no residual groups");
  for (int d : depths)
    if (d <= 0) return bad("every depth must be positive");
  if (int(topk.size()) != layers())
    return bad("topk has " + std::to_string(topk.size()) + " entries, expected one per layer (" +
               std::to_string(layers()) + ")");
  if (ffn_kernel < 1 || ffn_kernel % 2 == 0) return bad("ffn_kernel must be odd");
  if (mlp_hidden <= 0) return bad("mlp_hidden must be positive");
  if (upscale < 1 || upscale > 8) return bad("upscale must be in [1, 8]");
  // torch.topk(k) needs k <= the keys a row still has.
  const int n = window * window;
  int kept[2] = {n, n};
  int l = 0;
  for (int d : depths)
    for (int i = 0; i < d; ++i, ++l) {
      const int s = i % 2, t = topk[size_t(l)];
      if (t < 1) return bad("topk must be positive");
      if (t < n) {
        if (t > kept[s])
          return bad("layer " + std::to_string(l) + " keeps " + std::to_string(t) +
                     " keys but its shift parity has only " + std::to_string(kept[s]));
        kept[s] = t;
      }
    }
  return Status::ok();
}

std::vector<int64_t> pft_relative_position_index(int window) {
  const int ws = window, n = ws * ws;
  std::vector<int64_t> rpi(size_t(n) * n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      rpi[size_t(i) * n + j] =
          int64_t(i / ws - j / ws + ws - 1) * (2 * ws - 1) + (i % ws - j % ws + ws - 1);
  return rpi;
}

// ---- module tree -------------------------------------------------------------------------------

PftNet::PftNet(const PftConfig& cfg) : cfg_(cfg) {
  const int64_t c = cfg.embed, f = cfg.mlp_hidden;
  auto lin = [](PftLinear& l, int64_t in, int64_t out) { l.in = in, l.out = out; };
  auto conv = [](PftConv& cv, int64_t in, int64_t out) { cv.c_in = in, cv.c_out = out, cv.k = 3; };
  conv(conv_first_, 3, c);
  int l = 0;
  groups_.resize(cfg.depths.size());
  for (size_t g = 0; g < groups_.size(); ++g) {
    groups_[g].layers.resize(size_t(cfg.depths[g]));
    for (int i = 0; i < cfg.depths[g]; ++i, ++l) {
      PftLayer& L = groups_[g].layers[size_t(i)];
      L.index = l;
      L.shift = i % 2 ? cfg.window / 2 : 0;
      lin(L.wqkv, c, 3 * c);
      lin(L.proj, c, c);
      lin(L.fc1, c, f);
      lin(L.fc2, f, c);
      L.lepe.c = c, L.lepe.k = cfg.ffn_kernel;
      L.ffn_dw.c = f, L.ffn_dw.k = cfg.ffn_kernel;
    }
    conv(groups_[g].conv, c, c);
  }
  conv(conv_after_body_, c, c);
  conv(upsample_, c, 3 * int64_t(cfg.upscale) * cfg.upscale);
}

void PftNet::visit(const Visitor& fn) {
  const int64_t c = cfg_.embed, ws = cfg_.window;
  auto norm = [&](const std::string& p, PftNorm& nm) {
    fn(p + ".weight", {c}, &nm.gamma);
    fn(p + ".bias", {c}, &nm.beta);
  };
  auto lin = [&](const std::string& p, PftLinear& l) {
    fn(p + ".weight", {l.out, l.in}, &l.w);
    fn(p + ".bias", {l.out}, &l.b);
  };
  auto conv = [&](const std::string& p, PftConv& cv) {
    fn(p + ".weight", {cv.c_out, cv.c_in, cv.k, cv.k}, &cv.w);
    fn(p + ".bias", {cv.c_out}, &cv.b);
  };
  auto dw = [&](const std::string& p, PftDwConv& d) {
    fn(p + ".depthwise_conv.0.weight", {d.c, 1, d.k, d.k}, &d.w);
    fn(p + ".depthwise_conv.0.bias", {d.c}, &d.b);
  };
  conv("conv_first", conv_first_);
  fn("relative_position_index_SA", {ws * ws, ws * ws}, nullptr);
  norm("patch_embed.norm", embed_norm_);
  for (size_t g = 0; g < groups_.size(); ++g) {
    const std::string gp = "layers." + std::to_string(g);
    for (size_t i = 0; i < groups_[g].layers.size(); ++i) {
      PftLayer& L = groups_[g].layers[i];
      const std::string p = gp + ".residual_group.layers." + std::to_string(i);
      norm(p + ".norm1", L.norm1);
      norm(p + ".norm2", L.norm2);
      lin(p + ".wqkv", L.wqkv);
      dw(p + ".v_LePE", L.lepe);
      fn(p + ".attn_win.relative_position_bias_table",
         {(2 * ws - 1) * (2 * ws - 1), cfg_.bias_columns()}, &L.bias_table);
      lin(p + ".attn_win.proj", L.proj);
      lin(p + ".convffn.fc1", L.fc1);
      dw(p + ".convffn.dwconv", L.ffn_dw);
      lin(p + ".convffn.fc2", L.fc2);
    }
    conv(gp + ".conv", groups_[g].conv);
  }
  norm("norm", norm_);
  conv("conv_after_body", conv_after_body_);
  conv("upsample.0", upsample_);
}

std::vector<PftTensorSpec> pft_tensor_specs(const PftConfig& cfg) {
  MACRO_CHECK(cfg.validate().is_ok());
  PftNet net(cfg);
  std::vector<PftTensorSpec> specs;
  net.visit([&](const std::string& name, const std::vector<int64_t>& shape, std::vector<float>*) {
    specs.push_back({name, shape});
  });
  return specs;
}

Result<std::unique_ptr<PftNet>> PftNet::load(const SafeTensors& file, const PftConfig& cfg) {
  MACRO_TRY(cfg.validate());
  auto net = std::make_unique<PftNet>(cfg);
  std::vector<std::string> missing, misshaped, bad_values;
  std::set<std::string> used;
  net->visit(
      [&](const std::string& name, const std::vector<int64_t>& shape, std::vector<float>* storage) {
        used.insert(name);
        const TensorEntry* e = file.find(name);
        if (!e) {
          missing.push_back(name + " " + shape_string(shape));
          return;
        }
        if (e->shape != shape) {
          misshaped.push_back(name + ": expected " + shape_string(shape) + ", found " +
                              shape_string(e->shape));
          return;
        }
        std::vector<float> tmp;
        std::vector<float>& dst = storage ? *storage : tmp;
        dst.resize(size_t(e->numel()));
        if (Status s = convert_to_f32(*e, dst.data(), dst.size()); !s) {
          bad_values.push_back(name + ": " + s.message());
          return;
        }
        if (!storage) {  // the relative position index must be the one the forward computes
          const std::vector<int64_t> rpi = pft_relative_position_index(cfg.window);
          for (size_t i = 0; i < rpi.size(); ++i)
            if (double(dst[i]) != double(rpi[i])) {
              bad_values.push_back(name + ": element " + std::to_string(i) + " is " +
                                   std::to_string(dst[i]) + ", expected " + std::to_string(rpi[i]) +
                                   " for window " + std::to_string(cfg.window));
              return;
            }
          return;
        }
        for (float v : dst)
          if (!std::isfinite(v)) {
            bad_values.push_back(name + ": non-finite values");
            return;
          }
      });
  std::vector<std::string> unused;
  for (const std::string& n : file.names())
    if (!used.count(n)) unused.push_back(n);
  if (!missing.empty() || !misshaped.empty() || !unused.empty() || !bad_values.empty())
    return Status::error(file.path() + ": not a PFT checkpoint for embed " +
                         std::to_string(cfg.embed) + ", x" + std::to_string(cfg.upscale) + ":" +
                         name_list("missing", missing) + name_list("mis-shaped", misshaped) +
                         name_list("unused", unused) + name_list("unreadable", bad_values));
  net->pack();
  return net;
}

void PftNet::pack() {
  auto lin = [](PftLinear& l) {
    l.packed = PackedWeights::pack(l.w.data(), l.out, l.in, l.in, WeightType::kF32);
    std::vector<float>().swap(l.w);
  };
  auto conv = [](PftConv& cv) {
    cv.packed = ConvWeights::pack(cv.w.data(), cv.b.data(), cv.c_out, cv.c_in, cv.k, cv.k);
    std::vector<float>().swap(cv.w);
  };
  auto dw = [](PftDwConv& d) {
    const int kk = d.k * d.k;
    d.taps.assign(size_t(kk * d.c), 0.f);
    for (int64_t ch = 0; ch < d.c; ++ch)
      for (int t = 0; t < kk; ++t) d.taps[size_t(t * d.c + ch)] = d.w[size_t(ch * kk + t)];
    std::vector<float>().swap(d.w);
  };
  conv(conv_first_);
  for (PftGroup& g : groups_) {
    for (PftLayer& L : g.layers) {
      lin(L.wqkv), lin(L.proj), lin(L.fc1), lin(L.fc2);
      dw(L.lepe), dw(L.ffn_dw);
    }
    conv(g.conv);
  }
  conv(conv_after_body_);
  conv(upsample_);
}

// ---- forward -----------------------------------------------------------------------------------

// The focusing state of one shift parity.
struct PftNet::PfaState {
  enum Kind { kNone, kDense, kSparse } kind = kNone;
  // kDense: the map is the chain of dense layers' maps, multiplied and renormalised in order; each
  // element keeps that layer's scaled q and k, [nwin, Hd, 2, n, d], and its bias table.
  std::vector<std::vector<float>> chain_qk;
  std::vector<const PftLayer*> chain_layers;
  // kSparse: per (window, head, query) the K kept values and key indices, [nwin, Hd, n, K].
  int k = 0;
  std::vector<float> val;
  std::vector<uint16_t> idx;
};

struct PftNet::Work {
  int64_t hp = 0, wp = 0, n_tok = 0, nwin_x = 0, nwin = 0;
  std::vector<float> xn, qkv, lepe, ao, hid, hid2;
  struct Scratch {
    std::vector<float> s, p, p2, q, k, v, o;
    std::vector<int> lab, pos;
    std::vector<uint32_t> keys;
    std::vector<int> cand;
    std::vector<int> key_off;  // key (y, x) -> y (2 ws - 1) + x: bias index = row base - key_off
    std::vector<int64_t> tok_pos;
  };
  std::vector<Scratch> scratch;  // one per worker
};

size_t PftNet::state_bytes(int h, int w) const {
  const int64_t ws = cfg_.window, n = ws * ws;
  const int64_t hp = round_up(std::max(h, 1), ws), wp = round_up(std::max(w, 1), ws);
  const int64_t nt = hp * wp, c = cfg_.embed, f = cfg_.mlp_hidden, hd = cfg_.heads;
  const int64_t s2 = int64_t(cfg_.upscale) * cfg_.upscale;
  // Activations: t, t_in, xn, q|k|v, lepe, ao, hid, hid2, three planes buffers, padded input,
  // upsample conv output, the result.
  const int64_t act = nt * (9 * c + 2 * f + 3 + 3 * s2) + int64_t(h) * w * 3 * s2;
  // Focusing state: simulate the two parities.
  int64_t size[2] = {0, 0}, peak = 0;
  int kind[2] = {0, 0};  // 0 none, 1 dense, 2 sparse
  for (const PftGroup& g : groups_)
    for (const PftLayer& L : g.layers) {
      const int s = L.shift ? 1 : 0, t = cfg_.topk[size_t(L.index)];
      int64_t next = size[s];
      if (t < n) {
        next = nt * hd * t * 6;
        kind[s] = 2;
      } else if (kind[s] != 2) {
        next = size[s] + nt * 2 * c * 4;  // one more dense chain element
        kind[s] = 1;
      }
      peak = std::max(peak, size[1 - s] + size[s] + next * (next != size[s]));
      size[s] = next;
    }
  return size_t(act * 4 + peak);
}

// One layer's window attention (with the LePE added) into wk.ao; updates the parity's state.
void PftNet::attention(const PftLayer& L, Work& wk, PfaState& st, ThreadPool* pool) const {
  const int ws = cfg_.window, n = ws * ws, heads = cfg_.heads;
  const int64_t c = cfg_.embed, d = cfg_.head_dim(), hp = wk.hp, wp = wk.wp;
  const int cols = cfg_.bias_columns(), shift = L.shift, t_keep = cfg_.topk[size_t(L.index)];
  const float scale = float(1.0 / std::sqrt(double(d)));
  const int64_t nslot = wk.nwin * heads;

  // What this layer produces.
  const bool was_sparse = st.kind == PfaState::kSparse;
  const int k_in = was_sparse ? st.k : n;
  const bool select = t_keep < n;
  std::vector<float> new_val;
  std::vector<uint16_t> new_idx;
  std::vector<float> new_chain;
  if (select) {
    new_val.resize(size_t(nslot) * n * t_keep);
    new_idx.resize(size_t(nslot) * n * t_keep);
  } else if (!was_sparse) {
    new_chain.resize(size_t(nslot) * 2 * n * d);
  }
  const size_t chain_len = st.kind == PfaState::kDense ? st.chain_qk.size() : 0;

  const OpsKernels& ok = ops_kernels();
  const PftAvRows av_rows = pft_av_rows(active_isa());
  par(
      pool, size_t(nslot),
      [&](size_t j0, size_t j1, int worker) {
        Work::Scratch& sc = wk.scratch[size_t(worker)];
        for (size_t job = j0; job < j1; ++job) {
          const int64_t win = int64_t(job) / heads;
          const int head = int(job % heads), hcol = cols == 1 ? 0 : head;
          const int64_t wy = win / wk.nwin_x, wx = win % wk.nwin_x;
          // Gather this head's q (scaled), k, v for the window of the (rolled) image;
          // shifted-window labels from the rolled coordinates.
          bool masked = false;
          std::vector<int64_t>& tok_pos = sc.tok_pos;
          for (int i = 0; i < n; ++i) {
            const int64_t sy = wy * ws + i / ws, sx = wx * ws + i % ws;
            const int64_t y = (sy + shift) % hp, x = (sx + shift) % wp;
            const int64_t p = y * wp + x;
            tok_pos[size_t(i)] = p;
            const float* row = wk.qkv.data() + p * 3 * c + head * d;
            for (int64_t e = 0; e < d; ++e) {
              sc.q[size_t(i * d + e)] = row[e] * scale;
              sc.k[size_t(i * d + e)] = row[c + e];
              sc.v[size_t(i * d + e)] = row[2 * c + e];
            }
            if (shift) {
              auto band = [&](int64_t v, int64_t size) {
                return v < size - ws ? 0 : (v < size - ws / 2 ? 1 : 2);
              };
              sc.lab[size_t(i)] = band(sy, hp) * 3 + band(sx, wp);
              masked |= sc.lab[size_t(i)] != sc.lab[0];
            }
          }
          // Dense probabilities softmax(q k^T + bias (+ mask)) of a layer into dst [n, n].
          auto dense_probs = [&](const float* q, const float* k, const PftLayer& layer,
                                 float* dst) {
            GemmParams gp;
            gp.trans_b = true;
            gemm_f32(n, n, d, q, d, k, d, dst, n, gp, nullptr);
            const float* table = layer.bias_table.data();
            for (int i = 0; i < n; ++i) {
              float* row = dst + int64_t(i) * n;
              const int yi = i / ws, xi = i % ws;
              for (int yj = 0; yj < ws; ++yj) {
                const int base = (yi - yj + ws - 1) * (2 * ws - 1) + xi + ws - 1;
                float* r = row + yj * ws;
                for (int xj = 0; xj < ws; ++xj) r[xj] += table[(base - xj) * cols + hcol];
              }
              if (masked)
                for (int j = 0; j < n; ++j)
                  if (sc.lab[size_t(j)] != sc.lab[size_t(i)]) row[j] += kShiftMaskValue;
              ok.softmax(row, row, n, 1.0f);
            }
          };
          float* a = sc.s.data();  // this layer's map, [n, k_row]
          const int k_row = was_sparse ? k_in : n;
          const size_t slot = size_t(job);
          if (!was_sparse) {
            dense_probs(sc.q.data(), sc.k.data(), L, a);
            if (chain_len > 0) {
              // The previous map: the chain's maps multiplied and renormalised in order.
              for (size_t ci = 0; ci < chain_len; ++ci) {
                const float* qk = st.chain_qk[ci].data() + slot * 2 * n * d;
                float* dst = ci == 0 ? sc.p.data() : sc.p2.data();
                dense_probs(qk, qk + n * d, *st.chain_layers[ci], dst);
                if (ci == 0) continue;
                for (int i = 0; i < n; ++i)
                  focus_row(dst + int64_t(i) * n, sc.p.data() + int64_t(i) * n, n);
                sc.p.swap(sc.p2);
              }
              for (int i = 0; i < n; ++i)
                focus_row(a + int64_t(i) * n, sc.p.data() + int64_t(i) * n, n);
            }
          } else {
            const float* table = L.bias_table.data();
            // Many kept keys: all scores by one GEMM, then gathered (far faster than gathered
            // dots).
            const bool via_gemm = k_in >= kGemmMinKeys;
            if (via_gemm) {
              GemmParams gp;
              gp.trans_b = true;
              gemm_f32(n, n, d, sc.q.data(), d, sc.k.data(), d, sc.p.data(), n, gp, nullptr);
            }
            for (int i = 0; i < n; ++i) {
              const uint16_t* ix = st.idx.data() + (slot * n + i) * k_in;
              const float* pv = st.val.data() + (slot * n + i) * k_in;
              float* row = a + int64_t(i) * k_in;
              const float* qi = sc.q.data() + i * d;
              const float* si = sc.p.data() + int64_t(i) * n;
              const int row_base = (i / ws + ws - 1) * (2 * ws - 1) + i % ws + ws - 1;
              for (int j = 0; j < k_in; ++j) {
                const int key = ix[j];
                float s = 0.f;
                if (via_gemm) {
                  s = si[key];
                } else {
                  const float* kj = sc.k.data() + key * d;
                  for (int64_t e = 0; e < d; ++e) s += qi[e] * kj[e];
                }
                row[j] = s + table[(row_base - sc.key_off[size_t(key)]) * cols + hcol];
              }
              ok.softmax(row, row, k_in, 1.0f);
              focus_row(row, pv, k_in);
            }
          }
          // Keep the top keys, or keep the map as it is.
          float* o = sc.o.data();
          auto sparse_av = [&](const float* vals, const uint16_t* idx, int kk) {
            av_rows(o, vals, idx, sc.v.data(), n, kk, d);
          };
          if (select) {
            float* nv = new_val.data() + slot * n * t_keep;
            uint16_t* ni = new_idx.data() + slot * n * t_keep;
            for (int i = 0; i < n; ++i) {
              const float* row = a + int64_t(i) * k_row;
              select_topk(row, k_row, t_keep, sc.pos.data(), sc.keys.data(), sc.cand.data());
              const uint16_t* old = was_sparse ? st.idx.data() + (slot * n + i) * k_in : nullptr;
              for (int j = 0; j < t_keep; ++j) {
                const int p = sc.pos[size_t(j)];
                nv[int64_t(i) * t_keep + j] = row[p];
                ni[int64_t(i) * t_keep + j] = old ? old[p] : uint16_t(p);
              }
            }
            sparse_av(nv, ni, t_keep);
          } else if (was_sparse) {
            float* pv = st.val.data() + slot * n * k_in;
            std::memcpy(pv, a, size_t(n) * k_in * 4);
            sparse_av(pv, st.idx.data() + slot * n * k_in, k_in);
          } else {
            av_rows(o, a, nullptr, sc.v.data(), n, n, d);
            float* qk = new_chain.data() + slot * 2 * n * d;
            std::memcpy(qk, sc.q.data(), size_t(n * d) * 4);
            std::memcpy(qk + n * d, sc.k.data(), size_t(n * d) * 4);
          }
          // Scatter back to image positions (the reverse roll), adding the LePE.
          for (int i = 0; i < n; ++i) {
            const int64_t p = tok_pos[size_t(i)];
            float* dst = wk.ao.data() + p * c + head * d;
            const float* lp = wk.lepe.data() + p * c + head * d;
            for (int64_t e = 0; e < d; ++e) dst[e] = o[i * d + e] + lp[e];
          }
        }
      },
      1);

  if (select) {
    st.kind = PfaState::kSparse;
    st.k = t_keep;
    st.val.swap(new_val);
    st.idx.swap(new_idx);
    st.chain_qk.clear();
    st.chain_layers.clear();
  } else if (!was_sparse) {
    st.kind = PfaState::kDense;
    st.chain_qk.push_back(std::move(new_chain));
    st.chain_layers.push_back(&L);
  }
}

void PftNet::run_layer(const PftLayer& L, float* t, Work& wk, PfaState* states,
                       ThreadPool* pool) const {
  const int64_t n = wk.n_tok, c = cfg_.embed, f = cfg_.mlp_hidden;
  layer_norm(wk.xn.data(), t, L.norm1.gamma.data(), L.norm1.beta.data(), n, c, cfg_.ln_eps, pool);
  GemmParams gp;
  gp.bias_n = L.wqkv.b.data();
  gemm_packed(n, wk.xn.data(), c, L.wqkv.packed, wk.qkv.data(), 3 * c, gp, pool);  // [N, 3C]
  depthwise(L.lepe, wk.qkv.data() + 2 * c, 3 * c, wk.hp, wk.wp, wk.lepe.data(), c, pool);
  activation(wk.lepe.data(), wk.lepe.data(), n * c, Act::kGelu, pool);  // [N, C]
  attention(L, wk, states[L.shift ? 1 : 0], pool);                      // ao [N, C]
  GemmParams pp;
  pp.bias_n = L.proj.b.data();
  pp.residual = t;
  pp.ldr = c;
  gemm_packed(n, wk.ao.data(), c, L.proj.packed, t, c, pp, pool);  // t += proj(ao)
  // ConvFFN
  layer_norm(wk.xn.data(), t, L.norm2.gamma.data(), L.norm2.beta.data(), n, c, cfg_.ln_eps, pool);
  GemmParams p1;
  p1.bias_n = L.fc1.b.data();
  gemm_packed(n, wk.xn.data(), c, L.fc1.packed, wk.hid.data(), f, p1, pool);
  activation(wk.hid.data(), wk.hid.data(), n * f, Act::kGelu, pool);  // a [N, F]
  depthwise(L.ffn_dw, wk.hid.data(), f, wk.hp, wk.wp, wk.hid2.data(), f, pool);
  activation(wk.hid2.data(), wk.hid2.data(), n * f, Act::kGelu, pool);
  add(wk.hid.data(), wk.hid.data(), wk.hid2.data(), n * f, pool);  // a + GELU(dw(a))
  GemmParams p2;
  p2.bias_n = L.fc2.b.data();
  p2.residual = t;
  p2.ldr = c;
  gemm_packed(n, wk.hid.data(), f, L.fc2.packed, t, c, p2, pool);  // t += fc2(...)
}

Result<std::vector<float>> PftNet::forward(const float* image, int h, int w, ThreadPool* pool,
                                           const LayerCallback& on_layer) const {
  if (!image || h <= 0 || w <= 0)
    return Status::error("pft: empty input image (" + std::to_string(w) + "x" + std::to_string(h) +
                         ")");
  const size_t need = state_bytes(h, w);
  if (need > max_state_bytes_)
    return Status::error("pft: a " + std::to_string(w) + "x" + std::to_string(h) + " input needs " +
                         std::to_string(need >> 20) + " MiB of activations and attention state, " +
                         "above the limit of " + std::to_string(max_state_bytes_ >> 20) + " MiB");
  const int ws = cfg_.window, n = ws * ws, s = cfg_.upscale;
  const int64_t c = cfg_.embed, f = cfg_.mlp_hidden, d = cfg_.head_dim();
  Work wk;
  wk.hp = round_up(h, ws), wk.wp = round_up(w, ws);
  wk.n_tok = wk.hp * wk.wp;
  wk.nwin_x = wk.wp / ws;
  wk.nwin = (wk.hp / ws) * wk.nwin_x;
  const int64_t nt = wk.n_tok, hp = wk.hp, wp = wk.wp;

  // Mirror padding and mean subtraction: x0 [3, Hp, Wp].
  std::vector<float> x0(size_t(3 * nt));
  for (int64_t y = 0; y < hp; ++y) {
    const int64_t sy = mirror_index(y, h);
    for (int64_t x = 0; x < wp; ++x) {
      const float* px = image + (sy * w + mirror_index(x, w)) * 3;
      for (int ch = 0; ch < 3; ++ch)
        x0[size_t(ch * nt + y * wp + x)] = (px[ch] - cfg_.mean[ch]) * cfg_.img_range;
    }
  }
  std::vector<float> f0(size_t(c * nt));
  run_conv(conv_first_, x0.data(), hp, wp, nullptr, f0.data(), pool);  // [C, Hp, Wp]
  std::vector<float>().swap(x0);

  std::vector<float> t(size_t(nt * c)), t_in(size_t(nt * c));
  planes_to_tokens(f0.data(), nt, c, t.data(), pool);  // [N, C]
  layer_norm(t.data(), t.data(), embed_norm_.gamma.data(), embed_norm_.beta.data(), nt, c,
             cfg_.ln_eps, pool);

  wk.xn.resize(size_t(nt * c));
  wk.qkv.resize(size_t(nt * 3 * c));
  wk.lepe.resize(size_t(nt * c));
  wk.ao.resize(size_t(nt * c));
  wk.hid.resize(size_t(nt * f));
  wk.hid2.resize(size_t(nt * f));
  wk.scratch.resize(size_t(pool ? pool->size() : 1));
  bool long_chain = false;  // a dense chain of two or more maps needs a third n x n buffer
  {
    int dense[2] = {0, 0};
    bool sparse[2] = {false, false};
    for (const PftGroup& g : groups_)
      for (const PftLayer& L : g.layers) {
        const int sp = L.shift ? 1 : 0;
        if (cfg_.topk[size_t(L.index)] < n) sparse[sp] = true;
        if (!sparse[sp]) long_chain |= ++dense[sp] >= 2;
      }
  }
  for (Work::Scratch& sc : wk.scratch) {
    sc.s.resize(size_t(n) * n);
    sc.p.resize(size_t(n) * n);
    if (long_chain) sc.p2.resize(size_t(n) * n);
    sc.q.resize(size_t(n * d));
    sc.k.resize(size_t(n * d));
    sc.v.resize(size_t(n * d));
    sc.o.resize(size_t(n * d));
    sc.lab.assign(size_t(n), 0);
    sc.pos.resize(size_t(n));
    sc.keys.resize(size_t(n));
    sc.cand.resize(size_t(n));
    sc.key_off.resize(size_t(n));
    for (int j = 0; j < n; ++j) sc.key_off[size_t(j)] = (j / ws) * (2 * ws - 1) + j % ws;
    sc.tok_pos.resize(size_t(n));
  }

  PfaState states[2];
  std::vector<float> pa(size_t(c * nt)), pb(size_t(c * nt));
  const int total = cfg_.layers();
  int done = 0;
  for (const PftGroup& g : groups_) {
    t_in = t;
    for (const PftLayer& L : g.layers) {
      run_layer(L, t.data(), wk, states, pool);
      if (on_layer) on_layer(++done, total);
    }
    // t = tokens(conv(image(t))) + t_in
    tokens_to_planes(t.data(), nt, c, pa.data(), pool);
    tokens_to_planes(t_in.data(), nt, c, pb.data(), pool);
    run_conv(g.conv, pa.data(), hp, wp, pb.data(), pb.data(), pool);  // residual aliases y
    planes_to_tokens(pb.data(), nt, c, t.data(), pool);
  }
  states[0] = PfaState(), states[1] = PfaState();
  wk = Work();
  layer_norm(t.data(), t.data(), norm_.gamma.data(), norm_.beta.data(), nt, c, cfg_.ln_eps, pool);
  tokens_to_planes(t.data(), nt, c, pa.data(), pool);
  run_conv(conv_after_body_, pa.data(), hp, wp, f0.data(), pb.data(), pool);  // + f0
  std::vector<float> up(size_t(3 * s * s * nt));
  run_conv(upsample_, pb.data(), hp, wp, nullptr, up.data(), pool);  // [3 s^2, Hp, Wp]

  // Pixel shuffle, + mean, crop: out [H s, W s, 3].
  const int64_t oh = int64_t(h) * s, ow = int64_t(w) * s;
  std::vector<float> out(size_t(oh * ow * 3));
  par(pool, size_t(oh), [&](size_t y0, size_t y1, int) {
    for (int64_t y = int64_t(y0); y < int64_t(y1); ++y)
      for (int64_t x = 0; x < ow; ++x)
        for (int ch = 0; ch < 3; ++ch) {
          const int64_t plane = ch * s * s + (y % s) * s + x % s;
          out[size_t((y * ow + x) * 3 + ch)] =
              up[size_t(plane * nt + (y / s) * wp + x / s)] / cfg_.img_range + cfg_.mean[ch];
        }
  });
  return out;
}

}  // namespace macro::nets
