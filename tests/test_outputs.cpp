// Outputs that destroy nothing (attention/runtime/file_io.h): a FIFO or a character device is
// written in place and stays what it was, a symlink keeps pointing at its target (which gets the
// new bytes), a dangling link creates its target, /dev/full reports ENOSPC naming the file, and
// sockets and directories are refused. /dev/null is only ever written after asserting that it is
// a character device and that the writer takes the in-place path for it.
#include <catch2/catch.hpp>

#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "attention/runtime/file_io.h"
#include "gs/image_io.h"
#include "test_support.h"

using namespace macro;
namespace fs = std::filesystem;

namespace {

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

std::vector<std::string> names_in(const std::string& dir) {
  std::vector<std::string> v;
  for (const auto& e : fs::directory_iterator(dir)) v.push_back(e.path().filename().string());
  std::sort(v.begin(), v.end());
  return v;
}

bool is_char_device(const std::string& path, dev_t* rdev = nullptr) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || !S_ISCHR(st.st_mode)) return false;
  if (rdev) *rdev = st.st_rdev;
  return true;
}

// Reads a FIFO to its end on a thread (a FIFO's writer blocks until a reader opens it).
struct FifoReader {
  std::string bytes;
  std::thread thread;
  explicit FifoReader(const std::string& path) {
    thread = std::thread([this, path] { bytes = slurp(path); });
  }
  std::string join() {
    thread.join();
    return bytes;
  }
};

}  // namespace

TEST_CASE("outputs: a FIFO is written in place and stays a FIFO", "[outputs]") {
  test::TempDir tmp("out-fifo");
  const std::string fifo = tmp.file("pipe");
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  auto target = resolve_output(fifo);
  REQUIRE(target.is_ok());
  CHECK(target->kind == OutputTarget::kSpecial);

  std::string payload(200000, '\0');  // more than a pipe buffer: the reader must drain it
  for (size_t i = 0; i < payload.size(); ++i) payload[i] = char('a' + i % 26);
  {
    FifoReader reader(fifo);
    REQUIRE(write_file_atomic(fifo, payload).is_ok());
    CHECK(reader.join() == payload);
  }
  // The streamed writer in chunks, and a PNG (write_png -> write_file_atomic).
  {
    FifoReader reader(fifo);
    AtomicFile f;
    REQUIRE(f.open(fifo).is_ok());
    REQUIRE(f.write(std::string_view("first,")).is_ok());
    REQUIRE(f.write(std::string_view("second")).is_ok());
    REQUIRE(f.commit().is_ok());
    CHECK(reader.join() == "first,second");
  }
  {
    FifoReader reader(fifo);
    gs::Image img(4, 3, 3);
    REQUIRE(gs::write_png(fifo, img).is_ok());
    const std::string png = reader.join();
    REQUIRE(png.size() > 8);
    CHECK(png.substr(1, 3) == "PNG");
  }
  // An EXR goes through temp_path_for + commit_temp_file: the temporary is not beside the FIFO.
  {
    FifoReader reader(fifo);
    const std::vector<float> plane(6, 0.5f);
    REQUIRE(gs::write_exr(fifo, 3, 2, {{"Y", plane.data()}}).is_ok());
    const std::string exr = reader.join();
    REQUIRE(exr.size() > 4);
    CHECK(uint8_t(exr[0]) == 0x76);  // OpenEXR magic 76 2f 31 01
    CHECK(uint8_t(exr[1]) == 0x2f);
  }
  struct stat st {};
  REQUIRE(::lstat(fifo.c_str(), &st) == 0);
  CHECK(S_ISFIFO(st.st_mode));
  CHECK(names_in(tmp.path) == std::vector<std::string>{"pipe"});  // no temporary left
}

TEST_CASE("outputs: /dev/null takes the in-place path and stays a character device", "[outputs]") {
  dev_t before = 0, after = 0;
  REQUIRE(is_char_device("/dev/null", &before));
  auto target = resolve_output("/dev/null");
  REQUIRE(target.is_ok());
  REQUIRE(target->kind == OutputTarget::kSpecial);  // never the rename path
  REQUIRE(target->path == "/dev/null");
  CHECK(write_file_atomic("/dev/null", std::string("discarded")).is_ok());
  gs::Image img(2, 2, 3);
  REQUIRE(is_char_device("/dev/null"));
  CHECK(gs::write_png("/dev/null", img).is_ok());
  REQUIRE(is_char_device("/dev/null"));
  const std::vector<float> plane(4, 1.f);
  CHECK(gs::write_exr("/dev/null", 2, 2, {{"Y", plane.data()}}).is_ok());
  REQUIRE(is_char_device("/dev/null", &after));
  CHECK(after == before);
}

