// Winograd F(2x2, 3x3) bf16 and fp32 convs (attention/runtime/conv_winograd.h, conv.h's
// ConvWinograd).
//
// Bound, per output (b, co, oy, ox) in tile (ty, tx) at position (i, j):
//   bf16: |y - ref| <= (2^-8 + 2^-16 + (Cin + 10) 2^-24) S + 2^-22 (|ref| + |bias| + |residual|)
//   fp32: |y - ref| <= (Cin + 10) 2^-24 S + 2^-22 (|ref| + |bias| + |residual|)
//   S = sum_ci sum_xi |A^T|[i][xi/4] |A^T|[j][xi%4] (|G| |g| |G|^T)_xi (|B|^T |d| |B|)_xi
// with ref the double loop nest (conv2d_reference), d the tile's 4x4 input patch and g the 3x3
// kernel. bf16: U and V are each rounded to bf16 once (2^-9 relative each, to the magnitudes
// above, which also bound their fp32 sums) and the products are exact. Both: U is rounded to fp32
// once and V's two levels of adds round twice (3 roundings, under the 10), fp32 accumulation over
// Cin and the output transform add at most (Cin + 8) roundings, bias and residual two more. These
// worst cases are loose (max error / bound ~0.03-0.09 for bf16), so the typical error is also
// checked: rms error at most 3x the direct path's of the same type on the same weights (measured
// 1.6-2.0x for bf16, 0.7-1.3x for fp32; max error / bound ~0.002-0.017 for fp32).
#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <random>
#include <utility>
#include <vector>

#include "attention/runtime/conv.h"
#include "attention/runtime/conv_winograd.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/half.h"
#include "test_support.h"

