// Helpers for tests that compare network outputs with golden safetensors files.
#pragma once

#include <catch2/catch.hpp>
#include <cstdio>
#include <string>

#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/tensor.h"
#include "test_support.h"

namespace macro::test {

// A golden tensor as an owning fp32 Tensor of its stored shape (the test fails if it is absent).
inline Tensor read_tensor(const SafeTensors& f, const std::string& name) {
  const TensorEntry* e = f.find(name);
  INFO("golden tensor " << name << " in " << f.path());
  REQUIRE(e != nullptr);
  auto v = f.read_f32(name);
  REQUIRE(v.is_ok());
  return Tensor::from_f32(e->shape, *v);
}

// Tolerances: relative L2 ||a-b|| / ||b|| and max abs.
struct Bound {
  double rel_l2, max_abs;
};
// The goldens' fp32 tolerance (../shared/golden/README.md).
constexpr Bound kFp32{1e-4, 1e-3};

// got against the golden want within b, both measures printed on one line after `what`.
inline Diff check_close(const std::string& what, const TensorView& got, const Tensor& want,
                        Bound b) {
  REQUIRE(got.shape_vec() == want.shape());
  const Diff d = compare(got.f32(), want.f32(), size_t(want.numel()));
  std::printf("  %-40s rel L2 %.3e  max abs %.3e\n", what.c_str(), d.rel_l2, d.max_abs);
  INFO(what << ": rel L2 " << d.rel_l2 << ", max abs " << d.max_abs);
  CHECK(d.rel_l2 <= b.rel_l2);
  CHECK(d.max_abs <= b.max_abs);
  return d;
}

}  // namespace macro::test
