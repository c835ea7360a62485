// safetensors reader (mmap + full validation) and atomic writer. Format: see safetensors.h.
#include "attention/runtime/io/safetensors.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <nlohmann/json.hpp>
#include <set>

#include "attention/runtime/file_io.h"
#include "attention/runtime/half.h"
#include "attention/runtime/limits.h"
#include "attention/runtime/io/torch_checkpoint.h"

namespace macro {

namespace {

using json = nlohmann::json;

// A header larger than this is refused before any allocation (real checkpoints stay far below:
// the SD-Turbo U-Net header is about 100 KB).
constexpr uint64_t kMaxHeaderBytes = 100ull << 20;
constexpr uint64_t kMaxIndexBytes = 64ull << 20;

std::string errno_text() {
  return std::strerror(errno);
}

bool mul_overflow(uint64_t a, uint64_t b, uint64_t* out) {
  return __builtin_mul_overflow(a, b, out);
}

// Parse JSON text, refusing duplicate keys at any depth (nlohmann would keep one silently).
// Returns the parsed value or an error message (without the file name).
Result<json> parse_json_strict(const std::string& text) {
  std::vector<std::set<std::string>> keys;  // one set per open object
  std::string duplicate;
  auto cb = [&](int /*depth*/, json::parse_event_t event, json& parsed) -> bool {
    switch (event) {
      case json::parse_event_t::object_start:
        keys.emplace_back();
        break;
      case json::parse_event_t::object_end:
        if (!keys.empty()) keys.pop_back();
        break;
      case json::parse_event_t::key:
        if (!keys.empty() && parsed.is_string()) {
          const std::string& k = parsed.get_ref<const std::string&>();
          if (!keys.back().insert(k).second && duplicate.empty()) duplicate = k;
        }
        break;
      default:
        break;
    }
    return true;
  };
  json j;
  try {
    j = json::parse(text, cb, /*allow_exceptions=*/true);
  } catch (const std::exception& e) {
    return Status::error(std::string("malformed JSON header: ") + e.what());
  }
  if (!duplicate.empty()) return Status::error("duplicate name '" + duplicate + "' in JSON header");
  return j;
}

std::string dir_of(const std::string& path) {
  size_t p = path.find_last_of('/');
  return p == std::string::npos ? std::string(".") : path.substr(0, p);
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

std::string shape_text(const std::vector<int64_t>& s) {
  std::string t = "[";
  for (size_t i = 0; i < s.size(); ++i) {
    if (i) t += ',';
    t += std::to_string(s[i]);
  }
  t += ']';
  return t;
}

const char* dtype_name(DType dtype) {
  switch (dtype) {
    case DType::kF32:
      return "F32";
    case DType::kF16:
      return "F16";
    case DType::kBF16:
      return "BF16";
    case DType::kI32:
      return "I32";
    case DType::kI64:
      return "I64";
    case DType::kU8:
      return "U8";
    case DType::kI8:
      return "I8";
    case DType::kBool:
      return "BOOL";
    case DType::kF64:
      return "F64";
  }
  return "?";
}

size_t dtype_size(DType dtype) {
  switch (dtype) {
    case DType::kF32:
      return 4;
    case DType::kF16:
      return 2;
    case DType::kBF16:
      return 2;
    case DType::kI32:
      return 4;
    case DType::kI64:
      return 8;
    case DType::kU8:
      return 1;
    case DType::kI8:
      return 1;
    case DType::kBool:
      return 1;
    case DType::kF64:
      return 8;
  }
  return 0;
}

Result<DType> parse_dtype(const std::string& name) {
  static const DType all[] = {DType::kF32, DType::kF16, DType::kBF16, DType::kI32, DType::kI64,
                              DType::kU8,  DType::kI8,  DType::kBool, DType::kF64};
  for (DType d : all)
    if (name == dtype_name(d)) return d;
  return Status::error("unknown dtype '" + name +
                       "' (expected one of F32, F16, BF16, F64, I32, I64, U8, I8, BOOL)");
}

// ---------------------------------------------------------------------------------------------
// Mapping

struct SafeTensors::Mapping {
  void* addr = nullptr;
  size_t size = 0;
  ~Mapping() {
    if (addr) ::munmap(addr, size);
  }
};

SafeTensors::SafeTensors() = default;
SafeTensors::~SafeTensors() = default;
SafeTensors::SafeTensors(SafeTensors&&) noexcept = default;
SafeTensors& SafeTensors::operator=(SafeTensors&&) noexcept = default;

std::vector<std::string> SafeTensors::names() const {
  std::vector<std::string> out;
  out.reserve(tensors_.size());
  for (const auto& kv : tensors_) out.push_back(kv.first);
  return out;
}

bool SafeTensors::contains(const std::string& name) const {
  return tensors_.count(name) != 0;
}

const TensorEntry* SafeTensors::find(const std::string& name) const {
  auto it = tensors_.find(name);
  return it == tensors_.end() ? nullptr : &it->second;
}

Result<SafeTensors> SafeTensors::open(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status::error(path + ": cannot open: " + errno_text());
  struct stat st;
  if (::fstat(fd, &st) != 0) {
    std::string e = errno_text();
    ::close(fd);
    return Status::error(path + ": cannot stat: " + e);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return Status::error(path + ": expected a regular file");
  }
  const uint64_t file_bytes = static_cast<uint64_t>(st.st_size);
  if (file_bytes < 8) {
    ::close(fd);
    return Status::error(path + ": truncated: file is " + std::to_string(file_bytes) +
                         " bytes, expected at least 8 (header length)");
  }
  auto mapping = std::make_shared<Mapping>();
  void* addr = ::mmap(nullptr, file_bytes, PROT_READ, MAP_PRIVATE, fd, 0);
  ::close(fd);
  if (addr == MAP_FAILED) return Status::error(path + ": cannot map: " + errno_text());
  mapping->addr = addr;
  mapping->size = file_bytes;
  const uint8_t* base = static_cast<const uint8_t*>(addr);

  uint64_t header_len = 0;
  for (int i = 0; i < 8; ++i) header_len |= uint64_t(base[i]) << (8 * i);
  if (header_len > kMaxHeaderBytes)
    return Status::error(path + ": header length " + std::to_string(header_len) +
                         " bytes exceeds the limit of " + std::to_string(kMaxHeaderBytes));
  if (header_len > file_bytes - 8)
    return Status::error(path + ": truncated: header length " + std::to_string(header_len) +
                         " bytes but only " + std::to_string(file_bytes - 8) +
                         " bytes follow the length field");
  const uint8_t* data = base + 8 + header_len;
  const uint64_t data_bytes = file_bytes - 8 - header_len;

  std::string text(reinterpret_cast<const char*>(base + 8), header_len);
  auto parsed = parse_json_strict(text);
  if (!parsed) return parsed.status().with_context(path);
  const json& header = *parsed;
  if (!header.is_object())
    return Status::error(path + ": header: expected a JSON object, found " +
                         std::string(header.type_name()));

  SafeTensors st_out;
  st_out.path_ = path;
  struct Range {
    uint64_t begin, end;
    const std::string* name;
  };
  std::vector<Range> ranges;
  for (auto it = header.begin(); it != header.end(); ++it) {
    const std::string& name = it.key();
    const json& v = it.value();
    if (name == "__metadata__") {
      if (!v.is_object())
        return Status::error(path + ": __metadata__: expected an object of strings, found " +
                             std::string(v.type_name()));
      for (auto m = v.begin(); m != v.end(); ++m) {
        if (!m.value().is_string())
          return Status::error(path + ": __metadata__ '" + m.key() +
                               "': expected a string, found " + std::string(m.value().type_name()));
        st_out.metadata_[m.key()] = m.value().get<std::string>();
      }
      continue;
    }
    const std::string where = path + ": tensor '" + name + "'";
    if (!v.is_object())
      return Status::error(where + ": expected an object, found " + v.type_name());
    for (auto f = v.begin(); f != v.end(); ++f)
      if (f.key() != "dtype" && f.key() != "shape" && f.key() != "data_offsets")
        return Status::error(where + ": unexpected field '" + f.key() + "'");
    if (!v.contains("dtype") || !v["dtype"].is_string())
      return Status::error(where + ": field 'dtype': expected a string");
    auto dt = parse_dtype(v["dtype"].get<std::string>());
    if (!dt) return dt.status().with_context(where);
    if (!v.contains("shape") || !v["shape"].is_array())
      return Status::error(where + ": field 'shape': expected an array of non-negative integers");
    if (!v.contains("data_offsets") || !v["data_offsets"].is_array() ||
        v["data_offsets"].size() != 2)
      return Status::error(where + ": field 'data_offsets': expected [begin, end]");

    TensorEntry e;
    e.name = name;
    e.dtype = *dt;
    uint64_t numel = 1;
    for (const json& d : v["shape"]) {
      if (!d.is_number_unsigned() && !(d.is_number_integer() && d.get<int64_t>() >= 0))
        return Status::error(where + ": field 'shape': expected non-negative integers, found " +
                             d.dump());
      uint64_t dim = d.get<uint64_t>();
      if (dim > uint64_t(INT64_MAX) || mul_overflow(numel, dim, &numel))
        return Status::error(where + ": shape " + v["shape"].dump() + " overflows 64 bits");
      e.shape.push_back(static_cast<int64_t>(dim));
    }
    uint64_t nbytes = 0;
    if (mul_overflow(numel, dtype_size(e.dtype), &nbytes))
      return Status::error(where + ": shape " + v["shape"].dump() + " overflows 64 bits");
    const json& off = v["data_offsets"];
    if (!off[0].is_number_unsigned() || !off[1].is_number_unsigned())
      return Status::error(
          where + ": field 'data_offsets': expected non-negative integers, found " + off.dump());
    uint64_t b = off[0].get<uint64_t>(), en = off[1].get<uint64_t>();
    if (en < b) return Status::error(where + ": data_offsets " + off.dump() + ": end before begin");
    if (en > data_bytes)
      return Status::error(where + ": data_offsets " + off.dump() +
                           " outside the data section of " + std::to_string(data_bytes) + " bytes");
    if (en - b != nbytes)
      return Status::error(where + ": shape " + shape_text(e.shape) + " of " + dtype_name(e.dtype) +
                           " needs " + std::to_string(nbytes) + " bytes, data_offsets " +
                           off.dump() + " give " + std::to_string(en - b));
    if (nbytes > resource_limits().max_tensor_bytes)
      return Status::error(where + ": shape " + shape_text(e.shape) + " of " + dtype_name(e.dtype) +
                           " is " + std::to_string(nbytes) + " bytes, more than the limit of " +
                           std::to_string(resource_limits().max_tensor_bytes) +
                           " (--max-tensor-bytes)");
    e.data = data + b;
    e.bytes = static_cast<size_t>(nbytes);
    auto ins = st_out.tensors_.emplace(name, std::move(e));
    if (!ins.second)
      return Status::error(where + ": duplicate name");  // parse_json_strict caught it
    if (en > b) ranges.push_back({b, en, &ins.first->first});
  }
  std::sort(ranges.begin(), ranges.end(),
            [](const Range& x, const Range& y) { return x.begin < y.begin; });
  for (size_t i = 1; i < ranges.size(); ++i)
    if (ranges[i].begin < ranges[i - 1].end)
      return Status::error(path + ": tensor '" + *ranges[i].name + "' bytes [" +
                           std::to_string(ranges[i].begin) + ", " + std::to_string(ranges[i].end) +
                           ") overlap tensor '" + *ranges[i - 1].name + "' [" +
                           std::to_string(ranges[i - 1].begin) + ", " +
                           std::to_string(ranges[i - 1].end) + ")");
  st_out.mappings_.push_back(std::move(mapping));
  return st_out;
}

Result<SafeTensors> SafeTensors::open_torch(const std::string& path, const std::string& key) {
  MACRO_ASSIGN_OR_RETURN(TorchCheckpoint ck, read_torch_checkpoint(path, key));
  SafeTensors out;
  out.path_ = path;
  out.metadata_["format"] = "pt";
  out.metadata_["torch.archive"] = ck.archive_prefix;
  out.metadata_["torch.key"] = ck.selected_key;
  for (TensorEntry& e : ck.tensors) {
    std::string name = e.name;
    if (!out.tensors_.emplace(name, std::move(e)).second)
      return Status::error(path + ": tensor '" + name + "' appears twice after flattening");
  }
  out.owner_ = std::move(ck.owner);
  return out;
}

Result<SafeTensors> SafeTensors::open_checkpoint(const std::string& path) {
  if (!ends_with(path, ".safetensors") && !ends_with(path, ".index.json") &&
      file_has_zip_magic(path))
    return open_torch(path);
  if (!ends_with(path, ".index.json")) return open(path);
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, kMaxIndexBytes));
  auto parsed = parse_json_strict(text);
  if (!parsed) return parsed.status().with_context(path);
  const json& index = *parsed;
  if (!index.is_object() || !index.contains("weight_map") || !index["weight_map"].is_object())
    return Status::error(path + ": expected an object with a 'weight_map' object");
  const std::string dir = dir_of(path);
  std::map<std::string, std::vector<std::string>> by_shard;  // shard -> names
  for (auto it = index["weight_map"].begin(); it != index["weight_map"].end(); ++it) {
    if (!it.value().is_string())
      return Status::error(path + ": weight_map '" + it.key() + "': expected a file name, found " +
                           it.value().dump());
    std::string shard = it.value().get<std::string>();
    if (shard.empty() || shard[0] == '/' || shard.find("..") != std::string::npos)
      return Status::error(path + ": weight_map '" + it.key() +
                           "': expected a file name beside the index, found '" + shard + "'");
    by_shard[shard].push_back(it.key());
  }
  SafeTensors out;
  out.path_ = path;
  if (index.contains("metadata") && index["metadata"].is_object())
    for (auto m = index["metadata"].begin(); m != index["metadata"].end(); ++m)
      out.metadata_[m.key()] =
          m.value().is_string() ? m.value().get<std::string>() : m.value().dump();
  for (auto& [shard, names] : by_shard) {
    const std::string shard_path = dir + "/" + shard;
    if (!file_exists(shard_path))
      return Status::error(path + ": tensor '" + names.front() + "' is mapped to shard '" + shard +
                           "', which does not exist (" + shard_path + ")");
    MACRO_ASSIGN_OR_RETURN(SafeTensors part, open(shard_path));
    for (const std::string& n : names) {
      const TensorEntry* e = part.find(n);
      if (!e)
        return Status::error(path + ": tensor '" + n + "' is mapped to shard '" + shard +
                             "' but that file does not contain it");
      if (!out.tensors_.emplace(n, *e).second)
        return Status::error(path + ": tensor '" + n + "' appears in more than one shard");
    }
    for (auto& kv : part.metadata_) out.metadata_.emplace(kv.first, kv.second);
    for (auto& m : part.mappings_) out.mappings_.push_back(m);
  }
  return out;
}

Result<std::vector<float>> SafeTensors::read_f32(const std::string& name,
                                                 const std::vector<int64_t>& expected_shape) const {
  const TensorEntry* e = find(name);
  if (!e) return Status::error(path_ + ": tensor '" + name + "' not found");
  if (!expected_shape.empty() && expected_shape != e->shape)
    return Status::error(path_ + ": tensor '" + name + "': expected shape " +
                         shape_text(expected_shape) + ", found " + shape_text(e->shape));
  const size_t n = e->bytes / dtype_size(e->dtype);
  std::vector<float> out(n);
  MACRO_TRY(convert_to_f32(*e, out.data(), n));
  return out;
}

Status convert_to_f32(const TensorEntry& e, float* dst, size_t n) {
  const size_t es = dtype_size(e.dtype);
  if (n * es != e.bytes)
    return Status::error("tensor '" + e.name + "': expected " + std::to_string(n) +
                         " elements, found " + std::to_string(e.bytes / es));
  if (n == 0) return Status::ok();  // empty tensors: no pointer is touched
  const uint8_t* p = e.data;
  switch (e.dtype) {
    case DType::kF32:
      std::memcpy(dst, p, n * 4);
      break;
    case DType::kF64:
      for (size_t i = 0; i < n; ++i) {
        double v;
        std::memcpy(&v, p + 8 * i, 8);
        dst[i] = static_cast<float>(v);
      }
      break;
    case DType::kBF16:
      for (size_t i = 0; i < n; ++i) {
        uint16_t h;
        std::memcpy(&h, p + 2 * i, 2);
        dst[i] = bf16_to_f32(h);
      }
      break;
    case DType::kF16:
      for (size_t i = 0; i < n; ++i) {
        uint16_t h;
        std::memcpy(&h, p + 2 * i, 2);
        dst[i] = f16_to_f32(h);
      }
      break;
    case DType::kI32:
      for (size_t i = 0; i < n; ++i) {
        int32_t v;
        std::memcpy(&v, p + 4 * i, 4);
        dst[i] = static_cast<float>(v);
      }
      break;
    case DType::kI64:
      for (size_t i = 0; i < n; ++i) {
        int64_t v;
        std::memcpy(&v, p + 8 * i, 8);
        dst[i] = static_cast<float>(v);
      }
      break;
    case DType::kU8:
      for (size_t i = 0; i < n; ++i) dst[i] = p[i];
      break;
    case DType::kI8:
      for (size_t i = 0; i < n; ++i) dst[i] = static_cast<int8_t>(p[i]);
      break;
    case DType::kBool:
      for (size_t i = 0; i < n; ++i) dst[i] = p[i] ? 1.0f : 0.0f;
      break;
  }
  return Status::ok();
}

// ---------------------------------------------------------------------------------------------
// Writer

Status write_safetensors(const std::string& path, const std::vector<TensorToWrite>& tensors,
                         const std::map<std::string, std::string>& metadata) {
  json header = json::object();
  if (!metadata.empty()) {
    json m = json::object();
    for (const auto& kv : metadata) m[kv.first] = kv.second;
    header["__metadata__"] = m;
  }
  uint64_t offset = 0;
  std::vector<uint64_t> sizes;
  for (const TensorToWrite& t : tensors) {
    const std::string where = path + ": tensor '" + t.name + "'";
    if (t.name.empty() || t.name == "__metadata__")
      return Status::error(path + ": invalid tensor name '" + t.name + "'");
    if (header.contains(t.name)) return Status::error(where + ": duplicate name");
    uint64_t numel = 1;
    json shape = json::array();
    for (int64_t d : t.shape) {
      if (d < 0)
        return Status::error(where + ": negative dimension in shape " + shape_text(t.shape));
      if (mul_overflow(numel, uint64_t(d), &numel))
        return Status::error(where + ": shape " + shape_text(t.shape) + " overflows");
      shape.push_back(d);
    }
    uint64_t bytes = 0;
    if (mul_overflow(numel, dtype_size(t.dtype), &bytes))
      return Status::error(where + ": shape " + shape_text(t.shape) + " overflows");
    if (bytes && !t.data) return Status::error(where + ": no data");
    header[t.name] = {{"dtype", dtype_name(t.dtype)},
                      {"shape", shape},
                      {"data_offsets", {offset, offset + bytes}}};
    sizes.push_back(bytes);
    offset += bytes;
  }
  std::string text = header.dump();
  while (text.size() % 8) text.push_back(' ');
  uint8_t len[8];
  for (int i = 0; i < 8; ++i) len[i] = uint8_t(uint64_t(text.size()) >> (8 * i));
  AtomicFile f;
  MACRO_TRY(f.open(path));
  MACRO_TRY(f.write(len, 8));
  MACRO_TRY(f.write(text));
  for (size_t i = 0; i < tensors.size(); ++i)
    if (sizes[i]) MACRO_TRY(f.write(tensors[i].data, sizes[i]));
  return f.commit();
}

}  // namespace macro
