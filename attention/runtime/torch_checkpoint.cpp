// PyTorch zip checkpoint reader (format and rules: torch_checkpoint.h).
//
// Three stages, each bounds-checked against the bytes it was given:
//   1. the zip directory (zip_reader.h): every record's data range inside the file; stored records
//      are used in place, deflated ones inflated on first use;
//   2. the pickle machine over <prefix>/data.pkl: plain data objects in an arena (so a cyclic memo
//      reference cannot leak or recurse forever), whitelisted globals resolved to tags, storages
//      resolved to records at BINPERSID;
//   3. selection of the state dict and flattening to named tensors, each validated (shape, stride,
//      offset inside its storage) and either pointing into the record or gathered into a copy.
#include "attention/runtime/torch_checkpoint.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <set>
#include <unordered_map>

#include "attention/runtime/limits.h"
#include "attention/runtime/zip_reader.h"

namespace macro {

namespace {

// Bounds for what a file may make us hold. Real checkpoints stay far below: data.pkl costs a few
// hundred bytes per tensor (a thousand-tensor model: well under 1 MB), a state dict nests 2-3 deep.
constexpr uint64_t kMaxPickleBytes = 256ull << 20;
constexpr size_t kMaxStack = 1u << 20;     // values on the pickle stack (and marks)
constexpr size_t kMaxObjects = 1u << 24;   // objects the pickle may build
constexpr uint64_t kMaxMemoIndex = 1u << 24;
constexpr int kMaxNesting = 64;            // dict/list depth when flattening
constexpr int kMaxDims = 64;
// Owned copies (strided tensors, inflated records) may total at most this much beyond four times
// the file size; a strided view with stride 0 could otherwise ask for far more than the file holds.
constexpr uint64_t kCopyAllowanceBytes = 256ull << 20;

bool add_overflow(uint64_t a, uint64_t b, uint64_t* out) {
  return __builtin_add_overflow(a, b, out);
}
bool mul_overflow(uint64_t a, uint64_t b, uint64_t* out) {
  return __builtin_mul_overflow(a, b, out);
}

std::string num(uint64_t v) { return std::to_string(v); }

std::string shape_text(const std::vector<int64_t>& s) {
  std::string t = "[";
  for (size_t i = 0; i < s.size(); ++i) {
    if (i) t += ',';
    t += std::to_string(s[i]);
  }
  t += ']';
  return t;
}

// Printable form of a name from the file (globals, keys) for messages.
std::string printable(const std::string& s, size_t max = 80) {
  std::string out;
  for (size_t i = 0; i < s.size() && i < max; ++i) {
    unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 32 && c < 127) {
      out.push_back(char(c));
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    }
  }
  if (s.size() > max) out += "...";
  return out;
}

// ---------------------------------------------------------------------------------------------
// Memory held by a checkpoint: the mapping (when read from a file) and owned copies.

// Copies live in shared mappings of anonymous memory files (memfd), not on the heap: weight
// loaders drop the pages of tensors they have packed with madvise(MADV_DONTNEED)
// (nets::release_param), which for a file mapping only evicts them (a later read faults the same
// bytes back) but would zero heap pages, including those of other tensors in the same buffer.
struct Owner {
  std::vector<std::pair<void*, size_t>> maps;  // the checkpoint file, then the copies
  std::vector<std::unique_ptr<uint8_t[]>> buffers;  // copies if memfd_create is unavailable
  ~Owner() {
    for (auto& [addr, size] : maps) ::munmap(addr, size);
  }
  uint8_t* allocate(size_t bytes) {
    const size_t len = bytes ? bytes : 1;
    const int fd = ::memfd_create("macro-torch-checkpoint", MFD_CLOEXEC);
    if (fd >= 0) {
      void* p = ::ftruncate(fd, off_t(len)) == 0
                    ? ::mmap(nullptr, len, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0)
                    : MAP_FAILED;
      ::close(fd);
      if (p != MAP_FAILED) {
        maps.emplace_back(p, len);
        return static_cast<uint8_t*>(p);
      }
    }
    buffers.emplace_back(new uint8_t[len]);
    return buffers.back().get();
  }
};

// ---------------------------------------------------------------------------------------------
// Pickle objects

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

struct GlobalInfo {
  const char* module;
  const char* name;
  Global tag;
  DType dtype;
};

const GlobalInfo kGlobals[] = {
    {"collections", "OrderedDict", Global::kOrderedDict, DType::kF32},
    {"torch._utils", "_rebuild_tensor_v2", Global::kRebuildTensorV2, DType::kF32},
    {"torch._utils", "_rebuild_tensor", Global::kRebuildTensor, DType::kF32},
    {"torch._utils", "_rebuild_parameter", Global::kRebuildParameter, DType::kF32},
    {"torch._utils", "_rebuild_parameter_with_state", Global::kRebuildParameterWithState,
     DType::kF32},
    {"torch._tensor", "_rebuild_from_type_v2", Global::kRebuildFromTypeV2, DType::kF32},
    {"torch", "Tensor", Global::kTensorType, DType::kF32},
    {"torch._tensor", "Tensor", Global::kTensorType, DType::kF32},
    {"torch.nn.parameter", "Parameter", Global::kParameterType, DType::kF32},
    {"torch", "FloatStorage", Global::kStorageType, DType::kF32},
    {"torch", "HalfStorage", Global::kStorageType, DType::kF16},
    {"torch", "BFloat16Storage", Global::kStorageType, DType::kBF16},
    {"torch", "DoubleStorage", Global::kStorageType, DType::kF64},
    {"torch", "LongStorage", Global::kStorageType, DType::kI64},
    {"torch", "IntStorage", Global::kStorageType, DType::kI32},
    {"torch", "ByteStorage", Global::kStorageType, DType::kU8},
    {"torch", "CharStorage", Global::kStorageType, DType::kI8},
    {"torch", "BoolStorage", Global::kStorageType, DType::kBool},
    {"torch", "UntypedStorage", Global::kUntypedStorage, DType::kU8},
    {"torch", "ShortStorage", Global::kUnsupportedStorage, DType::kU8},
    {"torch", "ComplexFloatStorage", Global::kUnsupportedStorage, DType::kU8},
    {"torch", "ComplexDoubleStorage", Global::kUnsupportedStorage, DType::kU8},
    {"torch", "QInt8Storage", Global::kUnsupportedStorage, DType::kU8},
    {"torch", "QUInt8Storage", Global::kUnsupportedStorage, DType::kU8},
    {"torch", "QInt32Storage", Global::kUnsupportedStorage, DType::kU8},
    {"torch.storage", "UntypedStorage", Global::kUntypedStorage, DType::kU8},
    {"torch", "float32", Global::kDtype, DType::kF32},
    {"torch", "float", Global::kDtype, DType::kF32},
    {"torch", "float16", Global::kDtype, DType::kF16},
    {"torch", "half", Global::kDtype, DType::kF16},
    {"torch", "bfloat16", Global::kDtype, DType::kBF16},
    {"torch", "float64", Global::kDtype, DType::kF64},
    {"torch", "double", Global::kDtype, DType::kF64},
    {"torch", "int64", Global::kDtype, DType::kI64},
    {"torch", "long", Global::kDtype, DType::kI64},
    {"torch", "int32", Global::kDtype, DType::kI32},
    {"torch", "int", Global::kDtype, DType::kI32},
    {"torch", "uint8", Global::kDtype, DType::kU8},
    {"torch", "int8", Global::kDtype, DType::kI8},
    {"torch", "bool", Global::kDtype, DType::kBool},
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

Result<ObjId> Unpickler::resolve_global(const std::string& module, const std::string& name) {
  for (const GlobalInfo& g : kGlobals) {
    if (module == g.module && name == g.name) {
      Obj o;
      o.kind = Kind::kGlobal;
      o.global = g.tag;
      o.dtype = g.dtype;
      o.s = module + "." + name;
      return make(std::move(o));
    }
  }
  return fail("global '" + printable(module) + "." + printable(name) +
              "' is not allowed (a checkpoint may only reference collections.OrderedDict, "
              "torch tensor rebuild functions, storage classes and dtypes; nothing is executed)");
}

// ('storage', storage_type, key, location, numel) -> the record <prefix>/data/<key>.
Result<ObjId> Unpickler::persistent_load(ObjId pid) {
  const Obj& t = objs_[pid];
  if (t.kind != Kind::kTuple || t.items.size() != 5 || objs_[t.items[0]].kind != Kind::kStr ||
      objs_[t.items[0]].s != "storage")
    return fail("persistent id: expected ('storage', type, key, location, numel)");
  const Obj& type = objs_[t.items[1]];
  const Obj& key = objs_[t.items[2]];
  const Obj& count = objs_[t.items[4]];
  if (type.kind == Kind::kGlobal && type.global == Global::kUnsupportedStorage)
    return fail("storage class '" + type.s +
                "' is not supported (supported element types: F32, F16, BF16, F64, I64, I32, U8, "
                "I8, BOOL)");
  if (type.kind != Kind::kGlobal ||
      (type.global != Global::kStorageType && type.global != Global::kUntypedStorage &&
       type.global != Global::kDtype))
    return fail("persistent id: expected a storage class, found " +
                (type.kind == Kind::kGlobal ? "'" + type.s + "'" : std::string("a non-class")));
  if (key.kind != Kind::kStr && key.kind != Kind::kInt)
    return fail("persistent id: storage key is not a string");
  if (count.kind != Kind::kInt || count.i < 0)
    return fail("persistent id: storage size is not a non-negative integer");
  const std::string k = key.kind == Kind::kStr ? key.s : std::to_string(key.i);
  const std::string record = prefix_ + "/data/" + k;
  const size_t idx = record_index(record);
  if (idx == SIZE_MAX)
    return fail("storage '" + printable(k) + "' refers to record '" + printable(record) +
                "', which the archive does not contain");
  const DType dtype = type.dtype;
  uint64_t nbytes = 0;
  if (mul_overflow(uint64_t(count.i), dtype_size(dtype), &nbytes) ||
      nbytes != (*entries_)[idx].size)
    return fail("storage '" + printable(k) + "': " + num(uint64_t(count.i)) + " elements of " +
                dtype_name(dtype) + " need " + num(nbytes) + " bytes, record '" +
                printable(record) + "' holds " + num((*entries_)[idx].size));
  Obj o;
  o.kind = Kind::kStorage;
  o.dtype = dtype;
  o.i = count.i;
  o.s = k;
  o.record = idx;
  return make(std::move(o));
}

Result<ObjId> Unpickler::call(ObjId callable, ObjId args_id) {
  // Copies: making objects below moves the arena.
  if (objs_[callable].kind != Kind::kGlobal) return fail("REDUCE on an object that is not a global");
  const std::string fname = objs_[callable].s;
  const Global global = objs_[callable].global;
  if (objs_[args_id].kind != Kind::kTuple)
    return fail("REDUCE of '" + fname + "' with non-tuple arguments");
  const std::vector<ObjId> a = objs_[args_id].items;
  auto tensor_arg = [&](ObjId id) -> Result<ObjId> {
    if (objs_[id].kind != Kind::kTensor) return fail("'" + fname + "' expects a tensor argument");
    return id;
  };
  switch (global) {
    case Global::kOrderedDict:
      if (!a.empty()) return fail("collections.OrderedDict called with arguments");
      return make_kind(Kind::kDict);
    case Global::kRebuildTensorV2:
    case Global::kRebuildTensor: {
      const bool v2 = global == Global::kRebuildTensorV2;
      if (v2 ? (a.size() < 4 || a.size() > 7) : a.size() != 4)
        return fail("'" + fname + "' called with " + num(a.size()) + " arguments");
      if (objs_[a[0]].kind != Kind::kStorage)
        return fail("'" + fname + "': first argument is not a storage");
      Obj o;
      o.kind = Kind::kTensor;
      o.storage = a[0];
      o.offset = a[1];
      o.shape = a[2];
      o.stride = a[3];
      return make(std::move(o));
    }
    case Global::kRebuildParameter:
    case Global::kRebuildParameterWithState:
      if (a.empty()) return fail("'" + fname + "' called without arguments");
      return tensor_arg(a[0]);
    case Global::kRebuildFromTypeV2: {
      // (func, new_type, args, state): func(*args), viewed as new_type.
      if (a.size() != 4) return fail("'" + fname + "' called with " + num(a.size()) + " arguments");
      const Obj& type = objs_[a[1]];
      if (type.kind != Kind::kGlobal ||
          (type.global != Global::kTensorType && type.global != Global::kParameterType))
        return fail("'" + fname + "': tensor type is not torch.Tensor or Parameter");
      const Obj& inner = objs_[a[0]];
      if (inner.kind != Kind::kGlobal || inner.global == Global::kRebuildFromTypeV2)
        return fail("'" + fname + "': rebuild function is not allowed");
      MACRO_ASSIGN_OR_RETURN(ObjId r, call(a[0], a[2]));
      return tensor_arg(r);
    }
    default:
      return fail("'" + fname + "' cannot be called");
  }
}

Status Unpickler::set_items(ObjId dict, const std::vector<ObjId>& kv) {
  if (objs_[dict].kind != Kind::kDict) return fail("SETITEM(S) on an object that is not a dict");
  if (kv.size() % 2) return fail("SETITEMS with an odd number of items");
  for (size_t k = 0; k < kv.size(); k += 2) {
    // A repeated string key replaces the earlier value in place (as in Python).
    auto& items = objs_[dict].items;
    const Obj& key = objs_[kv[k]];
    if (key.kind == Kind::kStr) {
      auto ins = dict_index_[dict].emplace(key.s, items.size() + 1);
      if (!ins.second) {
        items[ins.first->second] = kv[k + 1];
        continue;
      }
    }
    if (items.size() >= kMaxObjects) return fail("dict too large");
    items.push_back(kv[k]);
    items.push_back(kv[k + 1]);
  }
  return Status::ok();
}

Status Unpickler::append_items(ObjId list, const std::vector<ObjId>& items) {
  if (objs_[list].kind != Kind::kList) return fail("APPEND(S) on an object that is not a list");
  if (objs_[list].items.size() + items.size() > kMaxObjects) return fail("list too large");
  objs_[list].items.insert(objs_[list].items.end(), items.begin(), items.end());
  return Status::ok();
}

Status Unpickler::memo_put(uint64_t index) {
  if (index >= kMaxMemoIndex) return fail("memo index " + num(index) + " too large");
  if (stack_.size() <= stack_floor()) return fail("memo store from an empty stack");
  memo_[index] = stack_.back();
  return Status::ok();
}

Result<ObjId> Unpickler::run(const uint8_t* data, uint64_t size) {
  data_ = data;
  size_ = size;
  pos_ = 0;
  while (pos_ < size_) {
    const uint64_t op_pos = pos_;
    const uint8_t op = data_[pos_++];
    switch (op) {
      case 0x80: {  // PROTO
        MACRO_ASSIGN_OR_RETURN(uint64_t v, read_uint(1));
        if (v < 2 || v > 5) return fail("pickle protocol " + num(v) + " (expected 2 to 5)");
        break;
      }
      case 0x95: {  // FRAME: a length hint only
        MACRO_ASSIGN_OR_RETURN(uint64_t v, read_uint(8));
        (void)v;
        break;
      }
      case '.': {  // STOP
        if (stack_.size() != 1 || !marks_.empty())
          return fail("STOP with " + num(stack_.size()) + " values on the stack (expected 1)");
        return stack_.back();
      }
      case '(':  // MARK
        if (marks_.size() >= kMaxStack) return fail("too many MARKs");
        marks_.push_back(stack_.size());
        break;
      case '0': {  // POP
        MACRO_ASSIGN_OR_RETURN(ObjId v, pop());
        (void)v;
        break;
      }
      case '1': {  // POP_MARK
        MACRO_ASSIGN_OR_RETURN(auto v, pop_mark());
        (void)v;
        break;
      }
      case '2': {  // DUP
        if (stack_.size() <= stack_floor()) return fail("DUP on an empty stack");
        MACRO_TRY(push(stack_.back()));
        break;
      }
      case 'N': {
        MACRO_ASSIGN_OR_RETURN(ObjId v, make_kind(Kind::kNone));
        MACRO_TRY(push(v));
        break;
      }
      case 0x88:
      case 0x89: {  // NEWTRUE, NEWFALSE
        Obj o;
        o.kind = Kind::kBool;
        o.i = op == 0x88;
        MACRO_ASSIGN_OR_RETURN(ObjId v, make(std::move(o)));
        MACRO_TRY(push(v));
        break;
      }
      case 'J':
      case 'K':
      case 'M': {  // BININT (signed 32), BININT1, BININT2 (unsigned)
        const int n = op == 'J' ? 4 : op == 'K' ? 1 : 2;
        MACRO_ASSIGN_OR_RETURN(uint64_t u, read_uint(n));
        Obj o;
        o.kind = Kind::kInt;
        o.i = op == 'J' ? int64_t(int32_t(uint32_t(u))) : int64_t(u);
        MACRO_ASSIGN_OR_RETURN(ObjId v, make(std::move(o)));
        MACRO_TRY(push(v));
        break;
      }
      case 0x8a:
      case 0x8b: {  // LONG1, LONG4: little-endian two's complement of n bytes
        MACRO_ASSIGN_OR_RETURN(uint64_t n, read_uint(op == 0x8a ? 1 : 4));
        if (size_ - pos_ < n) return fail("truncated LONG");
        Obj o;
        o.kind = Kind::kInt;
        if (n > 8) {
          o.kind = Kind::kBigInt;
        } else if (n > 0) {
          uint64_t u = 0;
          for (uint64_t k = 0; k < n; ++k) u |= uint64_t(data_[pos_ + k]) << (8 * k);
          if (n < 8 && (data_[pos_ + n - 1] & 0x80)) u |= ~uint64_t(0) << (8 * n);
          o.i = int64_t(u);
        }
        pos_ += n;
        MACRO_ASSIGN_OR_RETURN(ObjId v, make(std::move(o)));
        MACRO_TRY(push(v));
        break;
      }
      case 'G': {  // BINFLOAT: big-endian double
        if (size_ - pos_ < 8) return fail("truncated BINFLOAT");
        uint64_t u = 0;
        for (int k = 0; k < 8; ++k) u = u << 8 | data_[pos_ + k];
        pos_ += 8;
        Obj o;
        o.kind = Kind::kFloat;
        std::memcpy(&o.f, &u, 8);
        MACRO_ASSIGN_OR_RETURN(ObjId v, make(std::move(o)));
        MACRO_TRY(push(v));
        break;
      }
      case 'X':
      case 0x8c:
      case 0x8d:
      case 'T':
      case 'U':
      case 'B':
      case 'C':
      case 0x8e:
      case 0x96: {  // strings (unicode, py2 str) and bytes
        const int n = (op == 0x8c || op == 'U' || op == 'C') ? 1
                      : (op == 0x8d || op == 0x8e || op == 0x96) ? 8
                                                                  : 4;
        MACRO_ASSIGN_OR_RETURN(uint64_t len, read_uint(n));
        if (op == 'T' && (len & 0x80000000u)) return fail("negative BINSTRING length");
        MACRO_ASSIGN_OR_RETURN(std::string s, read_bytes(len));
        Obj o;
        o.kind = (op == 'B' || op == 'C' || op == 0x8e || op == 0x96) ? Kind::kBytes : Kind::kStr;
        o.s = std::move(s);
        MACRO_ASSIGN_OR_RETURN(ObjId v, make(std::move(o)));
        MACRO_TRY(push(v));
        break;
      }
      case '}':
      case ']':
      case ')':
      case 0x8f: {  // EMPTY_DICT, EMPTY_LIST, EMPTY_TUPLE, EMPTY_SET (kept as a list)
        MACRO_ASSIGN_OR_RETURN(
            ObjId v, make_kind(op == '}' ? Kind::kDict : op == ')' ? Kind::kTuple : Kind::kList));
        MACRO_TRY(push(v));
        break;
      }
      case 'd':
      case 'l':
      case 't':
      case 0x91: {  // DICT, LIST, TUPLE, FROZENSET from the items above MARK
        MACRO_ASSIGN_OR_RETURN(std::vector<ObjId> items, pop_mark());
        MACRO_ASSIGN_OR_RETURN(
            ObjId v, make_kind(op == 'd' ? Kind::kDict : op == 't' ? Kind::kTuple : Kind::kList));
        if (op == 'd') {
          MACRO_TRY(set_items(v, items));
        } else {
          objs_[v].items = std::move(items);
        }
        MACRO_TRY(push(v));
        break;
      }
      case 0x85:
      case 0x86:
      case 0x87: {  // TUPLE1..3
        const size_t n = op - 0x84;
        if (stack_.size() - stack_floor() < n) return fail("TUPLE" + num(n) + " on a short stack");
        std::vector<ObjId> items(stack_.end() - n, stack_.end());
        stack_.resize(stack_.size() - n);
        MACRO_ASSIGN_OR_RETURN(ObjId v, make_kind(Kind::kTuple));
        objs_[v].items = std::move(items);
        MACRO_TRY(push(v));
        break;
      }
      case 's': {  // SETITEM
        MACRO_ASSIGN_OR_RETURN(ObjId value, pop());
        MACRO_ASSIGN_OR_RETURN(ObjId key, pop());
        if (stack_.size() <= stack_floor()) return fail("SETITEM without a dict");
        MACRO_TRY(set_items(stack_.back(), {key, value}));
        break;
      }
      case 'u': {  // SETITEMS
        MACRO_ASSIGN_OR_RETURN(std::vector<ObjId> kv, pop_mark());
        if (stack_.size() <= stack_floor()) return fail("SETITEMS without a dict");
        MACRO_TRY(set_items(stack_.back(), kv));
        break;
      }
      case 'a': {  // APPEND
        MACRO_ASSIGN_OR_RETURN(ObjId value, pop());
        if (stack_.size() <= stack_floor()) return fail("APPEND without a list");
        MACRO_TRY(append_items(stack_.back(), {value}));
        break;
      }
      case 'e':
      case 0x90: {  // APPENDS, ADDITEMS (sets kept as lists)
        MACRO_ASSIGN_OR_RETURN(std::vector<ObjId> items, pop_mark());
        if (stack_.size() <= stack_floor()) return fail("APPENDS without a list");
        MACRO_TRY(append_items(stack_.back(), items));
        break;
      }
      case 'q':
      case 'r': {  // BINPUT, LONG_BINPUT
        MACRO_ASSIGN_OR_RETURN(uint64_t idx, read_uint(op == 'q' ? 1 : 4));
        MACRO_TRY(memo_put(idx));
        break;
      }
      case 0x94:  // MEMOIZE
        MACRO_TRY(memo_put(memo_.size()));
        break;
      case 'h':
      case 'j': {  // BINGET, LONG_BINGET
        MACRO_ASSIGN_OR_RETURN(uint64_t idx, read_uint(op == 'h' ? 1 : 4));
        auto it = memo_.find(idx);
        if (it == memo_.end()) return fail("memo index " + num(idx) + " was never stored");
        MACRO_TRY(push(it->second));
        break;
      }
      case 'c': {  // GLOBAL module\nname\n
        MACRO_ASSIGN_OR_RETURN(std::string module, read_line());
        MACRO_ASSIGN_OR_RETURN(std::string name, read_line());
        MACRO_ASSIGN_OR_RETURN(ObjId v, resolve_global(module, name));
        MACRO_TRY(push(v));
        break;
      }
      case 0x93: {  // STACK_GLOBAL
        MACRO_ASSIGN_OR_RETURN(ObjId name, pop());
        MACRO_ASSIGN_OR_RETURN(ObjId module, pop());
        if (objs_[name].kind != Kind::kStr || objs_[module].kind != Kind::kStr)
          return fail("STACK_GLOBAL with non-string module or name");
        MACRO_ASSIGN_OR_RETURN(ObjId v, resolve_global(objs_[module].s, objs_[name].s));
        MACRO_TRY(push(v));
        break;
      }
      case 'R':
      case 0x81: {  // REDUCE callable(*args); NEWOBJ cls.__new__(cls, *args)
        MACRO_ASSIGN_OR_RETURN(ObjId args, pop());
        MACRO_ASSIGN_OR_RETURN(ObjId fn, pop());
        if (op == 0x81 && !(objs_[fn].kind == Kind::kGlobal &&
                            objs_[fn].global == Global::kOrderedDict))
          return fail("NEWOBJ of something other than collections.OrderedDict");
        MACRO_ASSIGN_OR_RETURN(ObjId v, call(fn, args));
        MACRO_TRY(push(v));
        break;
      }
      case 'b': {  // BUILD: state for the object below; an OrderedDict's _metadata is dropped
        MACRO_ASSIGN_OR_RETURN(ObjId state, pop());
        (void)state;
        if (stack_.size() <= stack_floor()) return fail("BUILD without an object");
        const Kind k = objs_[stack_.back()].kind;
        if (k != Kind::kDict && k != Kind::kTensor) return fail("BUILD on a plain value");
        break;
      }
      case 'Q': {  // BINPERSID
        MACRO_ASSIGN_OR_RETURN(ObjId pid, pop());
        MACRO_ASSIGN_OR_RETURN(ObjId v, persistent_load(pid));
        MACRO_TRY(push(v));
        break;
      }
      default: {
        char buf[8];
        std::snprintf(buf, sizeof buf, "0x%02x", op);
        pos_ = op_pos;
        return fail(std::string("pickle opcode ") + buf +
                    (op >= 32 && op < 127 ? std::string(" '") + char(op) + "'" : std::string()) +
                    " is not supported");
      }
    }
  }
  return fail("no STOP opcode before the end of the pickle");
}

// ---------------------------------------------------------------------------------------------
// Records and tensors

class Reader {
 public:
  Reader(const uint8_t* base, uint64_t size, std::string file, std::shared_ptr<Owner> owner)
      : base_(base), size_(size), file_(std::move(file)), owner_(std::move(owner)) {
    copy_budget_ = kCopyAllowanceBytes + (size > (UINT64_MAX - kCopyAllowanceBytes) / 4
                                              ? UINT64_MAX - kCopyAllowanceBytes
                                              : 4 * size);
  }
  Result<TorchCheckpoint> read(const std::string& key);

 private:
  Result<uint8_t*> allocate(uint64_t bytes, const std::string& what) {
    if (bytes > copy_budget_)
      return Status::error(file_ + ": " + what + ": a copy of " + num(bytes) +
                           " bytes exceeds what the file can justify (" + num(copy_budget_) +
                           " bytes left of four times the file size plus 256 MiB)");
    copy_budget_ -= bytes;
    return owner_->allocate(size_t(bytes));
  }
  Status resolve_record(Record& e);
  Status flatten(const Unpickler& vm, ObjId id, const std::string& name, int depth,
                 TorchCheckpoint* out, std::set<std::string>* seen);
  Result<TensorEntry> make_tensor(const Unpickler& vm, const Obj& t, const std::string& name);

  const uint8_t* base_;
  uint64_t size_;
  std::string file_;
  std::shared_ptr<Owner> owner_;
  uint64_t copy_budget_ = 0;
  // Flattening visits each object of a tree once; shared containers (a list holding the same list
  // twice, 40 levels deep) would expand exponentially, so visits are bounded by the object count.
  uint64_t visits_left_ = 0;
  std::vector<Record> entries_;
};

// Points e.bytes at the record's content: in place for stored records, inflated otherwise.
Status Reader::resolve_record(Record& e) {
  if (e.bytes || e.size == 0) {
    if (!e.bytes) e.bytes = base_ + e.data_offset;
    return Status::ok();
  }
  const std::string rec = file_ + ": record '" + printable(e.name) + "'";
  if (e.method == 0) {
    e.bytes = base_ + e.data_offset;
    return Status::ok();
  }
  MACRO_TRY(check_inflated_size(e, file_));
  if (e.size > resource_limits().max_tensor_bytes)
    return Status::error(rec + ": " + num(e.size) + " bytes exceeds the limit of " +
                         num(resource_limits().max_tensor_bytes) + " (--max-tensor-bytes)");
  MACRO_ASSIGN_OR_RETURN(uint8_t * out, allocate(e.size, "record '" + printable(e.name) + "'"));
  MACRO_TRY(inflate_zip_record(base_, e, out, file_));
  e.bytes = out;
  return Status::ok();
}

Result<TensorEntry> Reader::make_tensor(const Unpickler& vm, const Obj& t,
                                        const std::string& name) {
  const std::string where = file_ + ": tensor '" + printable(name, 200) + "'";
  const Obj& st = vm.obj(t.storage);
  const Obj& off = vm.obj(t.offset);
  const Obj& shape_o = vm.obj(t.shape);
  const Obj& stride_o = vm.obj(t.stride);
  auto int_list = [&](const Obj& o, const char* what,
                      std::vector<int64_t>* out) -> Status {
    if (o.kind != Kind::kTuple && o.kind != Kind::kList)
      return Status::error(where + ": " + what + " is not a tuple of integers");
    if (o.items.size() > size_t(kMaxDims))
      return Status::error(where + ": " + what + " has " + num(o.items.size()) +
                           " dimensions (at most " + num(kMaxDims) + ")");
    for (ObjId id : o.items) {
      const Obj& d = vm.obj(id);
      if (d.kind != Kind::kInt || d.i < 0)
        return Status::error(where + ": " + what + " holds a value that is not a non-negative "
                             "integer");
      out->push_back(d.i);
    }
    return Status::ok();
  };
  TensorEntry e;
  e.name = name;
  e.dtype = st.dtype;
  std::vector<int64_t> stride;
  MACRO_TRY(int_list(shape_o, "size", &e.shape));
  MACRO_TRY(int_list(stride_o, "stride", &stride));
  if (stride.size() != e.shape.size())
    return Status::error(where + ": size " + shape_text(e.shape) + " and stride " +
                         shape_text(stride) + " differ in length");
  if (off.kind != Kind::kInt || off.i < 0)
    return Status::error(where + ": storage offset is not a non-negative integer");
  const size_t es = dtype_size(e.dtype);
  uint64_t numel = 1, last = uint64_t(off.i);  // last: index of the last element in the storage
  bool overflow = false;
  for (size_t d = 0; d < e.shape.size(); ++d) {
    uint64_t span = 0;
    overflow |= mul_overflow(numel, uint64_t(e.shape[d]), &numel);
    if (e.shape[d] > 0) {
      overflow |= mul_overflow(uint64_t(e.shape[d] - 1), uint64_t(stride[d]), &span);
      overflow |= add_overflow(last, span, &last);
    }
  }
  uint64_t nbytes = 0;
  overflow |= mul_overflow(numel, es, &nbytes);
  if (overflow)
    return Status::error(where + ": size " + shape_text(e.shape) + " with stride " +
                         shape_text(stride) + " overflows 64 bits");
  if (nbytes > resource_limits().max_tensor_bytes)
    return Status::error(where + ": size " + shape_text(e.shape) + " of " + dtype_name(e.dtype) +
                         " is " + num(nbytes) + " bytes, more than the limit of " +
                         num(resource_limits().max_tensor_bytes) + " (--max-tensor-bytes)");
  e.bytes = size_t(nbytes);
  if (numel == 0) return e;  // no element is addressed
  const uint64_t storage_numel = uint64_t(st.i);
  if (last >= storage_numel)
    return Status::error(where + ": size " + shape_text(e.shape) + ", stride " +
                         shape_text(stride) + ", offset " + num(uint64_t(off.i)) +
                         " reach element " + num(last) + " of storage '" + printable(st.s) +
                         "', which holds " + num(storage_numel));
  Record& rec = entries_[st.record];
  MACRO_TRY(resolve_record(rec));
  const uint8_t* src = rec.bytes + uint64_t(off.i) * es;
  // Row-major contiguous (dims of size 1 may carry any stride, as in torch).
  bool contiguous = true;
  uint64_t expect = 1;
  for (size_t d = e.shape.size(); d-- > 0;) {
    if (e.shape[d] != 1 && uint64_t(stride[d]) != expect) contiguous = false;
    expect *= uint64_t(e.shape[d]);
  }
  if (contiguous && reinterpret_cast<uintptr_t>(src) % es == 0) {
    e.data = src;
    return e;
  }
  MACRO_ASSIGN_OR_RETURN(uint8_t * dst, allocate(nbytes, "tensor '" + printable(name) + "'"));
  // Gather in row-major order with an odometer over the dims.
  const size_t nd = e.shape.size();
  std::vector<int64_t> idx(nd, 0);
  uint64_t src_elem = 0;
  for (uint64_t k = 0; k < numel; ++k) {
    std::memcpy(dst + k * es, src + src_elem * es, es);
    for (size_t d = nd; d-- > 0;) {
      if (++idx[d] < e.shape[d]) {
        src_elem += uint64_t(stride[d]);
        break;
      }
      src_elem -= uint64_t(stride[d]) * uint64_t(e.shape[d] - 1);
      idx[d] = 0;
    }
  }
  e.data = dst;
  return e;
}

Status Reader::flatten(const Unpickler& vm, ObjId id, const std::string& name, int depth,
                       TorchCheckpoint* out, std::set<std::string>* seen) {
  const Obj& o = vm.obj(id);
  if (visits_left_-- == 0)
    return Status::error(file_ + ": '" + printable(name, 200) +
                         "': the pickle's shared references expand to more entries than it has "
                         "objects (" + num(vm.object_count()) + "); not a state dict");
  if (depth > kMaxNesting)
    return Status::error(file_ + ": '" + printable(name, 200) + "': nested deeper than " +
                         num(kMaxNesting) + " levels");
  auto child = [&](const std::string& k) { return name.empty() ? k : name + "." + k; };
  switch (o.kind) {
    case Kind::kTensor: {
      MACRO_ASSIGN_OR_RETURN(TensorEntry e, make_tensor(vm, o, name));
      if (!seen->insert(name).second)
        return Status::error(file_ + ": tensor '" + printable(name, 200) + "' appears twice");
      out->tensors.push_back(std::move(e));
      return Status::ok();
    }
    case Kind::kDict:
      for (size_t k = 0; k + 1 < o.items.size(); k += 2) {
        const Obj& key = vm.obj(o.items[k]);
        std::string ks;
        if (key.kind == Kind::kStr) {
          ks = key.s;
        } else if (key.kind == Kind::kInt) {
          ks = std::to_string(key.i);
        } else {
          return Status::error(file_ + ": '" + printable(name, 200) +
                               "': a dict key is neither a string nor an integer");
        }
        MACRO_TRY(flatten(vm, o.items[k + 1], child(ks), depth + 1, out, seen));
      }
      return Status::ok();
    case Kind::kList:
    case Kind::kTuple:
      for (size_t k = 0; k < o.items.size(); ++k)
        MACRO_TRY(flatten(vm, o.items[k], child(std::to_string(k)), depth + 1, out, seen));
      return Status::ok();
    default:
      return Status::ok();  // numbers, strings, None, storages, dtypes: not tensors
  }
}

Result<TorchCheckpoint> Reader::read(const std::string& key) {
  if (size_ >= 8 && std::memcmp(base_, "PYTORCH1", 8) == 0)
    return Status::error(file_ + ": a torch preview-release archive, not supported");
  if (size_ >= 2 && base_[0] == 0x80)
    return Status::error(file_ + ": a legacy (pre-1.6, non-zip) torch.save file; re-save it with "
                         "torch >= 1.6 or convert it to safetensors");
  if (size_ < 4 || le32(base_) != kZipLocalHeaderSig)
    return Status::error(file_ + ": not a zip archive (expected 'PK\\3\\4' at offset 0)");
  MACRO_ASSIGN_OR_RETURN(std::vector<ZipEntry> zip, read_zip_directory(base_, size_, file_));
  entries_.reserve(zip.size());
  for (ZipEntry& z : zip) {
    entries_.emplace_back();
    static_cast<ZipEntry&>(entries_.back()) = std::move(z);
  }

  // The prefix is the folder holding data.pkl (torch: the first record's folder).
  std::string prefix;
  for (const Record& e : entries_) {
    const size_t slash = e.name.find('/');
    if (slash != std::string::npos && slash > 0 && e.name.compare(slash, std::string::npos,
                                                                  "/data.pkl") == 0) {
      prefix = e.name.substr(0, slash);
      break;
    }
  }
  if (prefix.empty()) {
    std::string names;
    for (size_t i = 0; i < entries_.size() && i < 5; ++i)
      names += (i ? ", " : "") + printable(entries_[i].name);
    return Status::error(file_ + ": no '<folder>/data.pkl' record, not a torch.save checkpoint" +
                         (names.empty() ? std::string(" (empty archive)")
                                        : " (records: " + names + ")"));
  }
  TorchCheckpoint out;
  out.path = file_;
  out.archive_prefix = prefix;
  Unpickler vm(file_, prefix, &entries_);
  const size_t bo = vm.record_index(prefix + "/byteorder");
  if (bo != SIZE_MAX) {
    MACRO_TRY(resolve_record(entries_[bo]));
    std::string order(reinterpret_cast<const char*>(entries_[bo].bytes),
                      std::min<uint64_t>(entries_[bo].size, 16));
    if (order != "little")
      return Status::error(file_ + ": record '" + prefix + "/byteorder' is '" + printable(order) +
                           "', only little-endian checkpoints are supported");
  }
  Record& pkl = entries_[vm.record_index(prefix + "/data.pkl")];
  if (pkl.size > kMaxPickleBytes)
    return Status::error(file_ + ": " + prefix + "/data.pkl is " + num(pkl.size) +
                         " bytes, more than the limit of " + num(kMaxPickleBytes));
  MACRO_TRY(resolve_record(pkl));
  if (pkl.method == 0 && pkl.crc != 0 && pkl.size > 0 &&
      zip_crc32(pkl.bytes, pkl.size) != pkl.crc)
    return Status::error(file_ + ": " + prefix + "/data.pkl: CRC-32 mismatch (corrupt file)");
  MACRO_ASSIGN_OR_RETURN(ObjId root_id, vm.run(pkl.bytes ? pkl.bytes : base_, pkl.size));

  const Obj& root = vm.obj(root_id);
  if (root.kind != Kind::kDict)
    return Status::error(file_ + ": the checkpoint holds a " +
                         std::string(root.kind == Kind::kTensor ? "single tensor" : "non-dict") +
                         ", expected a dict of tensors (a state dict)");
  auto lookup = [&](const std::string& k) -> ObjId {
    for (size_t i = 0; i + 1 < root.items.size(); i += 2) {
      const Obj& ko = vm.obj(root.items[i]);
      if (ko.kind == Kind::kStr && ko.s == k) return root.items[i + 1];
    }
    return UINT32_MAX;
  };
  auto root_keys = [&] {
    std::string t;
    size_t shown = 0;
    for (size_t i = 0; i + 1 < root.items.size(); i += 2) {
      const Obj& ko = vm.obj(root.items[i]);
      if (ko.kind != Kind::kStr) continue;
      if (shown++ == 12) {
        t += ", ...";
        break;
      }
      t += (t.empty() ? "'" : ", '") + printable(ko.s) + "'";
    }
    return t.empty() ? std::string("none") : t;
  };
  ObjId selected = root_id;
  if (!key.empty()) {
    selected = lookup(key);
    if (selected == UINT32_MAX)
      return Status::error(file_ + ": key '" + printable(key) + "' not found (top-level keys: " +
                           root_keys() + ")");
    out.selected_key = key;
  } else {
    bool direct_tensor = false;
    for (size_t i = 1; i < root.items.size(); i += 2)
      direct_tensor |= vm.obj(root.items[i]).kind == Kind::kTensor;
    if (!direct_tensor) {
      if (lookup("params_ema") != UINT32_MAX) {
        out.selected_key = "params_ema";
      } else {
        std::vector<std::string> found;
        for (const char* k : {"params", "state_dict", "model"})
          if (lookup(k) != UINT32_MAX) found.push_back(k);
        if (found.size() > 1)
          return Status::error(file_ + ": holds both '" + found[0] + "' and '" + found[1] +
                               "'; name the state dict to load (a key)");
        if (found.size() == 1) out.selected_key = found[0];
      }
      if (!out.selected_key.empty()) selected = lookup(out.selected_key);
    }
  }
  // A key naming a single tensor gives that one tensor, named by the key.
  const std::string top = vm.obj(selected).kind == Kind::kTensor ? out.selected_key : "";
  std::set<std::string> seen;
  visits_left_ = 2 * uint64_t(vm.object_count()) + 1024;
  MACRO_TRY(flatten(vm, selected, top, 0, &out, &seen));
  if (out.tensors.empty())
    return Status::error(file_ + ": no tensors found" +
                         (out.selected_key.empty() ? std::string()
                                                   : " under key '" + printable(out.selected_key) +
                                                         "'") +
                         " (top-level keys: " + root_keys() + ")");
  out.owner = owner_;
  return out;
}

}  // namespace

Result<TorchCheckpoint> read_torch_checkpoint_from_memory(const uint8_t* data, size_t size,
                                                          const std::string& name,
                                                          const std::string& key) {
  static const uint8_t kEmpty[1] = {0};
  Reader r(size ? data : kEmpty, size, name, std::make_shared<Owner>());
  return r.read(key);
}

Result<TorchCheckpoint> read_torch_checkpoint(const std::string& path, const std::string& key) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status::error(path + ": cannot open: " + std::strerror(errno));
  struct stat st;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return Status::error(path + ": expected a regular file");
  }
  auto owner = std::make_shared<Owner>();
  const size_t bytes = size_t(st.st_size);
  static const uint8_t kEmpty[1] = {0};
  const uint8_t* base = kEmpty;
  if (bytes > 0) {
    void* addr = ::mmap(nullptr, bytes, PROT_READ, MAP_PRIVATE, fd, 0);
    if (addr == MAP_FAILED) {
      std::string err = std::strerror(errno);
      ::close(fd);
      return Status::error(path + ": cannot map: " + err);
    }
    owner->maps.emplace_back(addr, bytes);
    base = static_cast<const uint8_t*>(addr);
  }
  ::close(fd);
  Reader r(base, bytes, path, std::move(owner));
  return r.read(key);
}

bool file_has_zip_magic(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  unsigned char m[4] = {0, 0, 0, 0};
  ssize_t n = ::read(fd, m, 4);
  ::close(fd);
  return n == 4 && le32(m) == kZipLocalHeaderSig;
}

}  // namespace macro
