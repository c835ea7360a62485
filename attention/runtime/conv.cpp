// conv2d as an implicit GEMM over the shared GEMM driver (gemm.h): the packed weights are the A
// operand ([Cout, Cin*KH*KW] in MR-row panels), and the B panels (NR output pixels x a K block) are
// gathered straight from the NCHW input by pack_im2col below, tile by tile, into the driver's
// per-thread buffers. Stride-1 rows are copied as runs; padding is written as zeros. With bf16
// weights the panels are rounded to bf16 k pairs while gathering (fp32 accumulation and output).
#include "attention/runtime/conv.h"

#include <algorithm>
#include <cstring>

#include "attention/runtime/status.h"

namespace macro {
namespace {

struct Im2colCtx {
  const Conv2dShape* s;
  const float* x;  // one image [Cin, H, W]
  int64_t oh, ow;
};

// One run of consecutive output pixels on the same output row.
struct Segment {
  int col, len;
  int64_t oy, ox;
};

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

// One im2col row: the input values under tap (ci, dy, dx) for the panel's pixels; w floats, zeros
// for padding and for pixels past `count`.
void fill_row(const Im2colCtx& c, const Segment* segs, int nseg, int count, int w, int64_t ci,
              int64_t dy, int64_t dx, float* out_row) {
  const Conv2dShape& s = *c.s;
  const int64_t H = s.h, W = s.w;
  const int stride = s.stride;
  const float* xc = c.x + ci * H * W;
  for (int g = 0; g < nseg; ++g) {
    const Segment& sg = segs[g];
    float* out = out_row + sg.col;
    const int64_t iy = sg.oy * stride + dy - s.pad_top;
    if (iy < 0 || iy >= H) {
      std::memset(out, 0, sizeof(float) * sg.len);
      continue;
    }
    const float* row = xc + iy * W;
    const int64_t ix0 = sg.ox * stride + dx - s.pad_left;
    if (stride == 1) {
      const int64_t lo = std::clamp<int64_t>(-ix0, 0, sg.len);
      const int64_t hi = std::clamp<int64_t>(W - ix0, lo, sg.len);
      for (int64_t i = 0; i < lo; ++i) out[i] = 0.0f;
      std::memcpy(out + lo, row + ix0 + lo, sizeof(float) * size_t(hi - lo));
      for (int64_t i = hi; i < sg.len; ++i) out[i] = 0.0f;
    } else {
      for (int i = 0; i < sg.len; ++i) {
        const int64_t ix = ix0 + int64_t(i) * stride;
        out[i] = (ix >= 0 && ix < W) ? row[ix] : 0.0f;
      }
    }
  }
  if (count < w) std::memset(out_row + count, 0, sizeof(float) * size_t(w - count));
}

// Nearest-even bf16 of two floats as one pair word (low half = even k); branch-free, NaN quiet.
inline uint32_t bf16_bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  const uint32_t r = (u + 0x7fffu + ((u >> 16) & 1u)) >> 16;
  return (u & 0x7fffffffu) > 0x7f800000u ? ((u >> 16) | 0x40u) : r;
}

void pack_im2col(const void* ctx, const GemmKernel& kern, bool is_a, int64_t r0, int64_t rows,
                 int64_t k0, int64_t kc, void* dst_v) {
  MACRO_CHECK(!is_a);
  const Im2colCtx& c = *static_cast<const Im2colCtx*>(ctx);
  const Conv2dShape& s = *c.s;
  const int w = kern.nr;
  MACRO_CHECK(w <= 64);
  const int64_t kcp = detail::round_up(kc, kern.k_align);
  const int64_t khw = int64_t(s.kh) * s.kw;
  const bool f32 = kern.layout == PackLayout::kF32;
  Segment segs[64];
  alignas(64) float pair_rows[2][64];
  const int64_t panels = (rows + w - 1) / w;
  for (int64_t p = 0; p < panels; ++p) {
    const int64_t px0 = r0 + p * w;
    const int count = int(std::min<int64_t>(w, r0 + rows - px0));
    const int nseg = make_segments(c, px0, count, segs);
    int64_t ci = k0 / khw, rem = k0 % khw;
    int64_t dy = rem / s.kw, dx = rem % s.kw;
    auto next_tap = [&] {
      if (++dx == s.kw) {
        dx = 0;
        if (++dy == s.kh) {
          dy = 0;
          ++ci;
        }
      }
    };
    if (f32) {
      float* d = static_cast<float*>(dst_v) + p * kcp * w;
      for (int64_t k = 0; k < kcp; ++k) {
        if (k >= kc) {
          std::memset(d + k * w, 0, sizeof(float) * w);
          continue;
        }
        fill_row(c, segs, nseg, count, w, ci, dy, dx, d + k * w);
        next_tap();
      }
    } else {
      // bf16 k pairs ([kcp/2][w][2]): build the two fp32 rows, then round and interleave.
      uint32_t* d = static_cast<uint32_t*>(dst_v) + p * (kcp / 2) * w;
      for (int64_t q = 0; q < kcp / 2; ++q) {
        for (int h = 0; h < 2; ++h) {
          if (2 * q + h < kc) {
            fill_row(c, segs, nseg, count, w, ci, dy, dx, pair_rows[h]);
            next_tap();
          } else {
            std::memset(pair_rows[h], 0, sizeof(float) * w);
          }
        }
        uint32_t* dq = d + q * w;
        for (int j = 0; j < w; ++j)
          dq[j] = bf16_bits(pair_rows[0][j]) | (bf16_bits(pair_rows[1][j]) << 16);
      }
    }
  }
}

}  // namespace

