// safetensors files: u64 little-endian header length | JSON header | raw little-endian data.
//
// Reading memory-maps the file and validates everything before any tensor is touched: header
// length inside the file and below a cap, JSON well formed, every entry has a known dtype, a shape
// of non-negative dims whose byte size equals its [begin, end) range, ranges inside the data
// section and not overlapping, no duplicate names. A lying header is an error naming the file and
// the tensor, never a huge allocation or an out-of-bounds read.
// Sharded checkpoints: open_checkpoint() accepts "*.safetensors.index.json" (weight_map) too.
// PyTorch checkpoints (torch.save zip: .pth, .pt, .bin) open as a SafeTensors through open_torch(),
// and through open_checkpoint() when the file starts with the zip magic (torch_checkpoint.h).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro {

enum class DType { kF32, kF16, kBF16, kI32, kI64, kU8, kI8, kBool, kF64 };

const char* dtype_name(DType dtype);  // safetensors spelling: "F32", "BF16", ...
size_t dtype_size(DType dtype);
std::string shape_text(const std::vector<int64_t>& shape);  // "[2,3]", for messages
Result<DType> parse_dtype(const std::string& name);

// A tensor inside a mapped file (valid while the file object lives).
struct TensorEntry {
  std::string name;
  DType dtype = DType::kF32;
  std::vector<int64_t> shape;
  const uint8_t* data = nullptr;
  size_t bytes = 0;
  int64_t numel() const {
    int64_t n = 1;
    for (int64_t d : shape) n *= d;
    return n;
  }
};

class SafeTensors {
 public:
  static Result<SafeTensors> open(const std::string& path);
  // A single file, or an index JSON whose shards are opened together, or a PyTorch zip checkpoint
  // (a file starting with "PK\3\4" whose name does not end in .safetensors; as open_torch(path)).
  static Result<SafeTensors> open_checkpoint(const std::string& path);
  // A torch.save zip checkpoint. key picks the state dict inside it ("params_ema", "params");
  // "" selects automatically (attention/runtime/io/torch_checkpoint.h). Names are the flattened
  // state-dict names; metadata() holds "format" = "pt", "torch.archive" and "torch.key".
  static Result<SafeTensors> open_torch(const std::string& path, const std::string& key = "");

  SafeTensors();
  ~SafeTensors();
  SafeTensors(SafeTensors&&) noexcept;
  SafeTensors& operator=(SafeTensors&&) noexcept;

  const std::string& path() const { return path_; }
  std::vector<std::string> names() const;  // sorted
  bool contains(const std::string& name) const;
  const TensorEntry* find(const std::string& name) const;
  const std::map<std::string, std::string>& metadata() const { return metadata_; }

  // Copy a tensor out as float32, converting F32/F16/BF16/F64/I32/I64/U8/I8/BOOL. If
  // expected_shape is non-empty the shape must match exactly; errors name file and tensor.
  Result<std::vector<float>> read_f32(const std::string& name,
                                      const std::vector<int64_t>& expected_shape = {}) const;

 private:
  struct Mapping;
  std::string path_;
  std::vector<std::shared_ptr<Mapping>> mappings_;
  std::map<std::string, TensorEntry> tensors_;
  std::map<std::string, std::string> metadata_;
  std::shared_ptr<const void> owner_;  // torch checkpoints: the mapping and the owned copies
};

// Convert a mapped tensor's elements to float32 into dst (n must equal its element count).
// Used by loaders that fill preallocated buffers; read_f32 is the allocating form.
Status convert_to_f32(const TensorEntry& entry, float* dst, size_t n);

// One tensor to write; data is dtype-sized little-endian elements, row-major.
struct TensorToWrite {
  std::string name;
  DType dtype = DType::kF32;
  std::vector<int64_t> shape;
  const void* data = nullptr;
};

// Written atomically (temporary + rename). Tensors are laid out in the given order; the JSON header
// is padded with spaces to a multiple of 8 bytes so the data section starts 8-byte aligned.
Status write_safetensors(const std::string& path, const std::vector<TensorToWrite>& tensors,
                         const std::map<std::string, std::string>& metadata = {});

}  // namespace macro
