// Tensor views, owning tensors, the arena, bulk conversions.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>

#include "attention/runtime/tensor.h"

using namespace macro;

TEST_CASE("tensor views: strides, slices, selects, contiguity", "[runtime][tensor]") {
  Tensor t = Tensor::f32({2, 3, 4});
  for (int64_t i = 0; i < t.numel(); ++i) t.f32()[i] = float(i);
  const TensorView& v = t.view();
  REQUIRE(v.rank == 3);
  REQUIRE(v.stride[0] == 12);
  REQUIRE(v.stride[1] == 4);
  REQUIRE(v.stride[2] == 1);
  REQUIRE(v.is_contiguous());
  REQUIRE(v.describe() == "F32[2,3,4]");
  REQUIRE(reinterpret_cast<uintptr_t>(v.data) % kTensorAlign == 0);

  TensorView s = v.slice(1, 1, 3);  // [2,2,4]
  REQUIRE(s.shape_vec() == Shape{2, 2, 4});
  REQUIRE_FALSE(s.is_contiguous());
  REQUIRE(s.f32()[s.offset({1, 1, 3})] == float(1 * 12 + 2 * 4 + 3));
  TensorView first = v.slice(0, 1, 2);  // outermost slices stay contiguous
  REQUIRE(first.is_contiguous());
  REQUIRE(first.f32()[0] == 12.0f);

  TensorView row = v.select(1, 2);  // [2,4]
  REQUIRE(row.rank == 2);
  REQUIRE(row.shape_vec() == Shape{2, 4});
  REQUIRE(row.stride[0] == 12);
  REQUIRE(row.f32()[row.offset({1, 0})] == 20.0f);
  TensorView col = v.select(2, 1);  // [2,3] with stride 4
  REQUIRE(col.f32()[col.offset({1, 2})] == float(12 + 8 + 1));

  TensorView r = v.reshape({6, 4});
  REQUIRE(r.dim(-1) == 4);
  REQUIRE(r.f32()[r.offset({5, 3})] == 23.0f);

  REQUIRE(check_shape(v, {2, 3, 4}, "x").is_ok());
  Status bad = check_shape(v, {2, 3, 5}, "input.image");
  REQUIRE_FALSE(bad.is_ok());
  REQUIRE(bad.message() == "input.image: expected shape [2,3,5], found [2,3,4]");

  Tensor c = t.clone();
  c.f32()[0] = 99;
  REQUIRE(t.f32()[0] == 0.0f);
  Tensor z(DType::kBF16, {0, 5});
  REQUIRE(z.numel() == 0);
}

TEST_CASE("arena: aligned bump allocation with mark and reset", "[runtime][tensor]") {
  Arena a(1000);
  REQUIRE(a.capacity() >= 1000);
  void* p1 = a.alloc(1);
  void* p2 = a.alloc(65);
  REQUIRE(reinterpret_cast<uintptr_t>(p1) % 64 == 0);
  REQUIRE(reinterpret_cast<uintptr_t>(p2) % 64 == 0);
  REQUIRE(static_cast<uint8_t*>(p2) - static_cast<uint8_t*>(p1) == 64);
  REQUIRE(a.used() == 64 + 128);
  size_t m = a.mark();
  TensorView t = a.alloc_f32({4, 4});
  REQUIRE(t.shape_vec() == Shape{4, 4});
  REQUIRE(a.used() == m + 64);
  a.reset(m);
  REQUIRE(a.alloc(8) == t.data);  // the same memory is handed out again
  REQUIRE(a.peak() == m + 64);
  a.reset();
  REQUIRE(a.used() == 0);
  REQUIRE(Arena::footprint(0) == 0);
  REQUIRE(Arena::footprint(129) == 192);
}

TEST_CASE("bulk bf16/f16 conversions", "[runtime][tensor]") {
  std::vector<float> x = {0.0f, 1.0f, -2.5f, 1.0f + 0x1p-8f, 1.0f + 0x1p-11f, 65504.0f, 1e-7f};
  std::vector<uint16_t> b(x.size()), h(x.size());
  std::vector<float> xb(x.size()), xh(x.size());
  f32_to_bf16(x.data(), b.data(), int64_t(x.size()));
  bf16_to_f32(b.data(), xb.data(), int64_t(x.size()));
  f32_to_f16(x.data(), h.data(), int64_t(x.size()));
  f16_to_f32(h.data(), xh.data(), int64_t(x.size()));
  REQUIRE(b[1] == 0x3f80);
  REQUIRE(b[2] == 0xc020);
  REQUIRE(xb[3] == 1.0f);  // tie to even
  REQUIRE(h[1] == 0x3c00);
  REQUIRE(xh[4] == 1.0f);  // tie to even
  REQUIRE(xh[5] == 65504.0f);
  REQUIRE(std::abs(xh[6] - 1e-7f) <= 0x1p-25f);  // subnormal quantum 2^-24
  std::vector<float> y = x;
  round_to_bf16(y.data(), int64_t(y.size()));
  REQUIRE(y == xb);
}
