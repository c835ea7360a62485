// Zip archives written in memory: stored (uncompressed) records, as .sog files hold their WebP
// images (already compressed). The layout is the plain one every reader takes: for each member a
// local header (version 2.0, no flags, method 0, a fixed 1980-01-01 timestamp so that the same
// members give the same bytes), its bytes, then the central directory and its end record. No
// zip64: an archive of 4 GiB or more, more than 65535 members, a name longer than 65535 bytes, an
// empty or duplicated name is an error naming the archive.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro {

struct ZipMember {
  std::string name;
  std::vector<uint8_t> bytes;
};

// The archive's bytes, members in the given order. `file` names the archive in messages.
Result<std::vector<uint8_t>> write_zip_stored(const std::vector<ZipMember>& members,
                                              const std::string& file);

}  // namespace macro