namespace macro {
namespace {

using test::supported_isas;

struct ModeGuard {
  Isa isa = active_isa();
  ConvWinograd mode;
  size_t chunk;
  explicit ModeGuard(ConvWinograd m)
      : mode(conv2d_set_winograd(m)), chunk(conv2d_set_winograd_chunk(0)) {}
  ~ModeGuard() {
    (void)set_isa(isa);
    conv2d_set_winograd(mode);
    conv2d_set_winograd_chunk(chunk);
  }
};

using test::random_vec;

Conv2dShape shape(int64_t n, int64_t ci, int64_t h, int64_t w, int64_t co, int pad) {
  return Conv2dShape::make(n, ci, h, w, co, 3, 1, pad);
}

// The bound above for every output of s (row_origin honoured).
std::vector<double> winograd_bound(const Conv2dShape& s, const float* x, const float* w,
                                   const float* bias, const float* res, const float* ref, bool f32,
                                   double* s_over_direct) {
  const int64_t oh = s.out_h(), ow = s.out_w();
  const int phase = int(s.row_origin & 1);
  const double at[2][4] = {{1, 1, 1, 0}, {0, 1, 1, 1}};  // |A^T|
  // |G| |g| |G|^T per (co, ci).
  std::vector<double> ua(size_t(s.c_out * s.c_in * 16));
  for (int64_t k = 0; k < s.c_out * s.c_in; ++k) {
    const float* g = w + k * 9;
    double t[4][3];
    for (int c = 0; c < 3; ++c) {
      const double g0 = std::abs(g[c]), g1 = std::abs(g[3 + c]), g2 = std::abs(g[6 + c]);
      t[0][c] = g0, t[1][c] = t[2][c] = 0.5 * (g0 + g1 + g2), t[3][c] = g2;
    }
    for (int i = 0; i < 4; ++i) {
      const double r = 0.5 * (t[i][0] + t[i][1] + t[i][2]);
      const double u[4] = {t[i][0], r, r, t[i][2]};
      for (int j = 0; j < 4; ++j) ua[size_t(k * 16 + i * 4 + j)] = u[j];
    }
  }
  std::vector<double> bound(size_t(s.n * s.c_out * oh * ow));
  double ratio_sum = 0;
  int64_t ratio_n = 0;
  for (int64_t b = 0; b < s.n; ++b)
    for (int64_t oy = 0; oy < oh; ++oy)
      for (int64_t ox = 0; ox < ow; ++ox) {
        const int64_t ty = (oy + phase) / 2, tx = ox / 2;
        const int ti = int((oy + phase) % 2), tj = int(ox % 2);
        const int64_t iy0 = 2 * ty - phase - s.pad_top, ix0 = 2 * tx - s.pad_left;
        // |B|^T |d| |B| per input channel (|B^T| rows: 1010, 0110, 0110, 0101).
        std::vector<double> va(size_t(s.c_in * 16));
        std::vector<double> wx(size_t(s.c_in));  // sum over the 3x3 window of |x| (for the ratio)
        for (int64_t ci = 0; ci < s.c_in; ++ci) {
          double d[4][4];
          for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) {
              const int64_t iy = iy0 + i, ix = ix0 + j;
              d[i][j] = iy >= 0 && iy < s.h && ix >= 0 && ix < s.w
                            ? std::abs(x[((b * s.c_in + ci) * s.h + iy) * s.w + ix])
                            : 0.0;
            }
          double r[4][4];
          for (int j = 0; j < 4; ++j) {
            r[0][j] = d[0][j] + d[2][j];
            r[1][j] = r[2][j] = d[1][j] + d[2][j];
            r[3][j] = d[1][j] + d[3][j];
          }
          for (int i = 0; i < 4; ++i) {
            va[size_t(ci * 16 + i * 4 + 0)] = r[i][0] + r[i][2];
            va[size_t(ci * 16 + i * 4 + 1)] = r[i][1] + r[i][2];
            va[size_t(ci * 16 + i * 4 + 2)] = r[i][1] + r[i][2];
            va[size_t(ci * 16 + i * 4 + 3)] = r[i][1] + r[i][3];
          }
        }
        for (int64_t co = 0; co < s.c_out; ++co) {
          double S = 0, direct = 0;
          for (int64_t ci = 0; ci < s.c_in; ++ci) {
            for (int xi = 0; xi < 16; ++xi)
              S += at[ti][xi / 4] * at[tj][xi % 4] * ua[size_t((co * s.c_in + ci) * 16 + xi)] *
                   va[size_t(ci * 16 + xi)];
            for (int dy = 0; dy < 3; ++dy)
              for (int dx = 0; dx < 3; ++dx) {
                const int64_t iy = oy + dy - s.pad_top, ix = ox + dx - s.pad_left;
                if (iy < 0 || iy >= s.h || ix < 0 || ix >= s.w) continue;
                direct += std::abs(double(w[((co * s.c_in + ci) * 3 + dy) * 3 + dx]) *
                                   double(x[((b * s.c_in + ci) * s.h + iy) * s.w + ix]));
              }
          }
          const int64_t o = ((b * s.c_out + co) * oh + oy) * ow + ox;
          const double extra = std::abs(double(ref[o])) + (bias ? std::abs(bias[co]) : 0.0) +
                               (res ? std::abs(res[o]) : 0.0);
          const double rounding = f32 ? 0.0 : std::ldexp(1.0, -8) + std::ldexp(1.0, -16);
          bound[size_t(o)] = (rounding + double(s.c_in + 10) * std::ldexp(1.0, -24)) * S +
                             std::ldexp(1.0, -22) * extra;
          if (direct > 0) ratio_sum += S / direct, ++ratio_n;
        }
      }
  if (s_over_direct) *s_over_direct = ratio_n ? ratio_sum / double(ratio_n) : 0.0;
  return bound;
}

struct Case {
  Conv2dShape s;
  bool bias = true, residual = false, alias = false, relu = false;
};

// Runs the conv on the active path (Winograd forced) and checks it against the bound; returns y.
std::vector<float> check_case(const Case& c, WeightType type, ThreadPool* pool) {
  const bool f32 = type == WeightType::kF32;
  const Conv2dShape& s = c.s;
  auto x = random_vec(size_t(s.n * s.c_in * s.h * s.w), 21);
  auto w = random_vec(size_t(s.c_out * s.c_in * 9), 22);
  auto bias = random_vec(size_t(s.c_out), 23);
  const size_t ny = size_t(s.n * s.c_out * s.out_h() * s.out_w());
  auto res = random_vec(ny, 24);
  std::vector<float> ref(ny);
  conv2d_reference(s, x.data(), w.data(), c.bias ? bias.data() : nullptr,
                   c.residual ? res.data() : nullptr, ref.data());
  ConvWeights cw =
      ConvWeights::pack(w.data(), c.bias ? bias.data() : nullptr, s.c_out, s.c_in, 3, 3, type);
  REQUIRE(cw.winograd().size() == 16);
  REQUIRE(detail::winograd_applies(s, cw));
  std::vector<float> y(ny, NAN);
  if (c.alias) y = res;
  conv2d(s, x.data(), cw, c.residual ? (c.alias ? y.data() : res.data()) : nullptr, y.data(),
         c.relu ? ConvAct::kRelu : ConvAct::kNone, pool);
  double ratio = 0;
  const std::vector<double> bound =
      winograd_bound(s, x.data(), w.data(), c.bias ? bias.data() : nullptr,
                     c.residual ? res.data() : nullptr, ref.data(), f32, &ratio);
  size_t bad = 0, first = 0, clamped = 0;
  double worst = 0;  // max err / bound
  for (size_t i = 0; i < ny; ++i) {
    const double r = c.relu ? std::max(0.0, double(ref[i])) : double(ref[i]);
    const double err = std::abs(double(y[i]) - r);
    clamped += c.relu && y[i] == 0.0f;
    if (!(err <= bound[i])) {
      if (!bad) first = i;
      ++bad;
    }
    worst = std::max(worst, err / bound[i]);
  }
  INFO(isa_name(active_isa()) << (f32 ? " fp32" : " bf16") << " N=" << s.n << " Cin=" << s.c_in
                              << " " << s.h << "x" << s.w << " Cout=" << s.c_out
                              << " pad=" << s.pad_top << " origin=" << s.row_origin
                              << " res=" << c.residual << " alias=" << c.alias << " relu=" << c.relu
                              << " mean S/sum|w||x|=" << ratio << " max err/bound=" << worst
                              << " first bad " << first << ": y " << y[first] << " ref "
                              << ref[first] << " bound " << bound[first]);
  CHECK(bad == 0);
  if (c.relu) CHECK(clamped > ny / 4);
  // The typical error against the direct path's of the same type on the same weights (mode off).
  std::vector<float> yd(ny, NAN);
  if (c.alias) yd = res;
  const ConvWinograd mode = conv2d_set_winograd(ConvWinograd::kOff);
  conv2d(s, x.data(), cw, c.residual ? (c.alias ? yd.data() : res.data()) : nullptr, yd.data(),
         c.relu ? ConvAct::kRelu : ConvAct::kNone, pool);
  conv2d_set_winograd(mode);
  double ew = 0, ed = 0;
  for (size_t i = 0; i < ny; ++i) {
    const double r = c.relu ? std::max(0.0, double(ref[i])) : double(ref[i]);
    ew += (y[i] - r) * (y[i] - r);
    ed += (yd[i] - r) * (yd[i] - r);
  }
  INFO("rms error winograd / direct = " << std::sqrt(ew / ed));
  CHECK(std::sqrt(ew) <= 3.0 * std::sqrt(ed));
  CHECK(std::memcmp(y.data(), yd.data(), ny * 4) != 0);
  return y;
}

const Case kCases[] = {
    {shape(1, 5, 7, 9, 3, 1)},                               // odd H, W, Cin
    {shape(1, 8, 1, 20, 16, 1), true, true},                 // a 1-row image
    {shape(2, 33, 11, 13, 29, 1), true, true, true},         // batch 2, Cout % MR != 0, alias y
    {shape(1, 16, 9, 10, 20, 0), false, true, false, true},  // pad 0, relu
    {shape(1, 70, 6, 70, 24, 1), true, true, true, true},    // runs across rows and 16-tile groups
};

}  // namespace

