// Helpers for tests that compare network outputs with golden safetensors files.
#pragma once

#include <catch2/catch.hpp>
#include <string>

#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/tensor.h"

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

}  // namespace macro::test
