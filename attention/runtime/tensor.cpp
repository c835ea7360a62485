#include "attention/runtime/tensor.h"

#include <cstdlib>
#include <cstring>

#include "attention/runtime/large_alloc.h"

namespace macro {

std::string shape_to_string(const int64_t* shape, int rank) {
  std::string s = "[";
  for (int i = 0; i < rank; ++i) {
    if (i) s += ',';
    s += std::to_string(shape[i]);
  }
  s += ']';
  return s;
}

int64_t shape_numel(const Shape& s) {
  int64_t n = 1;
  for (int64_t d : s) {
    MACRO_CHECK(d >= 0);
    MACRO_CHECK(!__builtin_mul_overflow(n, d, &n));
  }
  return n;
}

// ---- TensorView --------------------------------------------------------------------------------

TensorView::TensorView(void* p, DType dt, const Shape& s) : data(p), dtype(dt) {
  MACRO_CHECK(s.size() <= size_t(kMaxRank));
  rank = static_cast<int>(s.size());
  int64_t st = 1;
  for (int i = rank - 1; i >= 0; --i) {
    MACRO_CHECK(s[i] >= 0);
    shape[i] = s[i];
    stride[i] = st;
    st *= s[i];
  }
}

int64_t TensorView::numel() const {
  int64_t n = 1;
  for (int i = 0; i < rank; ++i) n *= shape[i];
  return n;
}

bool TensorView::is_contiguous() const {
  int64_t st = 1;
  for (int i = rank - 1; i >= 0; --i) {
    if (shape[i] != 1 && stride[i] != st) return false;
    st *= shape[i];
  }
  return true;
}

TensorView TensorView::slice(int d, int64_t begin, int64_t end) const {
  if (d < 0) d += rank;
  MACRO_CHECK(d >= 0 && d < rank);
  MACRO_CHECK(0 <= begin && begin <= end && end <= shape[d]);
  TensorView v = *this;
  v.data = static_cast<uint8_t*>(data) + begin * stride[d] * int64_t(elem_size());
  v.shape[d] = end - begin;
  return v;
}

TensorView TensorView::select(int d, int64_t index) const {
  if (d < 0) d += rank;
  MACRO_CHECK(d >= 0 && d < rank);
  MACRO_CHECK(0 <= index && index < shape[d]);
  TensorView v = slice(d, index, index + 1);
  for (int i = d; i + 1 < rank; ++i) {
    v.shape[i] = v.shape[i + 1];
    v.stride[i] = v.stride[i + 1];
  }
  v.rank = rank - 1;
  v.shape[v.rank] = 0;
  v.stride[v.rank] = 0;
  return v;
}

TensorView TensorView::reshape(const Shape& s) const {
  MACRO_CHECK(is_contiguous());
  MACRO_CHECK(shape_numel(s) == numel());
  return TensorView(data, dtype, s);
}

float* TensorView::f32() const {
  MACRO_CHECK(dtype == DType::kF32);
  return static_cast<float*>(data);
}

uint16_t* TensorView::u16() const {
  MACRO_CHECK(dtype == DType::kBF16 || dtype == DType::kF16);
  return static_cast<uint16_t*>(data);
}

int64_t TensorView::offset(std::initializer_list<int64_t> idx) const {
  MACRO_CHECK(int(idx.size()) == rank);
  int64_t off = 0;
  int i = 0;
  for (int64_t v : idx) {
    MACRO_CHECK(v >= 0 && v < shape[i]);
    off += v * stride[i++];
  }
  return off;
}

std::string TensorView::describe() const {
  return std::string(dtype_name(dtype)) + shape_to_string(shape.data(), rank);
}

Status check_shape(const TensorView& t, const Shape& expected, const std::string& what) {
  if (t.dtype != DType::kF32)
    return Status::error(what + ": expected F32, found " + dtype_name(t.dtype));
  if (t.shape_vec() != expected)
    return Status::error(what + ": expected shape " + shape_to_string(expected) + ", found " +
                         shape_to_string(t.shape.data(), t.rank));
  if (!t.is_contiguous()) return Status::error(what + ": expected a contiguous tensor");
  return Status::ok();
}

// ---- Tensor ------------------------------------------------------------------------------------

namespace {
// Large tensors (the skips, the latents of many views) come huge-page backed and pre-faulted
// (large_alloc.h); the zeroing then runs at memory speed instead of one page fault per 4 KB.
void* aligned_zeroed(size_t bytes) {
  size_t rounded = (bytes + kTensorAlign - 1) / kTensorAlign * kTensorAlign;
  if (rounded == 0) rounded = kTensorAlign;
  return large_zeroed(rounded);
}
}  // namespace

void Tensor::Free::operator()(void* p) const {
  std::free(p);
}

Tensor::Tensor(DType dtype, const Shape& shape) {
  size_t bytes = static_cast<size_t>(shape_numel(shape)) * dtype_size(dtype);
  storage_.reset(aligned_zeroed(bytes));
  view_ = TensorView(storage_.get(), dtype, shape);
}

Tensor Tensor::from_f32(const Shape& shape, const std::vector<float>& values) {
  Tensor t(DType::kF32, shape);
  MACRO_CHECK(int64_t(values.size()) == t.numel());
  if (!values.empty()) std::memcpy(t.f32(), values.data(), values.size() * 4);
  return t;
}

Tensor Tensor::clone() const {
  Tensor t(view_.dtype, view_.shape_vec());
  MACRO_CHECK(view_.is_contiguous());
  if (view_.bytes()) std::memcpy(t.view_.data, view_.data, view_.bytes());
  return t;
}

// ---- Arena -------------------------------------------------------------------------------------

void Arena::Free::operator()(uint8_t* p) const {
  std::free(p);
}

void Arena::reserve(size_t capacity_bytes) {
  MACRO_CHECK(used_ == 0);
  if (capacity_bytes <= capacity_) return;
  size_t rounded = footprint(capacity_bytes);
  // Sized to a plan's peak, so every byte will be used: fault it all in now, in huge pages.
  uint8_t* p = static_cast<uint8_t*>(large_alloc(rounded, /*populate=*/true));
  MACRO_CHECK(p != nullptr);
  block_.reset(p);
  capacity_ = rounded;
}

void* Arena::alloc(size_t bytes) {
  size_t need = footprint(bytes);
  MACRO_CHECK(need <= capacity_ - used_);
  void* p = block_.get() + used_;
  used_ += need;
  if (used_ > peak_) peak_ = used_;
  return p;
}

TensorView Arena::alloc_tensor(DType dtype, const Shape& shape) {
  size_t bytes = static_cast<size_t>(shape_numel(shape)) * dtype_size(dtype);
  return TensorView(alloc(bytes), dtype, shape);
}

void Arena::reset(size_t mark) {
  MACRO_CHECK(mark <= used_);
  used_ = mark;
}

// ---- bulk conversions --------------------------------------------------------------------------

void f32_to_bf16(const float* src, uint16_t* dst, int64_t n) {
  for (int64_t i = 0; i < n; ++i) dst[i] = f32_to_bf16(src[i]);
}
void bf16_to_f32(const uint16_t* src, float* dst, int64_t n) {
  for (int64_t i = 0; i < n; ++i) dst[i] = bf16_to_f32(src[i]);
}
void f32_to_f16(const float* src, uint16_t* dst, int64_t n) {
  for (int64_t i = 0; i < n; ++i) dst[i] = f32_to_f16(src[i]);
}
void f16_to_f32(const uint16_t* src, float* dst, int64_t n) {
  for (int64_t i = 0; i < n; ++i) dst[i] = f16_to_f32(src[i]);
}
void round_to_bf16(float* x, int64_t n) {
  for (int64_t i = 0; i < n; ++i) x[i] = bf16_to_f32(f32_to_bf16(x[i]));
}

}  // namespace macro
