// conv2d as an implicit GEMM over the shared GEMM driver (gemm.h): the packed weights are the A
// operand ([Cout, Cin*KH*KW] in MR-row panels), and the B panels (NR output pixels x a K block) are
// gathered straight from the NCHW input by pack_im2col below, tile by tile, into the driver's
// per-thread buffers. Stride-1 rows are copied as runs; padding is written as zeros.
//
// bf16 weights: K is ordered (dy, dx, ci) with Cin padded to even, so a bf16 k pair is two
// neighbouring channels under the same tap. The input is converted once per call into channel-pair
// planes xp[Cin2/2][H][W] of 32-bit words (even channel in the low half; a per-thread buffer grown
// once, not allocated per call) and the pair panels are then gathered exactly like the fp32 ones,
// one 32-bit word per pixel. Large images go by bands of output rows (conv_rows: the shape re-cut
// to the band's input rows), so that buffer stays small.
//
// Stride-1 gathers into 32-column panels use the path's vector gather when it has one
// (KernelTable::conv_rows32: masked loads per output-row run); otherwise, and for stride 2, the
// portable fill_row below.
#include "attention/runtime/conv.h"

#include <algorithm>
#include <cstring>
#include <memory>
#include <vector>

#include "attention/runtime/conv_winograd.h"
#include "attention/runtime/large_alloc.h"
#include "attention/runtime/ops.h"
#include "attention/runtime/scratch.h"
#include "attention/runtime/status.h"