TEST_CASE("winograd: the scalar twin and every path against the double loop nest", "[winograd]") {
  ModeGuard guard(ConvWinograd::kAlways);
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    for (const Case& c : kCases)
      for (WeightType type : {WeightType::kBf16, WeightType::kF32}) check_case(c, type, nullptr);
  }
}

TEST_CASE("winograd: the vector transforms equal the scalar twins bit for bit", "[winograd]") {
  const detail::WinogradTransforms& sc = detail::winograd_scalar_transforms();
  // bf16 on AVX512-BF16 (vcvtne2ps2bf16), on plain AVX-512 and on AVX2 (rounding in integer
  // ops), fp32 on AVX-512 and AVX2.
  const std::pair<bool, Isa> cases[] = {{false, Isa::kAvx512Bf16}, {false, Isa::kAvx512},
                                        {true, Isa::kAvx512},      {false, Isa::kAvx2},
                                        {true, Isa::kAvx2}};
  for (const auto& [f32, isa] : cases) {
    if (!isa_supported(isa)) {
      WARN("no " << isa_name(isa) << " on this machine: only the scalar " << (f32 ? "fp32" : "bf16")
                 << " transforms exist here");
      continue;
    }
    const detail::WinogradTransforms& vx = detail::winograd_transforms(isa, f32);
    REQUIRE(vx.input != sc.input);
    INFO((f32 ? "fp32 " : "bf16 ") << vx.name);
    // A chunk of 45 tiles from tile 5 of a 17 x 13 output (TW = 7: runs cut by rows and
    // 16-groups).
    for (int pad : {0, 1})
      for (int phase : {0, 1}) {
        const int64_t cin = 7, h = 19, w = 13 + 2 * (1 - pad), oh = h + 2 * pad - 2,
                      ow = w + 2 * pad - 2;
        const int64_t tw = (ow + 1) / 2, th = (oh + phase + 1) / 2, tiles = th * tw;
        const int64_t t0 = 5, nt = std::min<int64_t>(45, tiles - t0);
        std::vector<detail::WinoRun> runs;
        for (int64_t col = 0; col < nt;) {
          const int64_t t = t0 + col, len = std::min({nt - col, tw - t % tw, 16 - col % 16});
          runs.push_back({t / tw, t % tw, int(col), int(len)});
          col += len;
        }
        auto x = random_vec(size_t(cin * h * w), 31);
        x[3] = NAN;  // a NaN rounds to the same quiet NaN in both
        // A patch of fp32 denormals (V denormal too: flushed to zero by both bf16 transforms).
        for (int64_t i = 0; i < 4; ++i)
          for (int64_t j = 0; j < 4; ++j)
            x[size_t(2 * w * h + (6 + i) * w + 4 + j)] = 3e-39f * float(i - j);
        const int nr = 32;
        // Rows per panel: 4 pairs (bf16) or 7 channels (fp32), plus one the transform leaves.
        const int64_t k_rows = f32 ? 8 : 5, T = 64, xs = T * k_rows;
        std::vector<uint32_t> v1(size_t(16 * xs), 0xdeadbeef), v2 = v1;
        detail::WinoInput in;
        in.x = x.data(), in.c_in = cin, in.h = h, in.w = w;
        in.pad_top = in.pad_left = pad, in.row_phase = phase;
        in.q0 = 0, in.q1 = f32 ? cin : 4, in.runs = runs.data(), in.nruns = int(runs.size());
        in.nr = nr, in.k_rows = k_rows, in.xi_stride = xs;
        in.f32 = f32;
        in.v = v1.data();
        sc.input(in);
        in.v = v2.data();
        vx.input(in);
        CHECK(std::memcmp(v1.data(), v2.data(), v1.size() * 4) == 0);
        size_t written = 0;
        for (uint32_t u : v1) written += u != 0xdeadbeef;
        CHECK(written == size_t(16 * nt * in.q1));
        // Output: M for 3 channels from 1, bias, residual aliasing y, ReLU.
        const int64_t cout = 4, co0 = 1, nco = 3;
        auto m = random_vec(size_t(16 * nco * T), 32);
        auto bias = random_vec(size_t(cout), 33);
        for (bool relu : {false, true})
          for (bool with_res : {false, true}) {
            auto y1 = random_vec(size_t(cout * oh * ow), 34), y2 = y1;
            detail::WinoOutput out;
            out.m = m.data(), out.ldm = T, out.xi_stride = nco * T, out.co0 = co0, out.nco = nco;
            out.bias = bias.data(), out.oh = oh, out.ow = ow, out.plane = oh * ow;
            out.row_phase = phase;
            out.relu = relu, out.runs = runs.data(), out.nruns = int(runs.size());
            out.y = y1.data(), out.residual = with_res ? y1.data() : nullptr;
            sc.output(out);
            out.y = y2.data(), out.residual = with_res ? y2.data() : nullptr;
            vx.output(out);
            INFO("pad " << pad << " phase " << phase << " relu " << relu << " res " << with_res);
            CHECK(std::memcmp(y1.data(), y2.data(), y1.size() * 4) == 0);
          }
      }
  }
}

