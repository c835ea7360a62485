// Generic PLY header and element reader (see ply_reader.h for the contract).
#include "gs/formats/ply_reader.h"

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <limits>

namespace macro::gs::ply {
namespace {

constexpr size_t kMaxHeaderBytes = 16u
                                   << 20;  // a header is a few KB; anything past this is not PLY

struct TypeInfo {
  const char* name;
  const char* alias;
  Type type;
  size_t size;
};
constexpr TypeInfo kTypes[] = {
    {"char", "int8", Type::kInt8, 1},        {"uchar", "uint8", Type::kUint8, 1},
    {"short", "int16", Type::kInt16, 2},     {"ushort", "uint16", Type::kUint16, 2},
    {"int", "int32", Type::kInt32, 4},       {"uint", "uint32", Type::kUint32, 4},
    {"float", "float32", Type::kFloat32, 4}, {"double", "float64", Type::kFloat64, 8},
};

bool parse_type(std::string_view s, Type* out) {
  for (const TypeInfo& t : kTypes) {
    if (s == t.name || s == t.alias) {
      *out = t.type;
      return true;
    }
  }
  return false;
}

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
    if (j > i) words.push_back(line.substr(i, j - i));
    i = j;
  }
  return words;
}

template <typename T>
T load(const uint8_t* p, bool swap) {
  uint8_t b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

double read_value(const uint8_t* p, Type t, bool swap) {
  switch (t) {
    case Type::kInt8:
      return load<int8_t>(p, false);
    case Type::kUint8:
      return load<uint8_t>(p, false);
    case Type::kInt16:
      return load<int16_t>(p, swap);
    case Type::kUint16:
      return load<uint16_t>(p, swap);
    case Type::kInt32:
      return load<int32_t>(p, swap);
    case Type::kUint32:
      return load<uint32_t>(p, swap);
    case Type::kFloat32:
      return load<float>(p, swap);
    case Type::kFloat64:
      return load<double>(p, swap);
  }
  return 0;
}

// out[r] = float(value at base + r*stride), one typed loop per (type, endianness).
template <typename T, bool kSwap>
void gather(const uint8_t* base, size_t stride, size_t n, float* out) {
  for (size_t r = 0; r < n; ++r) {
    const uint8_t* p = base + r * stride;
    T v;
    if constexpr (kSwap && sizeof(T) > 1) {
      uint8_t b[sizeof(T)];
      for (size_t k = 0; k < sizeof(T); ++k) b[k] = p[sizeof(T) - 1 - k];
      std::memcpy(&v, b, sizeof(T));
    } else {
      std::memcpy(&v, p, sizeof(T));
    }
    out[r] = static_cast<float>(v);
  }
}

template <bool kSwap>
void gather_any(Type t, const uint8_t* base, size_t stride, size_t n, float* out) {
  switch (t) {
    case Type::kInt8:
      return gather<int8_t, kSwap>(base, stride, n, out);
    case Type::kUint8:
      return gather<uint8_t, kSwap>(base, stride, n, out);
    case Type::kInt16:
      return gather<int16_t, kSwap>(base, stride, n, out);
    case Type::kUint16:
      return gather<uint16_t, kSwap>(base, stride, n, out);
    case Type::kInt32:
      return gather<int32_t, kSwap>(base, stride, n, out);
    case Type::kUint32:
      return gather<uint32_t, kSwap>(base, stride, n, out);
    case Type::kFloat32:
      return gather<float, kSwap>(base, stride, n, out);
    case Type::kFloat64:
      return gather<double, kSwap>(base, stride, n, out);
  }
}

std::string element_label(const Element& e) {
  return "element '" + e.name + "'";
}

// Bytes a binary list row's item count says it holds; fails on negative or non-integer counts.
bool list_count(const uint8_t* p, Type count_type, bool swap, uint64_t* out) {
  double c = read_value(p, count_type, swap);
  if (!(c >= 0)) return false;
  *out = static_cast<uint64_t>(c);
  return true;
}

// Walks one binary row with lists starting at p; fills offsets of scalar properties (relative to
// p) and returns the row size, or 0 with *error set when the row runs past `end`.
size_t walk_row(const Element& e, const uint8_t* p, const uint8_t* end, bool swap, size_t* offsets,
                std::string* error) {
  size_t pos = 0;
  const size_t left = static_cast<size_t>(end - p);
  for (size_t k = 0; k < e.properties.size(); ++k) {
    const Property& prop = e.properties[k];
    if (!prop.is_list) {
      if (offsets) offsets[k] = pos;
      pos += type_size(prop.type);
      if (pos > left) break;
      continue;
    }
    const size_t cs = type_size(prop.count_type);
    if (pos + cs > left) {
      pos += cs;
      break;
    }
    uint64_t n = 0;
    if (!list_count(p + pos, prop.count_type, swap, &n)) {
      *error = "list property '" + prop.name + "': negative item count";
      return 0;
    }
    pos += cs;
    const size_t is = type_size(prop.type);
    if (n > (left - pos) / is) {
      pos = left + 1;
      break;
    }
    pos += static_cast<size_t>(n) * is;
  }
  if (pos > left) {
    *error = "row runs past the end of the file";
    return 0;
  }
  return pos;
}

}  // namespace

