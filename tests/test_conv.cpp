// conv2d (attention/runtime/conv.h): every kernel path against the double-precision loop nest
// (conv2d_reference), on the networks' conv kinds at small odd sizes.
// Bound: max |y - ref| <= 1e-5 * max |ref| (fp32 accumulation over K = Cin*KH*KW <= 1000).
// bf16 weights: the same bound against the reference on bf16-rounded inputs and weights, and
// rel L2 <= 1e-2 against the fp32 reference.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/half.h"
#include "test_support.h"

namespace macro {
namespace {

using test::supported_isas;

using test::IsaGuard;

using test::random_vec;

double max_rel_err(const std::vector<float>& y, const std::vector<float>& ref) {
  double mx = 0, mref = 1e-30;
  for (size_t i = 0; i < y.size(); ++i) {
    const double d = std::abs(double(y[i]) - double(ref[i]));
    mx = std::isnan(d) ? INFINITY : std::max(mx, d);
    mref = std::max(mref, std::abs(double(ref[i])));
  }
  return mx / mref;
}

Conv2dShape shape(int64_t n, int64_t ci, int64_t h, int64_t w, int64_t co, int k, int s, int pt,
                  int pl, int pb, int pr) {
  Conv2dShape c;
  c.n = n, c.c_in = ci, c.h = h, c.w = w, c.c_out = co, c.kh = c.kw = k, c.stride = s;
  c.pad_top = pt, c.pad_left = pl, c.pad_bottom = pb, c.pad_right = pr;
  return c;
}

void check_conv(const Conv2dShape& s, bool bias, bool residual, ThreadPool* pool) {
  auto x = random_vec(size_t(s.n * s.c_in * s.h * s.w), 1);
  auto w = random_vec(size_t(s.c_out * s.c_in * s.kh * s.kw), 2);
  auto b = random_vec(size_t(s.c_out), 3);
  const size_t ny = size_t(s.n * s.c_out * s.out_h() * s.out_w());
  auto r = random_vec(ny, 4);
  std::vector<float> ref(ny), y(ny, NAN);
  conv2d_reference(s, x.data(), w.data(), bias ? b.data() : nullptr, residual ? r.data() : nullptr,
                   ref.data());
  ConvWeights cw =
      ConvWeights::pack(w.data(), bias ? b.data() : nullptr, s.c_out, s.c_in, s.kh, s.kw);
  conv2d(s, x.data(), cw, residual ? r.data() : nullptr, y.data(), pool);
  INFO(isa_name(active_isa()) << " N=" << s.n << " Cin=" << s.c_in << " " << s.h << "x" << s.w
                              << " Cout=" << s.c_out << " k=" << s.kh << " s=" << s.stride
                              << " pad=" << s.pad_top << "," << s.pad_left << "," << s.pad_bottom
                              << "," << s.pad_right << " bias=" << bias << " res=" << residual);
  REQUIRE(max_rel_err(y, ref) <= 1e-5);
  if (residual) {
    // In place: y aliases the residual.
    auto yr = r;
    conv2d(s, x.data(), cw, yr.data(), yr.data(), pool);
    REQUIRE(max_rel_err(yr, ref) <= 1e-5);
  }
}

}  // namespace

TEST_CASE("conv2d: 3x3 stride 1 pad 1, every path", "[kernels][conv]") {
  IsaGuard guard;
  test::KcCap cap(384);
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    check_conv(shape(2, 3, 7, 9, 5, 3, 1, 1, 1, 1, 1), true, false, nullptr);
    check_conv(shape(1, 50, 13, 35, 37, 3, 1, 1, 1, 1, 1), true, true, nullptr);  // K=450 > KC
    check_conv(shape(1, 1, 1, 1, 1, 3, 1, 1, 1, 1, 1), false, false, nullptr);
    check_conv(shape(1, 17, 5, 70, 29, 3, 1, 1, 1, 1, 1), false, true, nullptr);  // rows > NR
  }
}