// A 3x3 conv's random input, weights, bias and residual (seeds seed .. seed + 3).
struct ConvCase {
  Conv2dShape s;
  std::vector<float> x, w, b, r;
};
ConvCase make_case(const Conv2dShape& s, unsigned seed) {
  return {s, random_vec(size_t(s.n * s.c_in * s.h * s.w), seed),
          random_vec(size_t(s.c_out * s.c_in * 9), seed + 1), random_vec(size_t(s.c_out), seed + 2),
          random_vec(size_t(s.n * s.c_out * s.out_h() * s.out_w()), seed + 3)};
}

// Output rows [y0, y1) of image 1 of s as their own conv, re-cut like Conv2d::forward_rows
// (row_origin its first row): the band's shape, and its input rows gathered into xb.
Conv2dShape band_of_image1(const Conv2dShape& s, const std::vector<float>& x, int64_t y0,
                           int64_t y1, std::vector<float>* xb) {
  const int64_t iy0 = std::max<int64_t>(0, y0 - 1), iy1 = std::min(s.h, y1 + 1);
  Conv2dShape bs = s;
  bs.n = 1, bs.h = iy1 - iy0;
  bs.pad_top = int(1 - (y0 - iy0)), bs.pad_bottom = int(1 - (iy1 - y1));
  bs.row_origin = y0;
  xb->resize(size_t(s.c_in * bs.h * s.w));
  for (int64_t c = 0; c < s.c_in; ++c)
    std::memcpy(xb->data() + c * bs.h * s.w, x.data() + ((s.c_in + c) * s.h + iy0) * s.w,
                size_t(bs.h * s.w) * 4);
  return bs;
}

