// The restricted pickle machine of the PyTorch checkpoint reader (torch_checkpoint.h): it runs
// <prefix>/data.pkl of a torch.save zip into plain data objects held in an arena (so a cyclic memo
// reference cannot leak or recurse forever), resolves only whitelisted globals (to tags; nothing is
// ever called or imported) and turns persistent ids into storages backed by the zip's records.
// Internal to torch_checkpoint.cpp; every read is bounds-checked against the pickle's bytes.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <unordered_map>
#include <vector>

#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/status.h"
#include "attention/runtime/io/zip_reader.h"

namespace macro::torch_pickle {

// Bounds for what a pickle may make us hold (real checkpoints stay far below).
constexpr size_t kMaxStack = 1u << 20;    // values on the pickle stack (and marks)
constexpr size_t kMaxObjects = 1u << 24;  // objects the pickle may build
constexpr uint64_t kMaxMemoIndex = 1u << 24;

inline bool mul_overflow(uint64_t a, uint64_t b, uint64_t* out) {
  return __builtin_mul_overflow(a, b, out);
}

inline std::string num(uint64_t v) { return std::to_string(v); }

enum class Kind : uint8_t {
  kNone, kBool, kInt, kBigInt, kFloat, kStr, kBytes, kTuple, kList, kDict, kGlobal, kStorage,
  kTensor
};

enum class Global : uint8_t {
  kOrderedDict, kRebuildTensorV2, kRebuildTensor, kRebuildParameter, kRebuildParameterWithState,
  kRebuildFromTypeV2, kTensorType, kParameterType, kStorageType, kUntypedStorage, kDtype,
  kUnsupportedStorage  // a storage class we know but whose dtype has no DType (int16, complex)
};

using ObjId = uint32_t;

// A zip record and, once resolved, its content (in place or inflated).
struct Record : ZipEntry {
  const uint8_t* bytes = nullptr;
};

struct Obj {
  Kind kind = Kind::kNone;
  Global global = Global::kOrderedDict;
  DType dtype = DType::kF32;   // kGlobal storage classes and dtypes, kStorage
  int64_t i = 0;               // kInt, kBool; kStorage: numel
  double f = 0;
  std::string s;               // kStr, kBytes; kGlobal: "module.name"; kStorage: record key
  std::vector<ObjId> items;    // kTuple, kList; kDict: key, value, key, value ...
  size_t record = 0;           // kStorage: index into the zip entries
  ObjId storage = 0, offset = 0, shape = 0, stride = 0;  // kTensor: argument objects
};


// The pickle machine and everything it refers to.
class Unpickler {
 public:
  Unpickler(const std::string& file, const std::string& prefix, const std::vector<Record>* entries)
      : file_(file), prefix_(prefix), entries_(entries) {
    for (size_t i = 0; i < entries->size(); ++i) by_name_[(*entries)[i].name] = i;
  }

  Result<ObjId> run(const uint8_t* data, uint64_t size);
  const Obj& obj(ObjId id) const { return objs_[id]; }
  size_t object_count() const { return objs_.size(); }
  size_t record_index(const std::string& name) const {
    auto it = by_name_.find(name);
    return it == by_name_.end() ? SIZE_MAX : it->second;
  }

 private:
  Status fail(const std::string& what) const {
    return Status::error(file_ + ": " + prefix_ + "/data.pkl: offset " + num(pos_) + ": " + what);
  }
  Result<ObjId> make(Obj o) {
    if (objs_.size() >= kMaxObjects) return fail("more than " + num(kMaxObjects) + " objects");
    objs_.push_back(std::move(o));
    return ObjId(objs_.size() - 1);
  }
  Result<ObjId> make_kind(Kind k) {
    Obj o;
    o.kind = k;
    return make(std::move(o));
  }
  Status push(ObjId id) {
    if (stack_.size() >= kMaxStack) return fail("pickle stack deeper than " + num(kMaxStack));
    stack_.push_back(id);
    return Status::ok();
  }
  Result<ObjId> pop() {
    if (stack_.size() <= stack_floor()) return fail("pop from an empty stack");
    ObjId id = stack_.back();
    stack_.pop_back();
    return id;
  }
  size_t stack_floor() const { return marks_.empty() ? 0 : marks_.back(); }
  // Items above the last MARK, removing the mark.
  Result<std::vector<ObjId>> pop_mark() {
    if (marks_.empty()) return fail("no MARK on the stack");
    size_t m = marks_.back();
    marks_.pop_back();
    std::vector<ObjId> items(stack_.begin() + m, stack_.end());
    stack_.resize(m);
    return items;
  }
  Result<uint64_t> read_uint(int bytes) {
    if (size_ - pos_ < uint64_t(bytes)) return fail("truncated operand");
    uint64_t v = 0;
    for (int k = 0; k < bytes; ++k) v |= uint64_t(data_[pos_ + k]) << (8 * k);
    pos_ += bytes;
    return v;
  }
  Result<std::string> read_bytes(uint64_t n) {
    if (size_ - pos_ < n)
      return fail("string of " + num(n) + " bytes but only " + num(size_ - pos_) + " remain");
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return s;
  }
  Result<std::string> read_line() {
    const void* nl = std::memchr(data_ + pos_, '\n', size_ - pos_);
    if (!nl) return fail("unterminated text operand");
    const uint8_t* end = static_cast<const uint8_t*>(nl);
    std::string s(reinterpret_cast<const char*>(data_ + pos_), end - (data_ + pos_));
    pos_ = end - data_ + 1;
    return s;
  }
  Result<ObjId> resolve_global(const std::string& module, const std::string& name);
  Result<ObjId> persistent_load(ObjId pid);
  Result<ObjId> call(ObjId callable, ObjId args);
  Status set_items(ObjId dict, const std::vector<ObjId>& kv);
  Status append_items(ObjId list, const std::vector<ObjId>& items);
  Status memo_put(uint64_t index);

  std::string file_, prefix_;
  const std::vector<Record>* entries_;
  std::unordered_map<std::string, size_t> by_name_;
  std::vector<Obj> objs_;
  std::vector<ObjId> stack_;
  std::vector<size_t> marks_;
  std::unordered_map<uint64_t, ObjId> memo_;
  // Per dict: string key -> index of its value in items (SETITEM replaces without a scan).
  std::unordered_map<ObjId, std::unordered_map<std::string, size_t>> dict_index_;
  const uint8_t* data_ = nullptr;
  uint64_t size_ = 0, pos_ = 0;
};

}  // namespace macro::torch_pickle