TEST_CASE("conv2d: stride 2, symmetric and right/bottom-only padding, every path",
          "[kernels][conv]") {
  IsaGuard guard;
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    check_conv(shape(1, 16, 13, 11, 19, 3, 2, 1, 1, 1, 1), true, false, nullptr);  // UNet ds
    check_conv(shape(2, 9, 12, 16, 7, 3, 2, 0, 0, 1, 1), true, false, nullptr);    // VAE enc ds
    check_conv(shape(1, 9, 11, 15, 7, 3, 2, 0, 0, 1, 1), true, false, nullptr);    // odd sizes
    // Output rows of 35 and 40 pixels: runs that fill a whole 32-column panel and span 64 input
    // words, cut by the left and right padding.
    check_conv(shape(1, 5, 7, 70, 6, 3, 2, 1, 1, 1, 1), true, false, nullptr);
    check_conv(shape(1, 6, 6, 81, 5, 3, 2, 0, 0, 1, 1), true, true, nullptr);
  }
}

TEST_CASE("conv2d: 1x1 (shortcut, quant_conv), with residual, every path", "[kernels][conv]") {
  IsaGuard guard;
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    check_conv(shape(1, 33, 9, 10, 65, 1, 1, 0, 0, 0, 0), true, true, nullptr);
    check_conv(shape(2, 8, 3, 5, 8, 1, 1, 0, 0, 0, 0), true, false, nullptr);
  }
}

TEST_CASE("conv2d: bf16 weights and activations, every path", "[kernels][conv]") {
  IsaGuard guard;
  test::KcCap cap(384);
  auto round = [](std::vector<float> v) {
    for (float& x : v) x = bf16_to_f32(f32_to_bf16(x));
    return v;
  };
  const Conv2dShape shapes[] = {shape(1, 50, 13, 35, 37, 3, 1, 1, 1, 1, 1),  // K > KC
                                shape(2, 9, 11, 15, 7, 3, 2, 0, 0, 1, 1),
                                shape(1, 33, 9, 10, 65, 1, 1, 0, 0, 0, 0),
                                shape(1, 3, 5, 6, 4, 3, 1, 1, 1, 1, 1),    // odd K = 27
                                shape(1, 6, 6, 81, 5, 3, 2, 0, 0, 1, 1)};  // stride 2, wide rows
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    for (const Conv2dShape& s : shapes) {
      auto x = random_vec(size_t(s.n * s.c_in * s.h * s.w), 1);
      auto w = random_vec(size_t(s.c_out * s.c_in * s.kh * s.kw), 2);
      auto b = random_vec(size_t(s.c_out), 3);
      const size_t ny = size_t(s.n * s.c_out * s.out_h() * s.out_w());
      auto r = random_vec(ny, 4);
      std::vector<float> ref16(ny), ref32(ny), y(ny, NAN);
      auto x16 = round(x), w16 = round(w);
      conv2d_reference(s, x16.data(), w16.data(), b.data(), r.data(), ref16.data());
      conv2d_reference(s, x.data(), w.data(), b.data(), r.data(), ref32.data());
      ConvWeights cw =
          ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, s.kh, s.kw, WeightType::kBf16);
      conv2d(s, x.data(), cw, r.data(), y.data(), nullptr);
      INFO(isa_name(isa) << " Cin=" << s.c_in << " Cout=" << s.c_out << " k=" << s.kh
                         << " s=" << s.stride);
      REQUIRE(max_rel_err(y, ref16) <= 1e-5);
      REQUIRE(test::compare(y, ref32).rel_l2 <= 1e-2);
    }
  }
}