// Row bands of 3 rows of image 1 (each re-cut like Conv2d::forward_rows, row_origin its first
// row) written straight into their rows of a whole-image output (Conv2dShape::y_plane), with that
// output as the residual in place (it starts as the residual): the whole image's bits, base.
void check_bands_in_place(const Conv2dShape& s, const std::vector<float>& x,
                          const std::vector<float>& r, const ConvWeights& cw,
                          const std::vector<float>& base, ThreadPool* pool) {
  const int64_t oh = s.out_h(), ow = s.out_w(), rows = 3;
  std::vector<float> yw(r.begin() + s.c_out * oh * ow, r.begin() + 2 * s.c_out * oh * ow);
  std::vector<float> xb;
  for (int64_t y0 = 0; y0 < oh; y0 += rows) {
    Conv2dShape bs = band_of_image1(s, x, y0, std::min(oh, y0 + rows), &xb);
    bs.y_plane = oh * ow;
    conv2d(bs, xb.data(), cw, yw.data() + y0 * ow, yw.data() + y0 * ow, pool);
  }
  INFO(isa_name(active_isa()) << (cw.type() == WeightType::kF32 ? " fp32" : " bf16")
                              << (cw.winograd().empty() ? " direct" : " winograd"));
  CHECK(std::memcmp(yw.data(), base.data() + s.c_out * oh * ow, yw.size() * 4) == 0);
}

