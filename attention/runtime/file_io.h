// Reading user files with bounds, and writing outputs atomically.
//
// Every output goes through AtomicFile / write_file_atomic: the bytes are written to
// "<path>.tmp-<pid>" in the same folder, flushed, and renamed over <path>. A failure or an
// interrupt leaves no half-written file at <path> (and removes the temporary).
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include "attention/runtime/status.h"

namespace macro {

// Whole file into memory. Fails (naming the file) if it cannot be opened or is larger than max_bytes.
Result<std::vector<uint8_t>> read_file(const std::string& path, uint64_t max_bytes = 1ull << 34);
Result<std::string> read_text_file(const std::string& path, uint64_t max_bytes = 1ull << 30);
Result<uint64_t> file_size(const std::string& path);
bool file_exists(const std::string& path);
bool is_directory(const std::string& path);
// A file's size and modification time: what caches of loaded files compare to notice a replaced
// file. size -1 when the file cannot be stat'ed.
struct FileStamp {
  int64_t size = -1, mtime_ns = -1;
  bool operator==(const FileStamp& o) const { return size == o.size && mtime_ns == o.mtime_ns; }
};
FileStamp file_stamp(const std::string& path);

// Streamed atomic writer. write() calls accumulate; commit() renames into place. If the object is
// destroyed without commit() the temporary is removed.
class AtomicFile {
 public:
  AtomicFile() = default;
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  Status open(const std::string& path);
  Status write(const void* data, size_t bytes);
  Status write(std::string_view s) { return write(s.data(), s.size()); }
  Status commit();
  const std::string& temp_path() const { return temp_path_; }

 private:
  void discard();
  std::string path_;
  std::string temp_path_;
  std::FILE* file_ = nullptr;
};

Status write_file_atomic(const std::string& path, const void* data, size_t bytes);
inline Status write_file_atomic(const std::string& path, std::string_view s) {
  return write_file_atomic(path, s.data(), s.size());
}

// For writers that need a path (libraries that open the file themselves, e.g. OpenEXR): returns a
// temporary path next to `path`; call commit_temp_file() when the library closed it, or
// remove_temp_file() on failure.
std::string temp_path_for(const std::string& path);
Status commit_temp_file(const std::string& temp, const std::string& path);
void remove_temp_file(const std::string& temp);

// Temporaries still open are removed on SIGINT/SIGTERM (installed by the CLI).
void install_interrupt_cleanup();

}  // namespace macro