size_t type_size(Type t) {
  for (const TypeInfo& i : kTypes)
    if (i.type == t) return i.size;
  return 0;
}
const char* type_name(Type t) {
  for (const TypeInfo& i : kTypes)
    if (i.type == t) return i.name;
  return "?";
}
bool is_integer(Type t) {
  return t != Type::kFloat32 && t != Type::kFloat64;
}

bool Element::has_lists() const {
  for (const Property& p : properties)
    if (p.is_list) return true;
  return false;
}
size_t Element::scalar_row_bytes() const {
  size_t n = 0;
  for (const Property& p : properties) n += p.is_list ? 0 : type_size(p.type);
  return n;
}
int Element::find(std::string_view property) const {
  for (size_t i = 0; i < properties.size(); ++i)
    if (properties[i].name == property) return static_cast<int>(i);
  return -1;
}
const Element* Header::find(std::string_view element) const {
  int i = find_index(element);
  return i < 0 ? nullptr : &elements[static_cast<size_t>(i)];
}
int Header::find_index(std::string_view element) const {
  for (size_t i = 0; i < elements.size(); ++i)
    if (elements[i].name == element) return static_cast<int>(i);
  return -1;
}

bool looks_like_ply(const uint8_t* data, size_t size) {
  return size >= 4 && std::memcmp(data, "ply", 3) == 0 && (data[3] == '\n' || data[3] == '\r');
}