TEST_CASE("winograd: bit-identical for 1 and 2 threads, any chunk size and row bands",
          "[winograd]") {
  ModeGuard guard(ConvWinograd::kAlways);
  ThreadPool pool(2);
  const ConvCase cc = make_case(shape(2, 40, 23, 37, 30, 1), 41);
  const Conv2dShape& s = cc.s;
  const std::vector<float>&x = cc.x, &w = cc.w, &b = cc.b, &r = cc.r;
  const int64_t oh = s.out_h(), ow = s.out_w();
  const size_t ny = r.size();
  for (Isa isa : supported_isas())
    for (WeightType type : {WeightType::kBf16, WeightType::kF32}) {
      REQUIRE(set_isa(isa));
      const char* tname = type == WeightType::kF32 ? " fp32" : " bf16";
      ConvWeights cw = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3, type);
      REQUIRE(cw.winograd().size() == 16);
      std::vector<float> base(ny);
      conv2d_set_winograd_chunk(0);
      conv2d(s, x.data(), cw, r.data(), base.data(), nullptr);
      for (size_t chunk : {size_t(16), size_t(32), size_t(64), size_t(1000)})
        for (ThreadPool* p : {static_cast<ThreadPool*>(nullptr), &pool}) {
          conv2d_set_winograd_chunk(chunk);
          std::vector<float> y(ny, NAN);
          conv2d(s, x.data(), cw, r.data(), y.data(), p);
          INFO(isa_name(isa) << tname << " chunk " << chunk << " threads " << (p ? 2 : 1));
          CHECK(std::memcmp(y.data(), base.data(), ny * 4) == 0);
        }
      conv2d_set_winograd_chunk(0);
      conv2d_release_scratch();  // regrown by the next call
      // Row bands of 3 (odd starts) and 4 rows of image 1, each re-cut like Conv2d::forward_rows
      // with row_origin = its first row, give the whole image's rows.
      for (int64_t rows : {3, 4}) {
        for (int64_t y0 = 0; y0 < oh; y0 += rows) {
          const int64_t y1 = std::min(oh, y0 + rows);
          std::vector<float> xb, rb(size_t(s.c_out * (y1 - y0) * ow));
          const Conv2dShape bs = band_of_image1(s, x, y0, y1, &xb);
          REQUIRE(bs.out_h() == y1 - y0);
          for (int64_t c = 0; c < s.c_out; ++c)
            std::memcpy(rb.data() + c * (y1 - y0) * ow, r.data() + ((s.c_out + c) * oh + y0) * ow,
                        size_t((y1 - y0) * ow) * 4);
          std::vector<float> yb(rb.size(), NAN);
          conv2d(bs, xb.data(), cw, rb.data(), yb.data(), &pool);
          bool same = true;
          for (int64_t c = 0; c < s.c_out; ++c)
            same = same && std::memcmp(yb.data() + c * (y1 - y0) * ow,
                                       base.data() + ((s.c_out + c) * oh + y0) * ow,
                                       size_t((y1 - y0) * ow) * 4) == 0;
          INFO(isa_name(isa) << tname << " band rows " << rows << " from " << y0);
          CHECK(same);
        }
      }
      check_bands_in_place(s, x, r, cw, base, &pool);
      // The same with the direct conv's weights (the GEMM writes the rows through its ldc).
      conv2d_set_winograd(ConvWinograd::kOff);
      ConvWeights direct = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3, type);
      conv2d_set_winograd(ConvWinograd::kAlways);
      REQUIRE(direct.winograd().empty());
      std::vector<float> base_direct(ny);
      conv2d(s, x.data(), direct, r.data(), base_direct.data(), &pool);
      check_bands_in_place(s, x, r, direct, base_direct, &pool);
    }
}

