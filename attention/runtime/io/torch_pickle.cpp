// The restricted pickle machine (torch_pickle.h): the whitelist of globals and the opcodes.
#include "attention/runtime/io/torch_pickle.h"

#include <algorithm>

namespace macro::torch_pickle {
namespace {

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


}  // namespace

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
  return fail("global '" + printable_name(module) + "." + printable_name(name) +
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
    return fail("storage '" + printable_name(k) + "' refers to record '" + printable_name(record) +
                "', which the archive does not contain");
  const DType dtype = type.dtype;
  uint64_t nbytes = 0;
  if (mul_overflow(uint64_t(count.i), dtype_size(dtype), &nbytes) ||
      nbytes != (*entries_)[idx].size)
    return fail("storage '" + printable_name(k) + "': " + num(uint64_t(count.i)) + " elements of " +
                dtype_name(dtype) + " need " + num(nbytes) + " bytes, record '" +
                printable_name(record) + "' holds " + num((*entries_)[idx].size));
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


}  // namespace macro::torch_pickle