ConvWeights ConvWeights::pack(const float* w, const float* bias, int64_t c_out, int64_t c_in,
                              int kh, int kw, WeightType type, Isa isa) {
  ConvWeights cw;
  cw.c_out_ = c_out;
  cw.c_in_ = c_in;
  cw.kh_ = kh;
  cw.kw_ = kw;
  const int64_t K = c_in * kh * kw;
  cw.packed_ = PackedWeights::pack_as_a(w, c_out, K, K, type, isa);
  if (bias) cw.bias_.assign(bias, bias + c_out);
  return cw;
}

void conv2d(const Conv2dShape& s, const float* x, const ConvWeights& w, const float* residual,
            float* y, ThreadPool* pool) {
  MACRO_CHECK(w.c_out() == s.c_out && w.c_in() == s.c_in && w.kh() == s.kh && w.kw() == s.kw);
  MACRO_CHECK(s.stride >= 1 && s.pad_top >= 0 && s.pad_left >= 0 && s.pad_bottom >= 0 &&
              s.pad_right >= 0);
  const int64_t oh = s.out_h(), ow = s.out_w();
  if (oh <= 0 || ow <= 0 || s.n <= 0 || s.c_out <= 0) return;
  const GemmKernel& kern = w.packed().kernel();
  const int64_t K = s.c_in * s.kh * s.kw;
  const int64_t npix = oh * ow;
  for (int64_t b = 0; b < s.n; ++b) {
    Im2colCtx ctx{&s, x + b * s.c_in * s.h * s.w, oh, ow};
    detail::Operand oa{nullptr, nullptr, w.packed().panels(), w.packed().k_padded()};
    detail::Operand ob{pack_im2col, &ctx, nullptr, 0};
    detail::DriverShape ds;
    ds.M = s.c_out;
    ds.N = npix;
    ds.K = K;
    ds.C = y + b * s.c_out * npix;
    ds.ldc = npix;
    // All output channels in one task (the im2col panels are then gathered once), up to 512.
    ds.mc = detail::round_up(std::min<int64_t>(s.c_out, 512), kern.mr);
    ds.nc = int64_t(kern.nr) * std::max(1, 256 / kern.nr);
    GemmParams p;
    p.bias_m = w.bias();
    if (residual) {
      p.residual = residual + b * s.c_out * npix;
      p.ldr = npix;
    }
    detail::run_gemm(kern, ds, oa, ob, p, pool);
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