TEST_CASE("conv2d: direct rows in place over several K blocks keep a separate residual's bits",
          "[winograd][conv]") {
  test::KcCap cap(384);
  // K = 9 x 96 = 864 spans several K blocks on every path, where the GEMM would fold a residual
  // that aliases C into C (another summation order); conv2d reads it from a copy instead.
  ModeGuard guard(ConvWinograd::kOff);
  ThreadPool pool(2);
  const ConvCase cc = make_case(shape(2, 96, 9, 21, 20, 1), 61);
  for (WeightType type : {WeightType::kBf16, WeightType::kF32})
    for (Isa isa : supported_isas()) {
      REQUIRE(set_isa(isa));
      INFO(isa_name(isa) << (type == WeightType::kF32 ? " fp32" : " bf16"));
      ConvWeights cw =
          ConvWeights::pack(cc.w.data(), cc.b.data(), cc.s.c_out, cc.s.c_in, 3, 3, type);
      REQUIRE(cw.winograd().empty());
      std::vector<float> base(cc.r.size()), whole = cc.r;
      conv2d(cc.s, cc.x.data(), cw, cc.r.data(), base.data(), &pool);
      check_bands_in_place(cc.s, cc.x, cc.r, cw, base, &pool);
      conv2d(cc.s, cc.x.data(), cw, whole.data(), whole.data(), &pool);  // the whole call in place
      CHECK(std::memcmp(whole.data(), base.data(), base.size() * 4) == 0);
      // ... and by bands of one output row (the copied residual rows and the bf16 pair planes).
      const size_t old_band = conv2d_set_pair_band(64);
      whole = cc.r;
      conv2d(cc.s, cc.x.data(), cw, whole.data(), whole.data(), &pool);
      conv2d_set_pair_band(old_band);
      CHECK(std::memcmp(whole.data(), base.data(), base.size() * 4) == 0);
    }
}

