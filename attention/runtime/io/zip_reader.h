// Read-only zip archives held in memory (a mapped file): the directory and the records' contents.
//
// read_zip_directory() finds the end-of-central-directory record (the zip64 locator and end record
// when present), walks the central directory (zip64 extra fields for sizes and offsets) and checks
// each entry against its local header. Every offset and size is bounds-checked: the directory lies
// before its end record, each record's data lies before the directory, the local header names the
// same record, stored records have equal sizes, names are unique. Encrypted entries, methods other
// than stored (0) and deflate (8) and multi-disk archives are errors naming the file and record.
// Nothing is allocated from a claimed size except the entry list, bounded by the directory's bytes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro {

struct ZipEntry {
  std::string name;
  uint16_t method = 0;  // 0 stored, 8 deflated
  uint32_t crc = 0;     // CRC-32 of the uncompressed content, from the central directory
  uint64_t comp_size = 0, size = 0;
  uint64_t data_offset = 0;  // of the (compressed) content, from the start of the archive
};

// Deflate cannot expand data by more than about 1032:1.
constexpr uint64_t kMaxDeflateRatio = 1032;

// The entries in directory order. file names the archive in messages.
Result<std::vector<ZipEntry>> read_zip_directory(const uint8_t* base, uint64_t size,
                                                 const std::string& file);

// Checks that a deflated entry's size is one its compressed bytes can produce (call before
// allocating e.size bytes for it).
Status check_inflated_size(const ZipEntry& e, const std::string& file);

// Inflates a deflated entry (raw deflate, method 8) into dst, exactly e.size bytes, and checks the
// CRC-32. The stream must end exactly there.
Status inflate_zip_record(const uint8_t* base, const ZipEntry& e, uint8_t* dst,
                          const std::string& file);

// A name read from a file (a record, a pickle global or key) made printable for messages: bytes
// outside printable ASCII become \xNN, and more than `max` bytes end in "...".
std::string printable_name(const std::string& s, size_t max = 120);

// CRC-32 (zip's) of n bytes.
uint32_t zip_crc32(const uint8_t* data, uint64_t n);

// Little-endian reads (unaligned).
inline uint16_t le16(const uint8_t* p) { return uint16_t(p[0] | p[1] << 8); }
inline uint32_t le32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
inline uint64_t le64(const uint8_t* p) { return uint64_t(le32(p)) | uint64_t(le32(p + 4)) << 32; }

constexpr uint32_t kZipLocalHeaderSig = 0x04034b50;  // "PK\3\4", the first bytes of a zip file

}  // namespace macro
