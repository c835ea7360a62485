// A small PLY writer for the scene-format tests, independent of the library's reader and writer:
// any element, property types, list properties, ascii / binary little / big endian bodies.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace macro::test {

struct TProp {
  std::string name;
  std::string type;             // PLY type name
  std::string list_count = "";  // non-empty: a list with this count type
};
struct TElement {
  std::string name;
  std::vector<TProp> props;
  // rows[r] holds the values in property order; a list contributes its count then its items.
  std::vector<std::vector<double>> rows;
};

inline size_t tsize(const std::string& t) {
  if (t == "char" || t == "uchar") return 1;
  if (t == "short" || t == "ushort") return 2;
  if (t == "double") return 8;
  return 4;
}
inline void put_binary(std::vector<uint8_t>& out, const std::string& t, double v, bool big_endian) {
  uint8_t b[8];
  size_t n = tsize(t);
  if (t == "char") {
    int8_t x = static_cast<int8_t>(v);
    std::memcpy(b, &x, 1);
  } else if (t == "uchar") {
    uint8_t x = static_cast<uint8_t>(v);
    std::memcpy(b, &x, 1);
  } else if (t == "short") {
    int16_t x = static_cast<int16_t>(v);
    std::memcpy(b, &x, 2);
  } else if (t == "ushort") {
    uint16_t x = static_cast<uint16_t>(v);
    std::memcpy(b, &x, 2);
  } else if (t == "int") {
    int32_t x = static_cast<int32_t>(v);
    std::memcpy(b, &x, 4);
  } else if (t == "uint") {
    uint32_t x = static_cast<uint32_t>(v);
    std::memcpy(b, &x, 4);
  } else if (t == "float") {
    float x = static_cast<float>(v);
    std::memcpy(b, &x, 4);
  } else {
    std::memcpy(b, &v, 8);
  }
  if (big_endian) std::reverse(b, b + n);
  out.insert(out.end(), b, b + n);
}

inline std::vector<uint8_t> make_ply(const std::string& format,
                                     const std::vector<TElement>& elements,
                                     const std::vector<std::string>& comments = {}) {
  std::string h = "ply\nformat " + format + " 1.0\n";
  for (const auto& c : comments) h += "comment " + c + "\n";
  for (const auto& e : elements) {
    h += "element " + e.name + " " + std::to_string(e.rows.size()) + "\n";
    for (const auto& p : e.props)
      h += p.list_count.empty()
               ? "property " + p.type + " " + p.name + "\n"
               : "property list " + p.list_count + " " + p.type + " " + p.name + "\n";
  }
  h += "end_header\n";
  std::vector<uint8_t> out(h.begin(), h.end());
  const bool ascii = format == "ascii", be = format == "binary_big_endian";
  for (const auto& e : elements) {
    for (const auto& row : e.rows) {
      size_t at = 0;
      std::string line;
      for (const auto& p : e.props) {
        size_t items = 1;
        if (!p.list_count.empty()) {
          items = static_cast<size_t>(row[at]);
          if (ascii)
            line += std::to_string(items) + " ";
          else
            put_binary(out, p.list_count, row[at], be);
          ++at;
        }
        for (size_t j = 0; j < items; ++j, ++at) {
          if (ascii) {
            char buf[64];
            std::snprintf(buf, sizeof(buf), "%.17g ", row[at]);
            line += buf;
          } else {
            put_binary(out, p.type, row[at], be);
          }
        }
      }
      if (ascii) {
        line += "\n";
        out.insert(out.end(), line.begin(), line.end());
      }
    }
  }
  return out;
}

}  // namespace macro::test
