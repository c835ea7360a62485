// Reading user files with bounds, and writing outputs atomically.
//
// Every output goes through AtomicFile / write_file_atomic (or temp_path_for + commit_temp_file for
// libraries that open the file themselves). What happens depends on what <path> is:
//   - a regular file, or no file yet: the bytes go to "<path>.tmp-<pid>-<n>" in the same folder,
//     are flushed, and renamed over <path>. A failure or an interrupt leaves no half-written file
//     at <path> (and removes the temporary).
//   - a symbolic link (or a chain of them): the same, at the file the link points to; the link is
//     kept. A dangling link creates the file it names.
//   - a character device or a FIFO (/dev/null, /dev/stdout, a named pipe): written in place,
//     streamed; the node is never replaced by a regular file. Errors (ENOSPC from /dev/full, EPIPE)
//     name the file. Such a write cannot be undone, so an error can leave bytes already written.
//   - a directory, a socket or a block device: refused, naming what was found.
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

// Where an output's bytes go (symlinks followed): a regular file (existing or new) replaced by
// rename, or a special file written in place.
struct OutputTarget {
  enum Kind { kRegular, kSpecial } kind = kRegular;
  std::string path;
};
Result<OutputTarget> resolve_output(const std::string& path);

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

// On SIGINT/SIGTERM (installed by the CLI): temporaries still open are removed and one line is
// printed on stderr ("interrupted: no output written", or that finished outputs were kept).
void install_interrupt_cleanup();

}  // namespace macro