namespace macro {
namespace {

struct Im2colCtx {
  const Conv2dShape* s;
  const float* x;      // fp32: one image [Cin, H, W]
  const uint32_t* xp;  // bf16: one image's channel-pair planes [Cin2/2, H, W]
  int64_t cin2;        // bf16: Cin rounded up to even
  int64_t oh, ow;
  ConvGatherRows32 rows32;  // the path's vector gather (stride 1, 32-column panels), or null
  int64_t x_plane = 0;      // elements between the input planes of x / xp
  bool split_cols = false;  // bf16 stride 2: each pair-plane row holds its even columns, then odd
};

// Stride 2 over rows whose even columns come first and odd columns after (split_cols): the
// position in such a row of width W of column ix.
inline int64_t split_col(int64_t ix, int64_t W) {
  return ix % 2 ? (W + 1) / 2 + ix / 2 : ix / 2;
}

using Segment = ConvSegment;  // one run of consecutive output pixels on the same output row

// Output pixels [px0, px0 + count) split into runs on the same output row.
int make_segments(const Im2colCtx& c, int64_t px0, int count, Segment* segs) {
  int nseg = 0;
  for (int col = 0; col < count;) {
    const int64_t px = px0 + col;
    const int64_t oy = px / c.ow, ox = px % c.ow;
    const int len = int(std::min<int64_t>(count - col, c.ow - ox));
    segs[nseg++] = Segment{col, len, oy, ox};
    col += len;
  }
  return nseg;
}

// One im2col row: the input plane's values under tap (dy, dx) for the panel's pixels; w values,
// zeros for padding and for pixels past `count`. T is float (fp32) or uint32_t (bf16 pair words).
template <typename T>
void fill_row(const Im2colCtx& c, const Segment* segs, int nseg, int count, int w, const T* plane,
              int64_t dy, int64_t dx, T* out_row) {
  const Conv2dShape& s = *c.s;
  const int64_t H = s.h, W = s.w;
  const int stride = s.stride;
  for (int g = 0; g < nseg; ++g) {
    const Segment& sg = segs[g];
    T* out = out_row + sg.col;
    const int64_t iy = sg.oy * stride + dy - s.pad_top;
    if (iy < 0 || iy >= H) {
      std::memset(out, 0, sizeof(T) * sg.len);
      continue;
    }
    const T* row = plane + iy * W;
    const int64_t ix0 = sg.ox * stride + dx - s.pad_left;
    // out[lo, hi) = src[0, hi - lo), zeros (padding) before and after.
    auto run = [&](int64_t lo, int64_t hi, const T* src) {
      for (int64_t i = 0; i < lo; ++i) out[i] = T(0);
      if (hi > lo) std::memcpy(out + lo, src, sizeof(T) * size_t(hi - lo));
      for (int64_t i = hi; i < sg.len; ++i) out[i] = T(0);
    };
    if (stride == 1) {
      const int64_t lo = std::clamp<int64_t>(-ix0, 0, sg.len);
      run(lo, std::clamp<int64_t>(W - ix0, lo, sg.len), row + ix0 + lo);
    } else if (c.split_cols) {
      // Columns ix0, ix0 + 2, ... lie side by side in the split row: one copy between the pads.
      const int64_t lo = std::clamp<int64_t>((-ix0 + 1) / 2, 0, sg.len);      // first ix >= 0
      const int64_t hi = std::clamp<int64_t>((W - ix0 + 1) / 2, lo, sg.len);  // first ix >= W
      run(lo, hi, hi > lo ? row + split_col(ix0 + 2 * lo, W) : row);
    } else {
      // Pixels [lo, hi) read row[ix0 + i stride]; zeros (padding) before and after.
      const int64_t lo = std::clamp<int64_t>((-ix0 + stride - 1) / stride, 0, sg.len);
      const int64_t hi = std::clamp<int64_t>((W - ix0 + stride - 1) / stride, lo, sg.len);
      for (int64_t i = 0; i < lo; ++i) out[i] = T(0);
      const T* src = row + ix0;
      for (int64_t i = lo; i < hi; ++i) out[i] = src[i * stride];
      for (int64_t i = hi; i < sg.len; ++i) out[i] = T(0);
    }
  }
  if (count < w) std::memset(out_row + count, 0, sizeof(T) * size_t(w - count));
}

void pack_im2col(const void* ctx, const GemmKernel& kern, bool is_a, int64_t r0, int64_t rows,
                 int64_t k0, int64_t kc, void* dst_v) {
  MACRO_CHECK(!is_a);
  const Im2colCtx& c = *static_cast<const Im2colCtx*>(ctx);
  const Conv2dShape& s = *c.s;
  const int w = kern.nr;
  MACRO_CHECK(w <= 64);
  const int64_t kcp = detail::round_up(kc, kern.k_align);
  const int64_t HW = c.x_plane;
  Segment segs[64];
  const int64_t panels = (rows + w - 1) / w;
  for (int64_t p = 0; p < panels; ++p) {
    const int64_t px0 = r0 + p * w;
    const int count = int(std::min<int64_t>(w, r0 + rows - px0));
    const int nseg = make_segments(c, px0, count, segs);
    if (c.rows32 && s.stride == 1 && w == 32) {
      ConvRows a;
      const bool f32 = kern.layout == PackLayout::kF32;
      a.x = f32 ? reinterpret_cast<const uint32_t*>(c.x) : c.xp;
      a.hw = HW, a.h = s.h, a.w = s.w;
      a.pad_top = s.pad_top, a.pad_left = s.pad_left, a.kh = s.kh, a.kw = s.kw;
      a.tap_major = !f32;
      a.planes = f32 ? s.c_in : c.cin2 / 2;
      a.k0 = f32 ? k0 : k0 / 2;
      a.nrows = f32 ? kc : (kc + 1) / 2;
      a.rows_padded = f32 ? kcp : kcp / 2;
      a.segs = segs;
      a.nseg = nseg;
      a.dst = static_cast<uint32_t*>(dst_v) + p * a.rows_padded * w;
      c.rows32(a);
      continue;
    }
    if (kern.layout == PackLayout::kF32) {
      // k = (ci, dy, dx)
      const int64_t khw = int64_t(s.kh) * s.kw;
      int64_t ci = k0 / khw, rem = k0 % khw;
      int64_t dy = rem / s.kw, dx = rem % s.kw;
      float* d = static_cast<float*>(dst_v) + p * kcp * w;
      for (int64_t k = 0; k < kcp; ++k) {
        if (k >= kc) {
          std::memset(d + k * w, 0, sizeof(float) * w);
          continue;
        }
        fill_row<float>(c, segs, nseg, count, w, c.x + ci * HW, dy, dx, d + k * w);
        if (++dx == s.kw) {
          dx = 0;
          if (++dy == s.kh) {
            dy = 0;
            ++ci;
          }
        }
      }
    } else {
      // k = (dy, dx, ci) with Cin2 even; k0 and kc are even, pair q covers channels 2cp, 2cp+1.
      const int64_t pairs_per_tap = c.cin2 / 2;
      int64_t q0 = k0 / 2;
      int64_t tap = q0 / pairs_per_tap, cp = q0 % pairs_per_tap;
      uint32_t* d = static_cast<uint32_t*>(dst_v) + p * (kcp / 2) * w;
      for (int64_t q = 0; q < kcp / 2; ++q) {
        if (2 * q >= kc) {
          std::memset(d + q * w, 0, sizeof(uint32_t) * w);
          continue;
        }
        fill_row<uint32_t>(c, segs, nseg, count, w, c.xp + cp * HW, tap / s.kw, tap % s.kw,
                           d + q * w);
        if (++cp == pairs_per_tap) {
          cp = 0;
          ++tap;
        }
      }
    }
  }
}

}  // namespace

ConvWeights ConvWeights::pack(const float* w, const float* bias, int64_t c_out, int64_t c_in,
                              int kh, int kw, WeightType type, Isa isa, bool stride1_only) {
  ConvWeights cw;
  cw.c_out_ = c_out;
  cw.c_in_ = c_in;
  cw.kh_ = kh;
  cw.kw_ = kw;
  const ConvWinograd mode = conv2d_winograd_mode();
  // fp32 under kAuto: only on the paths with the vector fp32 transforms (AVX2 and up).
  const bool wino = kh == 3 && kw == 3 &&
                    (mode == ConvWinograd::kAlways ||
                     (mode == ConvWinograd::kAuto && detail::winograd_pack_qualifies(c_out, c_in) &&
                      (type == WeightType::kBf16 || detail::winograd_vector_path(isa))));
  if (wino) cw.wino_ = detail::winograd_pack(w, c_out, c_in, isa, type);
  if (wino && stride1_only) {
    // The Winograd packs only: every call takes them.
  } else if (type == WeightType::kF32) {
    const int64_t K = c_in * kh * kw;
    cw.packed_ = PackedWeights::pack_as_a(w, c_out, K, K, type, isa);
  } else {
    // Reorder to [Cout][KH][KW][Cin2] (Cin2 = Cin rounded up to even, zero weights for the pad).
    // The reordered copy is as large as the weight (118 MB for a 2560 -> 1280 3x3): a fresh,
    // pre-faulted huge-page block (large_alloc.h), not one page fault per 4 KB.
    const int64_t cin2 = (c_in + 1) / 2 * 2, K = int64_t(kh) * kw * cin2;
    const size_t n = size_t(c_out * K);
    std::unique_ptr<float, LargeFree> wr_block(
        static_cast<float*>(large_zeroed(n * sizeof(float))));
    float* const wr = wr_block.get();
    for (int64_t co = 0; co < c_out; ++co)
      for (int64_t ci = 0; ci < c_in; ++ci)
        for (int dy = 0; dy < kh; ++dy)
          for (int dx = 0; dx < kw; ++dx)
            wr[size_t(co * K + (dy * kw + dx) * cin2 + ci)] =
                w[((co * c_in + ci) * kh + dy) * kw + dx];
    cw.packed_ = PackedWeights::pack_as_a(wr, c_out, K, K, type, isa);
  }
  if (bias) cw.bias_.assign(bias, bias + c_out);
  return cw;
}

size_t ConvWeights::bytes() const {
  size_t b = packed_.bytes() + bias_.size() * sizeof(float);
  for (const PackedWeights& u : wino_) b += u.bytes();
  return b;
}

// bf16 channel-pair planes: grown once per calling thread to at most one band, reused by every
// call.
thread_local std::vector<uint32_t> t_pair_planes;
// Rows of a residual that aliases the output, copied per band (conv2d); grown once per thread.
thread_local std::vector<float> t_residual_rows;
// The whole im2col B of a conv whose tasks split the output channels (conv_rows), per calling
// thread.
thread_local detail::AlignedScratch t_im2col;
size_t g_pair_band_words = size_t(4) << 20;  // 16 MB of pair words per band (conv2d_set_pair_band)

void conv2d_release_scratch() {
  std::vector<uint32_t>().swap(t_pair_planes);
  std::vector<float>().swap(t_residual_rows);
  t_im2col.release();
  detail::winograd_release_scratch();
}

size_t conv2d_set_pair_band(size_t words) {
  const size_t old = g_pair_band_words;
  g_pair_band_words = std::max<size_t>(1, words);
  return old;
}

void conv2d(const Conv2dShape& s, const float* x, const ConvWeights& w, const float* residual,
            float* y, ThreadPool* pool) {
  conv2d(s, x, w, residual, y, ConvAct::kNone, pool);
}

namespace {

// The implicit GEMM's K: Cin * KH * KW taps, with Cin padded to even for the bf16 pairs.
inline int64_t conv_k(const Conv2dShape& s, bool bf16) {
  return (bf16 ? (s.c_in + 1) / 2 * 2 : s.c_in) * s.kh * s.kw;
}

// Output rows [oy0, oy1) of one image read input rows [iy0, iy1) (clipped to the image).
void input_rows(const Conv2dShape& s, int64_t oy0, int64_t oy1, int64_t* iy0, int64_t* iy1) {
  *iy0 = std::clamp<int64_t>(oy0 * s.stride - s.pad_top, 0, s.h);
  *iy1 = std::clamp<int64_t>((oy1 - 1) * s.stride - s.pad_top + s.kh, *iy0, s.h);
}

// The GEMM over output rows [oy0, oy1) of image b, whose input rows [iy0, iy1) start at `xf` (fp32,
// the image's planes: H * W apart) or `xp` (bf16 pair words, the band's planes: (iy1 - iy0) * W
// apart): the shape is re-cut to those rows, with the padding that falls inside the band. Each
// output pixel sums the same K in the same blocks as an unbanded call (KC depends on K only), so
// banding changes no bit. y is the image's output (planes s.out_plane() apart); `residual` starts
// at the band's row oy0, its planes res_plane apart.
void conv_rows(const Conv2dShape& s, const float* xf, const uint32_t* xp, int64_t iy0, int64_t iy1,
               int64_t oy0, int64_t oy1, const ConvWeights& w, const float* residual,
               int64_t res_plane, float* y, ConvAct act, ThreadPool* pool) {
  const GemmKernel& kern = w.packed().kernel();
  const bool bf16 = w.type() == WeightType::kBf16;
  const int64_t cin2 = (s.c_in + 1) / 2 * 2;
  const int64_t ow = s.out_w();
  Conv2dShape b = s;
  b.n = 1;
  b.h = iy1 - iy0;
  b.pad_top = int(iy0 - (oy0 * s.stride - s.pad_top));  // rows above the band that read as zero
  b.pad_bottom = int(std::max<int64_t>(0, (oy1 - 1) * s.stride - s.pad_top + s.kh - iy1));
  MACRO_CHECK(b.pad_top >= 0 && b.out_h() == oy1 - oy0 && b.out_w() == ow);
  Im2colCtx ctx{&b, xf, xp, cin2, oy1 - oy0, ow, kernels_for(w.packed().isa()).conv_rows32};
  ctx.split_cols = xp && s.stride == 2;  // convert_pairs split the rows
  ctx.x_plane = xf ? s.h * s.w : (iy1 - iy0) * s.w;
  detail::Operand oa{nullptr, nullptr, w.packed().panels(), w.packed().k_padded()};
  detail::Operand ob{pack_im2col, &ctx, nullptr, 0};
  detail::DriverShape ds;
  ds.M = s.c_out;
  ds.N = (oy1 - oy0) * ow;
  ds.K = conv_k(s, bf16);
  ds.C = y + oy0 * ow;
  ds.ldc = s.out_plane();
  // All output channels in one task (the im2col panels are then gathered once), up to 512. When
  // the weights outweigh the im2col panels (Cout >= pixels: the 16x16 and 8x8 U-Net levels, where
  // K = 9 Cin is long), the threads split the output channels instead, each reading its share of
  // the weights once and gathering the (small) panels itself; splitting the pixels would make
  // every thread stream all the weights.
  const int64_t threads = pool ? pool->size() : 1;
  if (threads > 1 && s.c_out >= ds.N && s.c_out >= threads * 4 * kern.mr) {
    const int64_t m_tasks = detail::round_up((s.c_out + 511) / 512, threads);
    ds.mc = detail::round_up((s.c_out + m_tasks - 1) / m_tasks, kern.mr);
    ds.m_only = true;
    // Every task would gather all the panels for itself (m_tasks times in all, twice per thread
    // for 1280 channels on 2 threads): gather the whole B once, the threads sharing the panels,
    // and hand it to the driver as prepacked (the same words, so the same sums). Up to 32 MB
    // (2560 -> 1280 channels at 2 x 16 x 16 pixels: 24 MB).
    const int64_t kp = detail::round_up(ds.K, kern.k_align), nr = kern.nr;
    const int64_t panels = (ds.N + nr - 1) / nr;
    const size_t panel_bytes = size_t(kp * nr * detail::packed_elem_bytes(kern.layout));
    const size_t bytes = size_t(panels) * panel_bytes;
    if (bytes <= (size_t(32) << 20)) {
      unsigned char* buf = static_cast<unsigned char*>(t_im2col.get(bytes));
      pool->parallel_for(
          size_t(panels),
          [&](size_t p0, size_t p1, int) {
            const int64_t c0 = int64_t(p0) * nr, c1 = std::min<int64_t>(ds.N, int64_t(p1) * nr);
            pack_im2col(&ctx, kern, false, c0, c1 - c0, 0, ds.K, buf + p0 * panel_bytes);
          },
          1);
      ob = detail::Operand{nullptr, nullptr, buf, kp};
    }
  } else {
    ds.mc = detail::round_up(std::min<int64_t>(s.c_out, 512), kern.mr);
  }
  ds.nc = int64_t(kern.nr) * std::max(1, 256 / kern.nr);
  GemmParams p;
  p.bias_m = w.bias();
  p.relu = act == ConvAct::kRelu;
  if (residual) {
    p.residual = residual;
    p.ldr = res_plane;
  }
  detail::run_gemm(kern, ds, oa, ob, p, pool);
}

// Input rows [iy0, iy1) of image xb [Cin, H, W] as pair words xp[Cin2/2][iy1 - iy0][W] (the
// path's OpsKernels::pair_words). For a stride-2 conv each row is stored split (split_cols): its
// even columns, then its odd ones, so that the columns one output row reads under a tap lie side
// by side.
void convert_pairs(const Conv2dShape& s, const float* xb, int64_t iy0, int64_t iy1, uint32_t* xp,
                   ThreadPool* pool) {
  const int64_t HW = s.h * s.w, W = s.w, n = (iy1 - iy0) * W, cin2 = (s.c_in + 1) / 2 * 2;
  const bool split = s.stride == 2;
  const auto pair_words = ops_kernels().pair_words;
  auto convert = [&](size_t p0, size_t p1, int) {
    thread_local std::vector<uint32_t> row_words;  // one split row's words, grown once
    if (split && row_words.size() < size_t(W)) row_words.resize(size_t(W));
    for (size_t cp = p0; cp < p1; ++cp) {
      const int64_t c0 = 2 * int64_t(cp), c1 = c0 + 1;
      const float* x0 = xb + c0 * HW + iy0 * W;
      const float* x1 = c1 < s.c_in ? xb + c1 * HW + iy0 * W : nullptr;
      uint32_t* dst = xp + cp * n;
      if (!split) {
        pair_words(dst, x0, x1, n);
        continue;
      }
      const int64_t even = (W + 1) / 2;
      for (int64_t r = 0; r < iy1 - iy0; ++r) {
        uint32_t* d = dst + r * W;
        const uint32_t* words = row_words.data();
        pair_words(row_words.data(), x0 + r * W, x1 ? x1 + r * W : nullptr, W);
        for (int64_t j = 0; j < even; ++j) d[j] = words[2 * j];
        for (int64_t j = 0; j < W / 2; ++j) d[even + j] = words[2 * j + 1];
      }
    }
  };
  if (pool)
    pool->parallel_for(size_t(cin2 / 2), convert, 1);
  else
    convert(0, size_t(cin2 / 2), 0);
}

}  // namespace

void conv2d(const Conv2dShape& s, const float* x, const ConvWeights& w, const float* residual,
            float* y, ConvAct act, ThreadPool* pool) {
  MACRO_CHECK(w.c_out() == s.c_out && w.c_in() == s.c_in && w.kh() == s.kh && w.kw() == s.kw);
  MACRO_CHECK(s.stride >= 1 && s.pad_top >= 0 && s.pad_left >= 0 && s.pad_bottom >= 0 &&
              s.pad_right >= 0);
  const int64_t oh = s.out_h(), ow = s.out_w();
  if (oh <= 0 || ow <= 0 || s.n <= 0 || s.c_out <= 0) return;
  const bool bf16 = w.type() == WeightType::kBf16;
  if (w.packed().empty() || detail::winograd_applies(s, w)) {
    detail::conv2d_winograd(s, x, w, residual, y, act, pool);
    return;
  }
  const int64_t cin2 = (s.c_in + 1) / 2 * 2;
  const int64_t HW = s.h * s.w, plane = s.out_plane();
  // A residual that is y itself keeps the bits of a separate residual: where the GEMM would fold
  // it into C (several K blocks, terms after the last), each band's rows are read from a copy.
  const bool copy_res =
      residual == y && detail::gemm_folds_aliased_residual(w.packed().kernel(), conv_k(s, bf16));
  // Bands of output rows: bf16 converts the input once per band into pair planes (then the halo
  // rows are converted twice), within g_pair_band_words; a copied residual stays within the same
  // budget of floats.
  int64_t band = s.out_h();
  if (bf16 && size_t(cin2 / 2 * HW) > g_pair_band_words) {
    const int64_t in_rows = std::max<int64_t>(s.kh, int64_t(g_pair_band_words) / (cin2 / 2 * s.w));
    band = std::max<int64_t>(1, (in_rows - s.kh) / s.stride + 1);
  }
  if (copy_res)
    band = std::min(band, std::max<int64_t>(1, int64_t(g_pair_band_words) / (s.c_out * ow)));
  for (int64_t b = 0; b < s.n; ++b) {
    const float* xb = x + b * s.c_in * HW;
    const float* rb = residual ? residual + b * s.c_out * plane : nullptr;
    float* yb = y + b * s.c_out * plane;
    for (int64_t oy0 = 0; oy0 < oh; oy0 += band) {
      const int64_t oy1 = std::min(oh, oy0 + band);
      const float* res_rows = rb ? rb + oy0 * ow : nullptr;
      int64_t res_plane = plane;
      if (copy_res) {
        const int64_t n = (oy1 - oy0) * ow;
        std::vector<float>& rc = t_residual_rows;
        if (rc.size() < size_t(s.c_out * n)) rc.resize(size_t(s.c_out * n));
        for (int64_t c = 0; c < s.c_out; ++c)
          std::memcpy(rc.data() + c * n, res_rows + c * plane, size_t(n) * sizeof(float));
        res_rows = rc.data();
        res_plane = n;
      }
      int64_t iy0, iy1;
      input_rows(s, oy0, oy1, &iy0, &iy1);
      if (!bf16) {
        conv_rows(s, xb + iy0 * s.w, nullptr, iy0, iy1, oy0, oy1, w, res_rows, res_plane, yb, act,
                  pool);
        continue;
      }
      std::vector<uint32_t>& xp = t_pair_planes;
      const size_t words = size_t(cin2 / 2 * (iy1 - iy0) * s.w);
      if (xp.size() < words) xp.resize(words);
      convert_pairs(s, xb, iy0, iy1, xp.data(), pool);
      conv_rows(s, nullptr, xp.data(), iy0, iy1, oy0, oy1, w, res_rows, res_plane, yb, act, pool);
    }
  }
}

void conv2d(const Conv2dShape& s, const float* x, const float* weight, const float* bias,
            const float* residual, float* y, ThreadPool* pool) {
  ConvWeights w = ConvWeights::pack(weight, bias, s.c_out, s.c_in, s.kh, s.kw, WeightType::kF32);
  conv2d(s, x, w, residual, y, pool);
}

void conv2d_reference(const Conv2dShape& s, const float* x, const float* weight, const float* bias,
                      const float* residual, float* y) {
  const int64_t oh = s.out_h(), ow = s.out_w();
  for (int64_t b = 0; b < s.n; ++b)
    for (int64_t co = 0; co < s.c_out; ++co)
      for (int64_t oy = 0; oy < oh; ++oy)
        for (int64_t ox = 0; ox < ow; ++ox) {
          double acc = bias ? bias[co] : 0.0;
          for (int64_t ci = 0; ci < s.c_in; ++ci)
            for (int dy = 0; dy < s.kh; ++dy) {
              const int64_t iy = oy * s.stride + dy - s.pad_top;
              if (iy < 0 || iy >= s.h) continue;
              for (int dx = 0; dx < s.kw; ++dx) {
                const int64_t ix = ox * s.stride + dx - s.pad_left;
                if (ix < 0 || ix >= s.w) continue;
                acc += double(weight[((co * s.c_in + ci) * s.kh + dy) * s.kw + dx]) *
                       double(x[((b * s.c_in + ci) * s.h + iy) * s.w + ix]);
              }
            }
          const int64_t o = ((b * s.c_out + co) * oh + oy) * ow + ox;
          if (residual) acc += residual[o];
          y[o] = float(acc);
        }
}

}  // namespace macro