TEST_CASE("conv2d: fused ReLU epilogue (after bias and residual), fp32 and bf16, every path",
          "[kernels][conv]") {
  IsaGuard guard;
  auto relu = [](std::vector<float> v) {
    for (float& x : v) x = x > 0.0f ? x : 0.0f;
    return v;
  };
  auto round = [](std::vector<float> v) {
    for (float& x : v) x = bf16_to_f32(f32_to_bf16(x));
    return v;
  };
  // Panels that straddle output rows (W 35, 70), no padding, right/bottom-only padding, stride 2.
  const Conv2dShape shapes[] = {
      shape(1, 20, 13, 35, 24, 3, 1, 1, 1, 1, 1), shape(2, 7, 6, 70, 13, 3, 1, 0, 0, 0, 0),
      shape(1, 9, 9, 33, 6, 3, 1, 0, 0, 1, 1), shape(1, 16, 13, 11, 19, 3, 2, 1, 1, 1, 1)};
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    for (const Conv2dShape& s : shapes) {
      auto x = random_vec(size_t(s.n * s.c_in * s.h * s.w), 11);
      auto w = random_vec(size_t(s.c_out * s.c_in * s.kh * s.kw), 12);
      auto b = random_vec(size_t(s.c_out), 13);
      const size_t ny = size_t(s.n * s.c_out * s.out_h() * s.out_w());
      auto r = random_vec(ny, 14);
      std::vector<float> ref(ny), ref16(ny), y(ny, NAN);
      conv2d_reference(s, x.data(), w.data(), b.data(), r.data(), ref.data());
      ref = relu(ref);
      INFO(isa_name(isa) << " Cin=" << s.c_in << " " << s.h << "x" << s.w << " Cout=" << s.c_out
                         << " s=" << s.stride << " pad=" << s.pad_top << "," << s.pad_bottom);
      ConvWeights cw = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, s.kh, s.kw);
      conv2d(s, x.data(), cw, r.data(), y.data(), ConvAct::kRelu, nullptr);
      REQUIRE(max_rel_err(y, ref) <= 1e-5);
      size_t zeros = 0;
      for (float v : y) zeros += v == 0.0f;
      REQUIRE(zeros > ny / 4);  // the activation did clamp (about half the outputs)
      auto x16 = round(x), w16 = round(w);
      conv2d_reference(s, x16.data(), w16.data(), b.data(), r.data(), ref16.data());
      ref16 = relu(ref16);
      ConvWeights cw16 =
          ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, s.kh, s.kw, WeightType::kBf16);
      std::fill(y.begin(), y.end(), NAN);
      conv2d(s, x.data(), cw16, r.data(), y.data(), ConvAct::kRelu, nullptr);
      REQUIRE(max_rel_err(y, ref16) <= 1e-5);
      conv2d_release_scratch();  // the next bf16 call regrows the pair planes
      std::fill(y.begin(), y.end(), NAN);
      conv2d(s, x.data(), cw16, r.data(), y.data(), ConvAct::kRelu, nullptr);
      REQUIRE(max_rel_err(y, ref16) <= 1e-5);
    }
  }
}

TEST_CASE("conv2d: threaded result equals single-threaded bit for bit", "[kernels][conv]") {
  ThreadPool pool(2);
  const Conv2dShape s = shape(1, 24, 31, 45, 40, 3, 1, 1, 1, 1, 1);
  auto x = random_vec(size_t(s.c_in * s.h * s.w), 5);
  auto w = random_vec(size_t(s.c_out * s.c_in * 9), 6);
  const size_t ny = size_t(s.c_out * s.out_h() * s.out_w());
  std::vector<float> y1(ny), y2(ny);
  conv2d(s, x.data(), w.data(), nullptr, nullptr, y1.data(), nullptr);
  conv2d(s, x.data(), w.data(), nullptr, nullptr, y2.data(), &pool);
  REQUIRE(y1 == y2);
  check_conv(s, true, true, &pool);
}

TEST_CASE("conv2d: more output channels than pixels (the threads split the channels), bit for bit",
          "[kernels][conv]") {
  // Cout 470 over a 9x7 image: the weights outweigh the im2col panels, so with 2 to 8 threads the
  // output channels are split between the tasks (Cout >= 4 MR per thread on every path), which
  // share the panels gathered once for all of them; the result must not depend on the thread
  // count, and stays within the reference bound on every path.
  const Conv2dShape s = shape(1, 37, 9, 7, 470, 3, 1, 1, 1, 1, 1);
  auto x = random_vec(size_t(s.c_in * s.h * s.w), 7);
  auto w = random_vec(size_t(s.c_out * s.c_in * 9), 8);
  auto b = random_vec(size_t(s.c_out), 9);
  const size_t ny = size_t(s.c_out * s.out_h() * s.out_w());
  for (Isa isa : supported_isas()) {
    IsaGuard guard(isa);
    for (WeightType type : {WeightType::kF32, WeightType::kBf16}) {
      ConvWeights cw = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3, type);
      std::vector<float> y1(ny);
      conv2d(s, x.data(), cw, nullptr, y1.data(), nullptr);
      for (int threads : {2, 3, 4, 8}) {
        INFO(isa_name(isa) << (type == WeightType::kF32 ? " fp32" : " bf16") << " threads "
                           << threads);
        ThreadPool pool(threads);
        std::vector<float> y(ny, NAN);
        conv2d(s, x.data(), cw, nullptr, y.data(), &pool);
        REQUIRE(std::memcmp(y.data(), y1.data(), ny * sizeof(float)) == 0);
      }
    }
  }
  ThreadPool pool(2);
  check_conv(s, true, true, &pool);
}

}  // namespace macro