Result<Header> parse_header(const uint8_t* data, size_t size, const std::string& file) {
  if (size == 0) return Status::error(file + ": empty file");
  if (!looks_like_ply(data, size))
    return Status::error(file + ": not a PLY file (expected the first line 'ply')");
  const size_t limit = std::min(size, kMaxHeaderBytes);
  const char* text = reinterpret_cast<const char*>(data);
  Header h;
  bool have_format = false;
  size_t pos = 0;
  int line_no = 0;
  while (true) {
    const void* nl = std::memchr(text + pos, '\n', limit - pos);
    if (!nl) {
      return Status::error(file + ": PLY header has no 'end_header' line" +
                           (limit < size ? " in its first 16 MiB" : " (file truncated?)"));
    }
    size_t eol = static_cast<size_t>(static_cast<const char*>(nl) - text);
    std::string_view line(text + pos, eol - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = eol + 1;
    ++line_no;
    if (line_no == 1) continue;  // "ply"
    const std::string where = file + ": PLY header line " + std::to_string(line_no);
    auto words = split_words(line);
    if (words.empty()) continue;
    const std::string_view key = words[0];
    if (key == "end_header") {
      h.body_offset = pos;
      break;
    }
    if (key == "comment") {
      size_t at = line.find("comment") + 7;
      while (at < line.size() && (line[at] == ' ' || line[at] == '\t')) ++at;
      h.comments.emplace_back(line.substr(std::min(at, line.size())));
      continue;
    }
    if (key == "obj_info") continue;
    if (key == "format") {
      if (words.size() < 2) return Status::error(where + ": 'format' without a value");
      if (words[1] == "ascii")
        h.encoding = Encoding::kAscii;
      else if (words[1] == "binary_little_endian")
        h.encoding = Encoding::kBinaryLittleEndian;
      else if (words[1] == "binary_big_endian")
        h.encoding = Encoding::kBinaryBigEndian;
      else
        return Status::error(where +
                             ": format: expected ascii, binary_little_endian or "
                             "binary_big_endian, found '" +
                             std::string(words[1]) + "'");
      have_format = true;
      continue;
    }
    if (key == "element") {
      if (words.size() != 3)
        return Status::error(where + ": expected 'element NAME COUNT', found '" +
                             std::string(line) + "'");
      Element e;
      e.name = std::string(words[1]);
      auto [ptr, ec] = std::from_chars(words[2].data(), words[2].data() + words[2].size(), e.count);
      if (ec != std::errc() || ptr != words[2].data() + words[2].size())
        return Status::error(where + ": element '" + e.name +
                             "': expected a non-negative integer count, found '" +
                             std::string(words[2]) + "'");
      h.elements.push_back(std::move(e));
      continue;
    }
    if (key == "property") {
      if (h.elements.empty()) return Status::error(where + ": property before any element");
      Element& e = h.elements.back();
      Property p;
      if (words.size() == 5 && words[1] == "list") {
        p.is_list = true;
        if (!parse_type(words[2], &p.count_type) || !is_integer(p.count_type))
          return Status::error(where + ": list count type: expected an integer type, found '" +
                               std::string(words[2]) + "'");
        if (!parse_type(words[3], &p.type))
          return Status::error(where + ": list item type: unknown type '" + std::string(words[3]) +
                               "'");
        p.name = std::string(words[4]);
      } else if (words.size() == 3) {
        if (!parse_type(words[1], &p.type))
          return Status::error(where + ": property '" + std::string(words[2]) +
                               "': unknown type '" + std::string(words[1]) + "'");
        p.name = std::string(words[2]);
      } else {
        return Status::error(where +
                             ": expected 'property TYPE NAME' or 'property list "
                             "COUNT_TYPE ITEM_TYPE NAME', found '" +
                             std::string(line) + "'");
      }
      e.properties.push_back(std::move(p));
      continue;
    }
    return Status::error(where + ": unknown header keyword '" + std::string(key) + "'");
  }
  if (!have_format) return Status::error(file + ": PLY header has no 'format' line");
  return h;
}

Result<std::vector<ElementRows>> locate_elements(const Header& header, const uint8_t* data,
                                                 size_t size, const std::string& file) {
  std::vector<ElementRows> out;
  out.reserve(header.elements.size());
  size_t cursor = header.body_offset;
  const bool ascii = header.encoding == Encoding::kAscii;
  const bool swap = header.encoding == Encoding::kBinaryBigEndian;

  // ASCII: a token cursor over the whole body.
  const char* text = reinterpret_cast<const char*>(data);
  auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; };
  auto next_token = [&](std::string_view* tok) {
    while (cursor < size && is_space(text[cursor])) ++cursor;
    if (cursor >= size) return false;
    size_t b = cursor;
    while (cursor < size && !is_space(text[cursor])) ++cursor;
    *tok = std::string_view(text + b, cursor - b);
    return true;
  };

  for (const Element& e : header.elements) {
    ElementRows rows;
    rows.file = file;
    rows.element = &e;
    rows.count = e.count;
    const size_t np = e.properties.size();
    rows.stored_type.resize(np);
    rows.stored_offset.assign(np, 0);
    const size_t left = cursor <= size ? size - cursor : 0;
    const std::string label = file + ": " + element_label(e);

    if (ascii) {
      // Each value needs at least one character and one separator.
      size_t scalars = 0;
      for (size_t k = 0; k < np; ++k) {
        rows.stored_type[k] = Type::kFloat64;
        if (!e.properties[k].is_list) rows.stored_offset[k] = 8 * scalars++;
      }
      if (np > 0 && e.count > (left / 2 + 1) / np)
        return Status::error(label + ": " + std::to_string(e.count) + " rows of " +
                             std::to_string(np) + " values cannot fit in the " +
                             std::to_string(left) + " bytes left in the file (truncated?)");
      rows.stride = 8 * scalars;
      rows.table.resize(static_cast<size_t>(e.count) * scalars);
      double* dst = rows.table.data();
      // An element without properties has empty rows: nothing to read, however large its count.
      for (uint64_t r = 0; np > 0 && r < e.count; ++r) {
        for (size_t k = 0; k < np; ++k) {
          const Property& p = e.properties[k];
          std::string_view tok;
          auto fail_end = [&] {
            return Status::error(label + ": the file ends at row " + std::to_string(r) + " of " +
                                 std::to_string(e.count) + ", property '" + p.name +
                                 "' (truncated?)");
          };
          if (!next_token(&tok)) return fail_end();
          double v = 0;
          auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
          if (ec == std::errc::result_out_of_range && ptr == tok.data() + tok.size()) {
            // "1e999" is infinite, "1e-999" zero: values for the NaN/Inf policy, not bad syntax.
            v = std::strtod(std::string(tok).c_str(), nullptr);
            ec = std::errc();
          }
          if (ec != std::errc() || ptr != tok.data() + tok.size())
            return Status::error(label + ": row " + std::to_string(r) + ", property '" + p.name +
                                 "': expected a number, found '" + std::string(tok.substr(0, 32)) +
                                 "'");
          if (!p.is_list) {
            *dst++ = v;
            continue;
          }
          if (!(v >= 0) || v != static_cast<double>(static_cast<uint64_t>(v)))
            return Status::error(label + ": row " + std::to_string(r) + ", list '" + p.name +
                                 "': expected a non-negative integer item count, found '" +
                                 std::string(tok) + "'");
          for (uint64_t j = 0, n = static_cast<uint64_t>(v); j < n; ++j)
            if (!next_token(&tok)) return fail_end();
        }
      }
      rows.begin = reinterpret_cast<const uint8_t*>(rows.table.data());
      rows.end = rows.begin + rows.table.size() * sizeof(double);
      out.push_back(std::move(rows));
      continue;
    }

    rows.swap_bytes = swap;
    size_t offset = 0;
    for (size_t k = 0; k < np; ++k) {
      rows.stored_type[k] = e.properties[k].type;
      rows.stored_offset[k] = offset;
      if (!e.properties[k].is_list) offset += type_size(e.properties[k].type);
    }
    rows.begin = data + std::min(cursor, size);
    if (!e.has_lists()) {
      rows.stride = e.scalar_row_bytes();
      if (rows.stride > 0 && e.count > left / rows.stride)
        return Status::error(label + ": " + std::to_string(e.count) + " rows of " +
                             std::to_string(rows.stride) + " bytes need " +
                             (e.count > std::numeric_limits<uint64_t>::max() / rows.stride
                                  ? std::string("more than 2^64")
                                  : std::to_string(e.count * rows.stride)) +
                             " bytes, only " + std::to_string(left) +
                             " are left in the file (truncated?)");
      cursor += static_cast<size_t>(e.count) * rows.stride;
      rows.end = data + cursor;
      out.push_back(std::move(rows));
      continue;
    }
    // Rows with lists: at least the scalars and each list's count per row, then walk.
    rows.variable_rows = true;
    size_t min_row = 0;
    for (const Property& p : e.properties) min_row += type_size(p.is_list ? p.count_type : p.type);
    if (e.count > left / min_row)
      return Status::error(label + ": " + std::to_string(e.count) + " rows of at least " +
                           std::to_string(min_row) + " bytes cannot fit in the " +
                           std::to_string(left) + " bytes left in the file (truncated?)");
    const uint8_t* p = rows.begin;
    const uint8_t* end = data + size;
    for (uint64_t r = 0; r < e.count; ++r) {
      std::string error;
      size_t bytes = walk_row(e, p, end, swap, nullptr, &error);
      if (bytes == 0 && !error.empty())
        return Status::error(label + ": row " + std::to_string(r) + " of " +
                             std::to_string(e.count) + ": " + error + " (truncated?)");
      p += bytes;
    }
    rows.end = p;
    cursor = static_cast<size_t>(p - data);
    out.push_back(std::move(rows));
  }
  return out;
}

