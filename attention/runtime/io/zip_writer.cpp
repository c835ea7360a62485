// Stored-record zip writer (see zip_writer.h).
#include "attention/runtime/io/zip_writer.h"

#include <set>

#include "attention/runtime/io/zip_reader.h"

namespace macro {
namespace {

void put16(std::vector<uint8_t>& out, uint32_t v) {
  out.push_back(uint8_t(v));
  out.push_back(uint8_t(v >> 8));
}
void put32(std::vector<uint8_t>& out, uint32_t v) {
  put16(out, v & 0xffff);
  put16(out, v >> 16);
}

constexpr uint32_t kCentralSig = 0x02014b50, kEndSig = 0x06054b50;
constexpr uint16_t kVersion = 20;  // 2.0: the plainest archive readers accept
constexpr uint16_t kDosTime = 0, kDosDate = (0 << 9) | (1 << 5) | 1;  // 1980-01-01 00:00

// The fields a local header and a central entry share, from "version needed" to the name length.
void put_common(std::vector<uint8_t>& out, uint32_t crc, uint32_t size, size_t name_len) {
  put16(out, kVersion);  // version needed to extract
  put16(out, 0);         // flags
  put16(out, 0);         // method: stored
  put16(out, kDosTime);
  put16(out, kDosDate);
  put32(out, crc);
  put32(out, size);  // compressed size
  put32(out, size);  // uncompressed size
  put16(out, uint32_t(name_len));
  put16(out, 0);  // extra field length
}

}  // namespace

Result<std::vector<uint8_t>> write_zip_stored(const std::vector<ZipMember>& members,
                                              const std::string& file) {
  if (members.size() > 0xffff)
    return Status::error(file + ": " + std::to_string(members.size()) +
                         " zip members, more than the 65535 an archive without zip64 holds");
  uint64_t total = 22;
  std::set<std::string> names;
  for (const ZipMember& m : members) {
    if (m.name.empty()) return Status::error(file + ": a zip member with an empty name");
    if (m.name.size() > 0xffff)
      return Status::error(file + ": zip member name of " + std::to_string(m.name.size()) +
                           " bytes, more than 65535");
    if (!names.insert(m.name).second)
      return Status::error(file + ": zip member '" + printable_name(m.name) + "' given twice");
    total += 30 + 46 + 2 * uint64_t(m.name.size()) + m.bytes.size();
  }
  if (total >= 0xffffffffull)
    return Status::error(file + ": a zip archive of " + std::to_string(total) +
                         " bytes, at least the 4 GiB an archive without zip64 holds");
  std::vector<uint8_t> out;
  out.reserve(static_cast<size_t>(total));
  std::vector<uint32_t> offsets, crcs;
  for (const ZipMember& m : members) {
    offsets.push_back(uint32_t(out.size()));
    crcs.push_back(zip_crc32(m.bytes.data(), m.bytes.size()));
    put32(out, kZipLocalHeaderSig);
    put_common(out, crcs.back(), uint32_t(m.bytes.size()), m.name.size());
    out.insert(out.end(), m.name.begin(), m.name.end());
    out.insert(out.end(), m.bytes.begin(), m.bytes.end());
  }
  const uint32_t dir_offset = uint32_t(out.size());
  for (size_t i = 0; i < members.size(); ++i) {
    const ZipMember& m = members[i];
    put32(out, kCentralSig);
    put16(out, kVersion);  // version made by (MS-DOS attributes, 2.0)
    put_common(out, crcs[i], uint32_t(m.bytes.size()), m.name.size());
    put16(out, 0);  // comment length
    put16(out, 0);  // disk number start
    put16(out, 0);  // internal attributes
    put32(out, 0);  // external attributes
    put32(out, offsets[i]);
    out.insert(out.end(), m.name.begin(), m.name.end());
  }
  const uint32_t dir_size = uint32_t(out.size()) - dir_offset;
  put32(out, kEndSig);
  put16(out, 0);  // this disk
  put16(out, 0);  // disk with the directory
  put16(out, uint32_t(members.size()));
  put16(out, uint32_t(members.size()));
  put32(out, dir_size);
  put32(out, dir_offset);
  put16(out, 0);  // comment length
  return out;
}

}  // namespace macro
