// PyTorch zip checkpoint reader (format and rules: torch_checkpoint.h).
//
// Three stages, each bounds-checked against the bytes it was given:
//   1. the zip directory (zip_reader.h): every record's data range inside the file; stored records
//      are used in place, deflated ones inflated on first use;
//   2. the pickle machine over <prefix>/data.pkl (torch_pickle.h): plain data objects in an arena
//      (so a cyclic memo reference cannot leak or recurse forever), whitelisted globals resolved to
//      tags, storages resolved to records at BINPERSID;
//   3. selection of the state dict and flattening to named tensors, each validated (shape, stride,
//      offset inside its storage) and either pointing into the record or gathered into a copy.
#include "attention/runtime/io/torch_checkpoint.h"

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
#include "attention/runtime/io/torch_pickle.h"
#include "attention/runtime/io/zip_reader.h"

namespace macro {

namespace {

using namespace torch_pickle;

// Bounds for what a file may make us hold. Real checkpoints stay far below: data.pkl costs a few
// hundred bytes per tensor (a thousand-tensor model: well under 1 MB), a state dict nests 2-3 deep.
constexpr uint64_t kMaxPickleBytes = 256ull << 20;
constexpr int kMaxNesting = 64;            // dict/list depth when flattening
constexpr int kMaxDims = 64;
// Owned copies (strided tensors, inflated records) may total at most this much beyond four times
// the file size; a strided view with stride 0 could otherwise ask for far more than the file holds.
constexpr uint64_t kCopyAllowanceBytes = 256ull << 20;

bool add_overflow(uint64_t a, uint64_t b, uint64_t* out) {
  return __builtin_add_overflow(a, b, out);
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
  const std::string rec = file_ + ": record '" + printable_name(e.name) + "'";
  if (e.method == 0) {
    e.bytes = base_ + e.data_offset;
    return Status::ok();
  }
  MACRO_TRY(check_inflated_size(e, file_));
  if (e.size > resource_limits().max_tensor_bytes)
    return Status::error(rec + ": " + num(e.size) + " bytes exceeds the limit of " +
                         num(resource_limits().max_tensor_bytes) + " (--max-tensor-bytes)");
  MACRO_ASSIGN_OR_RETURN(uint8_t * out, allocate(e.size, "record '" + printable_name(e.name) + "'"));
  MACRO_TRY(inflate_zip_record(base_, e, out, file_));
  e.bytes = out;
  return Status::ok();
}

Result<TensorEntry> Reader::make_tensor(const Unpickler& vm, const Obj& t,
                                        const std::string& name) {
  const std::string where = file_ + ": tensor '" + printable_name(name, 200) + "'";
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
                         " reach element " + num(last) + " of storage '" + printable_name(st.s) +
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
  MACRO_ASSIGN_OR_RETURN(uint8_t * dst, allocate(nbytes, "tensor '" + printable_name(name) + "'"));
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
    return Status::error(file_ + ": '" + printable_name(name, 200) +
                         "': the pickle's shared references expand to more entries than it has "
                         "objects (" + num(vm.object_count()) + "); not a state dict");
  if (depth > kMaxNesting)
    return Status::error(file_ + ": '" + printable_name(name, 200) + "': nested deeper than " +
                         num(kMaxNesting) + " levels");
  auto child = [&](const std::string& k) { return name.empty() ? k : name + "." + k; };
  switch (o.kind) {
    case Kind::kTensor: {
      MACRO_ASSIGN_OR_RETURN(TensorEntry e, make_tensor(vm, o, name));
      if (!seen->insert(name).second)
        return Status::error(file_ + ": tensor '" + printable_name(name, 200) + "' appears twice");
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
          return Status::error(file_ + ": '" + printable_name(name, 200) +
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
      names += (i ? ", " : "") + printable_name(entries_[i].name);
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
      return Status::error(file_ + ": record '" + prefix + "/byteorder' is '" + printable_name(order) +
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
      t += (t.empty() ? "'" : ", '") + printable_name(ko.s) + "'";
    }
    return t.empty() ? std::string("none") : t;
  };
  ObjId selected = root_id;
  if (!key.empty()) {
    selected = lookup(key);
    if (selected == UINT32_MAX)
      return Status::error(file_ + ": key '" + printable_name(key) + "' not found (top-level keys: " +
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
                                                   : " under key '" + printable_name(out.selected_key) +
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