Status ElementRows::for_each_block(const std::vector<int>& columns, const BlockFn& fn) const {
  const size_t nc = columns.size();
  for (int c : columns) {
    MACRO_CHECK(c >= 0 && static_cast<size_t>(c) < element->properties.size());
    MACRO_CHECK(!element->properties[static_cast<size_t>(c)].is_list);
  }
  std::vector<float> buffer(nc * kBlockRows);
  std::vector<const float*> cols(nc);
  for (size_t c = 0; c < nc; ++c) cols[c] = buffer.data() + c * kBlockRows;
  std::vector<size_t> offsets(element->properties.size());
  const uint8_t* walker = begin;
  for (uint64_t first = 0; first < count; first += kBlockRows) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(kBlockRows, count - first));
    if (!variable_rows) {
      const uint8_t* base = begin + static_cast<size_t>(first) * stride;
      for (size_t c = 0; c < nc; ++c) {
        const size_t k = static_cast<size_t>(columns[c]);
        float* out = buffer.data() + c * kBlockRows;
        if (swap_bytes)
          gather_any<true>(stored_type[k], base + stored_offset[k], stride, n, out);
        else
          gather_any<false>(stored_type[k], base + stored_offset[k], stride, n, out);
      }
    } else {
      for (size_t r = 0; r < n; ++r) {
        std::string error;
        size_t bytes = walk_row(*element, walker, end, swap_bytes, offsets.data(), &error);
        if (bytes == 0 && !error.empty())
          return Status::error(file + ": element '" + element->name + "': row " +
                               std::to_string(first + r) + ": " + error);
        for (size_t c = 0; c < nc; ++c) {
          const size_t k = static_cast<size_t>(columns[c]);
          buffer[c * kBlockRows + r] =
              static_cast<float>(read_value(walker + offsets[k], stored_type[k], swap_bytes));
        }
        walker += bytes;
      }
    }
    fn(static_cast<size_t>(first), n, cols.data());
  }
  return Status::ok();
}

double ElementRows::value(size_t row, int property) const {
  MACRO_CHECK(!variable_rows && row < count && property >= 0);
  const size_t k = static_cast<size_t>(property);
  MACRO_CHECK(!element->properties[k].is_list);
  return read_value(begin + row * stride + stored_offset[k], stored_type[k], swap_bytes);
}

Result<int> find_scalar(const Element& element, std::string_view name, const std::string& file) {
  int i = element.find(name);
  if (i < 0) return -1;
  const Property& p = element.properties[static_cast<size_t>(i)];
  if (p.is_list)
    return Status::error(file + ": element '" + element.name + "', property '" + p.name +
                         "': expected a scalar number (float, double, uchar, int, ...), found a "
                         "list");
  return i;
}

}  // namespace macro::gs::ply