TEST_CASE("outputs: /dev/full reports the error naming the file", "[outputs]") {
  if (!is_char_device("/dev/full")) {
    WARN("no /dev/full on this machine; skipped");
    return;
  }
  REQUIRE(resolve_output("/dev/full")->kind == OutputTarget::kSpecial);
  const std::string big(1 << 16, 'x');
  const Status s = write_file_atomic("/dev/full", big);
  REQUIRE_FALSE(s.is_ok());
  CHECK_THAT(s.message(), Catch::StartsWith("/dev/full: "));
  CHECK_THAT(s.message(), Catch::Contains(std::strerror(ENOSPC)));
  const std::vector<float> plane(4, 1.f);
  const Status e = gs::write_exr("/dev/full", 2, 2, {{"Y", plane.data()}});
  REQUIRE_FALSE(e.is_ok());
  CHECK_THAT(e.message(), Catch::Contains("/dev/full"));
  CHECK(is_char_device("/dev/full"));
}

TEST_CASE("outputs: a symlink keeps pointing at its target, which gets the new bytes",
          "[outputs]") {
  test::TempDir tmp("out-link");
  fs::create_directories(tmp.file("real"));
  const std::string target = tmp.file("real/result.png");
  REQUIRE(write_file_atomic(target, std::string("old bytes")).is_ok());
  const std::string link = tmp.file("link.png"), link2 = tmp.file("link2.png");
  fs::create_symlink("real/result.png", link);  // relative, resolved from the link's folder
  fs::create_symlink("link.png", link2);        // a chain of two

  REQUIRE(write_file_atomic(link, std::string("new bytes")).is_ok());
  CHECK(fs::is_symlink(link));
  CHECK(fs::read_symlink(link) == "real/result.png");
  CHECK(slurp(target) == "new bytes");

  REQUIRE(write_file_atomic(link2, std::string("third")).is_ok());
  CHECK(fs::is_symlink(link2));
  CHECK(fs::is_symlink(link));
  CHECK(slurp(target) == "third");

  // EXR (temp_path_for + commit_temp_file) through the link.
  const std::vector<float> plane(6, 0.25f);
  REQUIRE(gs::write_exr(link, 3, 2, {{"Y", plane.data()}}).is_ok());
  CHECK(fs::is_symlink(link));
  auto exr = gs::read_exr(target);
  REQUIRE(exr.is_ok());
  CHECK(exr->width == 3);

  // A dangling link: its target is created, the link kept.
  const std::string dangling = tmp.file("dangling.png");
  fs::create_symlink("real/new.png", dangling);
  REQUIRE(write_file_atomic(dangling, std::string("fresh")).is_ok());
  CHECK(fs::is_symlink(dangling));
  CHECK(slurp(tmp.file("real/new.png")) == "fresh");
  // No temporaries left in either folder.
  CHECK(names_in(tmp.file("real")) == std::vector<std::string>{"new.png", "result.png"});
  CHECK(names_in(tmp.path) ==
        std::vector<std::string>{"dangling.png", "link.png", "link2.png", "real"});
}

TEST_CASE("outputs: a regular file is replaced whole, sockets, directories and loops are refused",
          "[outputs]") {
  test::TempDir tmp("out-refuse");
  const std::string file = tmp.file("a.txt");
  REQUIRE(write_file_atomic(file, std::string("one")).is_ok());
  REQUIRE(write_file_atomic(file, std::string("two")).is_ok());
  CHECK(slurp(file) == "two");
  CHECK(resolve_output(file)->kind == OutputTarget::kRegular);

  const Status dir = write_file_atomic(tmp.path, std::string("x"));
  REQUIRE_FALSE(dir.is_ok());
  CHECK_THAT(dir.message(), Catch::Contains("found a directory"));

  const std::string sock = tmp.file("s.sock");
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  REQUIRE(fd >= 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  REQUIRE(sock.size() < sizeof(addr.sun_path));
  std::memcpy(addr.sun_path, sock.c_str(), sock.size() + 1);
  REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
  const Status s = write_file_atomic(sock, std::string("x"));
  ::close(fd);
  REQUIRE_FALSE(s.is_ok());
  CHECK_THAT(s.message(), Catch::StartsWith(sock + ": "));
  CHECK_THAT(s.message(), Catch::Contains("socket"));
  struct stat st {};
  REQUIRE(::lstat(sock.c_str(), &st) == 0);
  CHECK(S_ISSOCK(st.st_mode));  // not replaced by a regular file

  fs::create_symlink("loop_b", tmp.file("loop_a"));
  fs::create_symlink("loop_a", tmp.file("loop_b"));
  const Status loop = write_file_atomic(tmp.file("loop_a"), std::string("x"));
  REQUIRE_FALSE(loop.is_ok());
  CHECK_THAT(loop.message(), Catch::Contains("symbolic links"));
}