TEST_CASE("winograd: modes, pack rule, and the direct path when forced", "[winograd]") {
  ModeGuard guard(ConvWinograd::kAuto);
  const Conv2dShape s = shape(1, 64, 12, 20, 64, 1);
  auto x = random_vec(size_t(s.c_in * s.h * s.w), 51);
  auto w = random_vec(size_t(s.c_out * s.c_in * 9), 52);
  auto b = random_vec(size_t(s.c_out), 53);
  const size_t ny = size_t(s.c_out * s.out_h() * s.out_w());
  // The direct bf16 path: the loop nest on bf16-rounded inputs and weights to fp32 rounding.
  auto round = [](std::vector<float> v) {
    for (float& f : v) f = bf16_to_f32(f32_to_bf16(f));
    return v;
  };
  auto x16 = round(x), w16 = round(w);
  std::vector<float> ref16(ny);
  conv2d_reference(s, x16.data(), w16.data(), b.data(), nullptr, ref16.data());
  auto max_err = [&](const std::vector<float>& y) {
    double e = 0, m = 1e-30;
    for (size_t i = 0; i < ny; ++i) {
      e = std::max(e, std::abs(double(y[i]) - ref16[i]));
      m = std::max(m, std::abs(double(ref16[i])));
    }
    return e / m;
  };
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    INFO(isa_name(isa));
    conv2d_set_winograd(ConvWinograd::kAuto);
    ConvWeights auto_w =
        ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3, WeightType::kBf16);
    CHECK(auto_w.winograd().size() == 16);  // 64 channels qualify
    CHECK(auto_w.bytes() > auto_w.packed().bytes() * 2);
    ConvWeights small =
        ConvWeights::pack(w.data(), b.data(), 16, 16 * 4, 3, 3, WeightType::kBf16);  // Cout 16
    CHECK(small.winograd().empty());
    const std::vector<float> w_wide(size_t(64 * 1280 * 9), 0.25f);
    ConvWeights wide = ConvWeights::pack(w_wide.data(), nullptr, 64, 1280, 3, 3, WeightType::kBf16);
    CHECK(wide.winograd().empty());  // Cin 1280: no packs under kAuto
    // fp32 packs under kAuto only where the fp32 transforms are vector code (AVX2 and up).
    const bool f32_fast = isa == Isa::kAvx2 || isa == Isa::kAvx512 || isa == Isa::kAvx512Bf16 ||
                          isa == Isa::kAmx;
    ConvWeights f32 = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3);
    CHECK(f32.winograd().size() == (f32_fast ? 16u : 0u));
    // Auto: bf16 and fp32 on AVX2 and up (the paths with vector transforms), and only with
    // enough tiles (60 here: too few).
    CHECK_FALSE(detail::winograd_applies(s, auto_w));
    Conv2dShape big = s;
    big.h = 16, big.w = 16;  // 64 tiles
    CHECK(detail::winograd_applies(big, auto_w) == f32_fast);
    if (f32_fast) {
      CHECK_FALSE(detail::winograd_applies(s, f32));
      CHECK(detail::winograd_applies(big, f32));
    }
    Conv2dShape s2 = big;
    s2.stride = 2;
    CHECK_FALSE(detail::winograd_applies(s2, auto_w));
    // Forced off: no packs are built, and the direct path runs (exact bf16 inputs and weights).
    conv2d_set_winograd(ConvWinograd::kOff);
    ConvWeights off_w =
        ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3, WeightType::kBf16);
    CHECK(off_w.winograd().empty());
    std::vector<float> y_direct(ny, NAN), y_off(ny, NAN), y_wino(ny, NAN);
    conv2d(s, x.data(), off_w, nullptr, y_direct.data(), nullptr);
    conv2d(s, x.data(), auto_w, nullptr, y_off.data(), nullptr);  // packs present, mode off
    CHECK(max_err(y_direct) <= 1e-5);
    CHECK(std::memcmp(y_off.data(), y_direct.data(), ny * 4) == 0);
    // Always: the same weights take the Winograd path (a different rounding: not the direct bits).
    conv2d_set_winograd(ConvWinograd::kAlways);
    conv2d(s, x.data(), auto_w, nullptr, y_wino.data(), nullptr);
    CHECK(std::memcmp(y_wino.data(), y_direct.data(), ny * 4) != 0);
    CHECK(max_err(y_wino) > 1e-5);
    CHECK(test::compare(y_wino, ref16).rel_l2 <= 1e-2);
    // stride1_only: the direct pack is dropped and every call is Winograd, even with the mode off
    // and under the tile threshold; the bits are the same weights' Winograd bits.
    conv2d_set_winograd(ConvWinograd::kAuto);
    ConvWeights lean = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3,
                                         WeightType::kBf16, isa, /*stride1_only=*/true);
    CHECK(lean.packed().empty());
    CHECK(lean.type() == WeightType::kBf16);
    CHECK(lean.bytes() + auto_w.packed().bytes() == auto_w.bytes());
    conv2d_set_winograd(ConvWinograd::kOff);
    std::vector<float> y_lean(ny, NAN);
    conv2d(s, x.data(), lean, nullptr, y_lean.data(), nullptr);
    CHECK(std::memcmp(y_lean.data(), y_wino.data(), ny * 4) == 0);
    // ... but with the mode off at pack time there are no packs: the direct pack stays.
    ConvWeights kept = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3,
                                         WeightType::kBf16, isa, /*stride1_only=*/true);
    CHECK_FALSE(kept.packed().empty());
    CHECK(kept.winograd().empty());
  }
}

}  // namespace macro
