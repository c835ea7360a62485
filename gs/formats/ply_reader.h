// A generic PLY reader: the header (format, elements, typed properties, list properties, comments)
// and the rows of each element, for any scene format stored as PLY (Inria .ply, SuperSplat
// compressed.ply). It knows nothing about Gaussians.
//
// What it does:
//   - parse_header() reads "ply" ... "end_header" and checks every line (unknown types, a property
//     before any element, counts that do not parse, a missing end_header are errors naming the file
//     and the line).
//   - locate_elements() finds where each element's rows lie in the body, in file order, and checks
//     count * row size against the bytes that are left BEFORE anything is allocated. Elements with
//     list properties are walked row by row (bounded by the file size) so that the elements after
//     them can be found. ASCII bodies are converted once into a native table of doubles (scalar
//     properties only, lists skipped), so every later read is binary.
//   - ElementRows::for_each_block() hands the caller blocks of up to kBlockRows rows as float
//     columns [C][rows]. The type/endianness switch happens once per column per block; the inner
//     loops are typed gathers with no per-value dispatch.
// What it does not: write PLY (the writers format their own fixed header), or keep list values.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::gs::ply {

enum class Type : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };
enum class Encoding : uint8_t { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

size_t type_size(Type t);
const char* type_name(
    Type t);  // the canonical PLY spelling: char uchar short ushort int uint float double
bool is_integer(Type t);

struct Property {
  std::string name;
  Type type = Type::kFloat32;  // scalar type, or the item type of a list
  bool is_list = false;
  Type count_type = Type::kUint8;  // lists only: type of the leading item count
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Property> properties;
  bool has_lists() const;
  size_t scalar_row_bytes() const;            // bytes of one binary row if it has no lists
  int find(std::string_view property) const;  // index in properties, or -1
};

struct Header {
  Encoding encoding = Encoding::kBinaryLittleEndian;
  std::vector<Element> elements;
  std::vector<std::string> comments;  // "comment ..." lines, text after "comment "
  size_t body_offset = 0;             // first byte after the end_header line
  const Element* find(std::string_view element) const;
  int find_index(std::string_view element) const;
};

// True when the bytes start like a PLY file ("ply" and a line end).
bool looks_like_ply(const uint8_t* data, size_t size);

Result<Header> parse_header(const uint8_t* data, size_t size, const std::string& file);

// One element's rows. Binary rows point into the caller's file buffer (which must outlive this);
// ASCII rows live in `table` (native doubles), so the object is move-only (begin points into it).
struct ElementRows {
  ElementRows() = default;
  ElementRows(ElementRows&&) = default;
  ElementRows& operator=(ElementRows&&) = default;
  ElementRows(const ElementRows&) = delete;
  ElementRows& operator=(const ElementRows&) = delete;

  std::string file;  // for messages
  const Element* element = nullptr;
  uint64_t count = 0;
  // Storage layout of each property in a row (index = property index). For lists the offset is
  // meaningless; they cannot be read as columns.
  std::vector<Type> stored_type;
  std::vector<size_t> stored_offset;
  bool swap_bytes = false;         // big-endian body on this little-endian host
  bool variable_rows = false;      // binary rows with lists: walked row by row
  const uint8_t* begin = nullptr;  // first byte of the first row
  const uint8_t* end = nullptr;    // one past the last byte of the last row
  size_t stride = 0;               // bytes per row when !variable_rows
  std::vector<double> table;       // ASCII only: [count][scalar properties], begin points into it

  static constexpr size_t kBlockRows = 1024;

  // Calls fn(first_row, rows, cols) for consecutive blocks; cols[c] holds `rows` floats of the
  // property columns[c]. Every column must be a scalar property index of this element.
  using BlockFn = std::function<void(size_t first_row, size_t rows, const float* const* cols)>;
  Status for_each_block(const std::vector<int>& columns, const BlockFn& fn) const;

  // One value, any type, exactly (doubles hold every PLY integer). Fixed-size rows only.
  double value(size_t row, int property) const;
};

// Where every element's rows are, in header order. Counts are checked against the file size before
// any allocation; an element larger than the rest of the file is an error naming the element, its
// count, its row size and the bytes left.
Result<std::vector<ElementRows>> locate_elements(const Header& header, const uint8_t* data,
                                                 size_t size, const std::string& file);

// The property `name` of `element` as a column index: -1 when absent; an error (naming the file,
// the property, what was expected and found) when it is a list.
Result<int> find_scalar(const Element& element, std::string_view name, const std::string& file);

}  // namespace macro::gs::ply
