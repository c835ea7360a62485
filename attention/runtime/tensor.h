// Tensors: a non-owning strided view, an owning 64-byte-aligned buffer, and a bump arena.
//
// Legend: N batch, C channels, H x W spatial, T tokens, D features. Shapes are outermost first
// (row-major, like PyTorch); strides are in ELEMENTS, not bytes. Activations are NCHW or [N, T, D].
//
//   TensorView  {data, dtype, rank, shape, stride}: what ops take. Slicing/selecting makes views
//               that share the data. Cheap to copy; never owns memory.
//   Tensor      owns an aligned, contiguous buffer and hands out views. For weights and results.
//   Arena       one aligned block; alloc() bumps a pointer (64-byte aligned), mark()/reset() free
//               everything allocated after a mark. Networks size it once and run without malloc.
//
// bf16/f16 scalar conversions live in half.h (round to nearest even); bulk helpers are below.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "attention/runtime/half.h"
#include "attention/runtime/io/safetensors.h"  // DType, dtype_name, dtype_size
#include "attention/runtime/status.h"

namespace macro {

constexpr int kMaxRank = 6;
constexpr size_t kTensorAlign = 64;  // cache line and ZMM register width

using Shape = std::vector<int64_t>;

std::string shape_to_string(const int64_t* shape, int rank);
inline std::string shape_to_string(const Shape& s) {
  return shape_to_string(s.data(), static_cast<int>(s.size()));
}
// Product of dims; MACRO_CHECKs against negative dims and 64-bit overflow.
int64_t shape_numel(const Shape& s);

struct TensorView {
  void* data = nullptr;
  DType dtype = DType::kF32;
  int rank = 0;
  std::array<int64_t, kMaxRank> shape{};
  std::array<int64_t, kMaxRank> stride{};  // elements

  TensorView() = default;
  // Contiguous view over `data` with the given shape.
  TensorView(void* data, DType dtype, const Shape& shape);
  static TensorView f32(float* p, const Shape& s) { return TensorView(p, DType::kF32, s); }
  static TensorView f32(const float* p, const Shape& s) {
    return TensorView(const_cast<float*>(p), DType::kF32, s);
  }

  int64_t dim(int i) const { return shape[static_cast<size_t>(i < 0 ? i + rank : i)]; }
  int64_t numel() const;
  Shape shape_vec() const { return Shape(shape.begin(), shape.begin() + rank); }
  bool is_contiguous() const;
  size_t elem_size() const { return dtype_size(dtype); }
  size_t bytes() const { return static_cast<size_t>(numel()) * elem_size(); }

  // Views sharing the data.
  TensorView slice(int d, int64_t begin, int64_t end) const;  // [begin, end) along dim d
  TensorView select(int d, int64_t index) const;              // drops dim d
  TensorView reshape(const Shape& s) const;                   // contiguous views only

  // Typed pointers; MACRO_CHECK the dtype.
  float* f32() const;
  uint16_t* u16() const;  // BF16 or F16 storage
  template <typename T>
  T* as() const {
    return static_cast<T*>(data);
  }
  // Element offset of an index tuple (rank entries).
  int64_t offset(std::initializer_list<int64_t> idx) const;
  std::string describe() const;  // "F32[1,64,32,32]"
};

// Contiguous fp32 data of a view with this exact shape? Returns an error naming `what` otherwise.
Status check_shape(const TensorView& t, const Shape& expected, const std::string& what);

// Owning, 64-byte-aligned, contiguous.
class Tensor {
 public:
  Tensor() = default;
  Tensor(DType dtype, const Shape& shape);  // zero-filled
  static Tensor f32(const Shape& shape) { return Tensor(DType::kF32, shape); }
  static Tensor from_f32(const Shape& shape, const std::vector<float>& values);

  Tensor(Tensor&&) noexcept = default;
  Tensor& operator=(Tensor&&) noexcept = default;
  Tensor clone() const;

  const TensorView& view() const { return view_; }
  operator const TensorView&() const { return view_; }  // NOLINT: views are the currency
  float* f32() const { return view_.f32(); }
  int64_t numel() const { return view_.numel(); }
  const Shape shape() const { return view_.shape_vec(); }
  int64_t dim(int i) const { return view_.dim(i); }
  DType dtype() const { return view_.dtype; }
  bool empty() const { return !storage_; }

 private:
  struct Free {
    void operator()(void* p) const;
  };
  std::unique_ptr<void, Free> storage_;
  TensorView view_;
};

// Bump allocator over one aligned block. Not thread-safe: one arena per network run.
class Arena {
 public:
  Arena() = default;
  explicit Arena(size_t capacity_bytes) { reserve(capacity_bytes); }
  Arena(Arena&&) noexcept = default;
  Arena& operator=(Arena&&) noexcept = default;

  // (Re)allocate the block with at least this capacity; only allowed while nothing is allocated.
  void reserve(size_t capacity_bytes);
  // 64-byte-aligned bytes; running out is an invariant violation (the owner sized the arena).
  void* alloc(size_t bytes);
  float* alloc_f32(int64_t n) { return static_cast<float*>(alloc(static_cast<size_t>(n) * 4)); }
  TensorView alloc_tensor(DType dtype, const Shape& shape);
  TensorView alloc_f32(const Shape& shape) { return alloc_tensor(DType::kF32, shape); }

  size_t mark() const { return used_; }
  void reset(size_t mark = 0);
  size_t used() const { return used_; }
  size_t peak() const { return peak_; }
  size_t capacity() const { return capacity_; }
  // Bytes alloc() takes for a request (rounded up to the alignment): for sizing arenas.
  static size_t footprint(size_t bytes) {
    return (bytes + kTensorAlign - 1) / kTensorAlign * kTensorAlign;
  }

 private:
  struct Free {
    void operator()(uint8_t* p) const;
  };
  std::unique_ptr<uint8_t, Free> block_;
  size_t capacity_ = 0, used_ = 0, peak_ = 0;
};

// Bulk conversions (scalar; round to nearest even when narrowing).
void f32_to_bf16(const float* src, uint16_t* dst, int64_t n);
void bf16_to_f32(const uint16_t* src, float* dst, int64_t n);
void f32_to_f16(const float* src, uint16_t* dst, int64_t n);
void f16_to_f32(const uint16_t* src, float* dst, int64_t n);
// Round fp32 values through bf16 in place (what a bf16 weight sees).
void round_to_bf16(float* x, int64_t n);

}  // namespace macro
