// Zip directory reader and record inflater (contract: zip_reader.h).
#include "attention/runtime/io/zip_reader.h"

#include <zlib.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <set>

namespace macro {

namespace {

constexpr uint32_t kLocalSig = kZipLocalHeaderSig, kCentralSig = 0x02014b50,
                   kEocdSig = 0x06054b50, kZip64EocdSig = 0x06064b50,
                   kZip64LocatorSig = 0x07064b50;

bool add_overflow(uint64_t a, uint64_t b, uint64_t* out) {
  return __builtin_add_overflow(a, b, out);
}

std::string num(uint64_t v) { return std::to_string(v); }

}  // namespace

std::string printable_name(const std::string& s, size_t max) {
  std::string out;
  for (size_t i = 0; i < s.size() && i < max; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
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

Result<std::vector<ZipEntry>> read_zip_directory(const uint8_t* base, uint64_t n,
                                                 const std::string& file) {
  const std::string where = file + ": zip";
  if (n < 22)
    return Status::error(where + ": file is " + num(n) +
                         " bytes, too short for an end-of-central-directory record (22)");
  // The end record is the last 22 bytes plus a comment of at most 65535 bytes.
  uint64_t eocd = UINT64_MAX;
  const uint64_t lowest = n - 22 > 65535 ? n - 22 - 65535 : 0;
  for (uint64_t p = n - 22 + 1; p-- > lowest;) {
    if (le32(base + p) == kEocdSig && p + 22 + le16(base + p + 20) <= n) {
      eocd = p;
      break;
    }
  }
  if (eocd == UINT64_MAX)
    return Status::error(where + ": no end-of-central-directory record (truncated or not a zip)");
  const uint8_t* e = base + eocd;
  uint64_t disk = le16(e + 4), cd_disk = le16(e + 6), count = le16(e + 10);
  uint64_t cd_size = le32(e + 12), cd_offset = le32(e + 16);
  uint64_t directory_end = eocd;  // the central directory must end before this
  if (eocd >= 20 && le32(e - 20) == kZip64LocatorSig) {
    const uint64_t z64 = le64(e - 20 + 8);
    if (z64 > eocd - 20 || eocd - 20 - z64 < 56 || le32(base + z64) != kZip64EocdSig)
      return Status::error(where + ": zip64 locator points to offset " + num(z64) +
                           ", where no zip64 end-of-central-directory record is");
    const uint8_t* z = base + z64;
    disk = le32(z + 16);
    cd_disk = le32(z + 20);
    count = le64(z + 32);
    cd_size = le64(z + 40);
    cd_offset = le64(z + 48);
    directory_end = z64;
  }
  if (disk != 0 || cd_disk != 0)
    return Status::error(where + ": multi-disk archives are not supported");
  uint64_t cd_end = 0;
  if (add_overflow(cd_offset, cd_size, &cd_end) || cd_end > directory_end)
    return Status::error(where + ": central directory [" + num(cd_offset) + ", +" + num(cd_size) +
                         ") runs past its end record at " + num(directory_end));
  if (count > cd_size / 46)
    return Status::error(where + ": " + num(count) + " entries cannot fit in a central directory of " +
                         num(cd_size) + " bytes");

  std::vector<ZipEntry> entries;
  entries.reserve(count);
  std::set<std::string> names;
  uint64_t p = cd_offset;
  for (uint64_t i = 0; i < count; ++i) {
    if (cd_end - p < 46 || le32(base + p) != kCentralSig)
      return Status::error(where + ": central directory entry " + num(i) + " at offset " + num(p) +
                           ": bad signature or truncated");
    const uint8_t* c = base + p;
    const uint16_t flags = le16(c + 8), method = le16(c + 10);
    const uint32_t crc = le32(c + 16);
    uint64_t comp = le32(c + 20), size = le32(c + 24);
    const uint64_t name_len = le16(c + 28), extra_len = le16(c + 30), comment_len = le16(c + 32);
    uint64_t local = le32(c + 42);
    const uint64_t entry_len = 46 + name_len + extra_len + comment_len;
    if (cd_end - p < entry_len)
      return Status::error(where + ": central directory entry " + num(i) + " runs past the directory");
    ZipEntry z;
    z.name.assign(reinterpret_cast<const char*>(c + 46), name_len);
    const std::string rec = where + ": record '" + printable_name(z.name) + "'";
    // zip64 extra field: the 64-bit values of the fields saturated at 0xFFFFFFFF, in this order.
    const uint8_t* x = c + 46 + name_len;
    const uint8_t* x_end = x + extra_len;
    while (x_end - x >= 4) {
      const uint16_t id = le16(x), len = le16(x + 2);
      if (size_t(x_end - x - 4) < len) return Status::error(rec + ": extra field runs past the entry");
      if (id == 0x0001) {
        const uint8_t* f = x + 4;
        const uint8_t* f_end = f + len;
        for (uint64_t* field : {&size, &comp, &local}) {
          if (*field != 0xFFFFFFFFu) continue;
          if (f_end - f < 8) return Status::error(rec + ": zip64 extra field too short");
          *field = le64(f);
          f += 8;
        }
      }
      x += 4 + len;
    }
    if (flags & 0x41) return Status::error(rec + ": encrypted records are not supported");
    if (method != 0 && method != 8)
      return Status::error(rec + ": compression method " + num(method) +
                           " is not supported (expected 0 stored or 8 deflate)");
    if (method == 0 && comp != size)
      return Status::error(rec + ": stored record with compressed size " + num(comp) +
                           " != size " + num(size));
    // The local header repeats the name; its extra field (torch's alignment padding) may differ.
    if (local > cd_offset || cd_offset - local < 30 || le32(base + local) != kLocalSig)
      return Status::error(rec + ": local header offset " + num(local) +
                           " does not point to a local header before the central directory");
    const uint8_t* l = base + local;
    const uint64_t l_name = le16(l + 26), l_extra = le16(l + 28);
    uint64_t data = local + 30 + l_name + l_extra, data_end = 0;
    if (l_name != name_len || cd_offset - local - 30 < l_name ||
        std::memcmp(l + 30, z.name.data(), name_len) != 0)
      return Status::error(rec + ": local header at " + num(local) +
                           " names a different record");
    if (data > cd_offset || add_overflow(data, comp, &data_end) || data_end > cd_offset)
      return Status::error(rec + ": data [" + num(data) + ", +" + num(comp) +
                           ") runs past the central directory at " + num(cd_offset));
    z.method = method;
    z.crc = crc;
    z.comp_size = comp;
    z.size = size;
    z.data_offset = data;
    if (!names.insert(z.name).second) return Status::error(rec + ": appears twice");
    entries.push_back(std::move(z));
    p += entry_len;
  }
  return entries;
}

uint32_t zip_crc32(const uint8_t* data, uint64_t n) {
  uLong crc = crc32(0, nullptr, 0);
  for (uint64_t done = 0; done < n;) {  // zlib counts in uInt
    const uInt chunk = uInt(std::min<uint64_t>(n - done, 1u << 30));
    crc = crc32(crc, data + done, chunk);
    done += chunk;
  }
  return uint32_t(crc);
}

Status check_inflated_size(const ZipEntry& e, const std::string& file) {
  uint64_t max_out = 0;
  if (__builtin_mul_overflow(e.comp_size, kMaxDeflateRatio, &max_out) || e.size > max_out + 1024)
    return Status::error(file + ": record '" + printable_name(e.name) + "': claims " + num(e.size) +
                         " bytes inflated from " + num(e.comp_size) +
                         " compressed, more than deflate can produce");
  return Status::ok();
}

Status inflate_zip_record(const uint8_t* base, const ZipEntry& e, uint8_t* out,
                          const std::string& file) {
  const std::string rec = file + ": record '" + printable_name(e.name) + "'";
  z_stream zs;
  std::memset(&zs, 0, sizeof zs);
  if (inflateInit2(&zs, -MAX_WBITS) != Z_OK) return Status::error(rec + ": zlib init failed");
  // zlib counts in uInt: feed and drain in chunks below 4 GiB.
  const uint8_t* in = base + e.data_offset;
  uint64_t in_left = e.comp_size, out_done = 0;
  int rc = Z_OK;
  while (rc == Z_OK) {
    if (zs.avail_in == 0 && in_left) {
      zs.next_in = const_cast<Bytef*>(in);
      zs.avail_in = uInt(std::min<uint64_t>(in_left, 1u << 30));
      in += zs.avail_in;
      in_left -= zs.avail_in;
    }
    if (zs.avail_out == 0) {
      const uint64_t chunk = std::min<uint64_t>(e.size - out_done, 1u << 30);
      if (chunk == 0) {  // output full: the stream must end here
        uint8_t probe;
        zs.next_out = &probe;
        zs.avail_out = 1;
        rc = inflate(&zs, Z_NO_FLUSH);
        if (rc == Z_STREAM_END && zs.avail_out == 1) break;
        rc = Z_DATA_ERROR;
        break;
      }
      zs.next_out = out + out_done;
      zs.avail_out = uInt(chunk);
      out_done += chunk;
    }
    rc = inflate(&zs, Z_NO_FLUSH);
    if (rc == Z_BUF_ERROR && zs.avail_in == 0 && in_left == 0) break;
  }
  const uint64_t produced = zs.total_out;
  inflateEnd(&zs);
  if (rc != Z_STREAM_END || produced != e.size)
    return Status::error(rec + ": deflate data is corrupt or does not inflate to the " +
                         num(e.size) + " bytes the directory claims");
  if (zip_crc32(out, e.size) != e.crc)
    return Status::error(rec + ": CRC-32 mismatch after inflating (corrupt file)");
  return Status::ok();
}

}  // namespace macro
