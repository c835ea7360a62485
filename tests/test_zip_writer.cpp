// The stored-record zip writer (attention/runtime/io/zip_writer.h): our reader reads its archives
// back member for member, the bytes are the same for the same members, bad member lists are
// refused, and unzip or python3's zipfile (when installed) accept the archive.
#include <catch2/catch.hpp>
#include <cstdio>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "attention/runtime/io/zip_reader.h"
#include "attention/runtime/io/zip_writer.h"
#include "test_support.h"

using namespace macro;

namespace {

std::vector<ZipMember> sample_members() {
  std::mt19937 rng(3);
  std::vector<ZipMember> m = {{"meta.json", {'{', '}'}}, {"empty.bin", {}}, {"big.bin", {}}};
  m[2].bytes.resize(70000);
  for (uint8_t& b : m[2].bytes) b = uint8_t(rng());
  return m;
}

}  // namespace

TEST_CASE("zip writer: our reader reads the members back", "[zip]") {
  const std::vector<ZipMember> members = sample_members();
  auto z = write_zip_stored(members, "t.zip");
  REQUIRE(z.is_ok());
  auto entries = read_zip_directory(z->data(), z->size(), "t.zip");
  INFO(entries.status().message());
  REQUIRE(entries.is_ok());
  REQUIRE(entries->size() == members.size());
  for (size_t i = 0; i < members.size(); ++i) {
    const ZipEntry& e = (*entries)[i];
    CHECK(e.name == members[i].name);
    CHECK(e.method == 0);
    REQUIRE(e.size == members[i].bytes.size());
    CHECK(e.crc == zip_crc32(members[i].bytes.data(), members[i].bytes.size()));
    CHECK(std::equal(members[i].bytes.begin(), members[i].bytes.end(),
                     z->begin() + ptrdiff_t(e.data_offset)));
  }
  // Deterministic: the same members give the same bytes.
  auto again = write_zip_stored(members, "t.zip");
  REQUIRE(again.is_ok());
  CHECK(*again == *z);
  // No members: a valid empty archive.
  auto empty = write_zip_stored({}, "e.zip");
  REQUIRE(empty.is_ok());
  CHECK(empty->size() == 22);
  auto none = read_zip_directory(empty->data(), empty->size(), "e.zip");
  REQUIRE(none.is_ok());
  CHECK(none->empty());
}

TEST_CASE("zip writer: bad member lists are refused naming the archive", "[zip]") {
  auto dup = write_zip_stored({{"a", {1}}, {"a", {2}}}, "dup.zip");
  REQUIRE_FALSE(dup.is_ok());
  CHECK(dup.status().message().find("dup.zip") != std::string::npos);
  CHECK(dup.status().message().find("'a' given twice") != std::string::npos);
  auto unnamed = write_zip_stored({{"", {1}}}, "unnamed.zip");
  REQUIRE_FALSE(unnamed.is_ok());
  CHECK(unnamed.status().message().find("empty name") != std::string::npos);
  auto long_name = write_zip_stored({{std::string(70000, 'x'), {}}}, "long.zip");
  REQUIRE_FALSE(long_name.is_ok());
  CHECK(long_name.status().message().find("more than 65535") != std::string::npos);
}

TEST_CASE("zip writer: unzip and python3's zipfile accept the archive", "[zip]") {
  test::TempDir dir("zipw");
  auto z = write_zip_stored(sample_members(), "t.zip");
  REQUIRE(z.is_ok());
  const std::string path = dir.file("t.zip");
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(z->data()), std::streamsize(z->size()));
  bool checked = false;
  if (test::run_command("command -v unzip >/dev/null 2>&1") == 0) {
    CHECK(test::run_command("unzip -tq '" + path + "' >/dev/null 2>&1") == 0);
    checked = true;
  } else {
    WARN("SKIP: unzip not installed");
  }
  if (test::run_command("command -v python3 >/dev/null 2>&1") == 0) {
    const std::string py =
        "import sys, zipfile\n"
        "z = zipfile.ZipFile(sys.argv[1])\n"
        "assert z.testzip() is None\n"
        "assert z.namelist() == ['meta.json', 'empty.bin', 'big.bin'], z.namelist()\n"
        "assert z.read('meta.json') == b'{}' and len(z.read('big.bin')) == 70000\n";
    std::ofstream(dir.file("check.py")) << py;
    CHECK(test::run_command("python3 '" + dir.file("check.py") + "' '" + path + "'") == 0);
    checked = true;
  } else {
    WARN("SKIP: python3 not installed");
  }
  if (!checked) WARN("SKIP: neither unzip nor python3 is installed; only our reader checked it");
}
