#include "attention/runtime/file_io.h"

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <mutex>
#include <set>

namespace macro {
namespace {

std::mutex& temp_mutex() {
  static std::mutex m;
  return m;
}
std::set<std::string>& live_temps() {
  static std::set<std::string> s;
  return s;
}
void register_temp(const std::string& p) {
  std::lock_guard<std::mutex> lock(temp_mutex());
  live_temps().insert(p);
}
void unregister_temp(const std::string& p) {
  std::lock_guard<std::mutex> lock(temp_mutex());
  live_temps().erase(p);
}

// Signal handler: best effort removal of live temporaries, then default action.
void on_signal(int sig) {
  // std::set iteration is not async-signal-safe in theory; we only unlink (which is) and then die.
  for (const auto& p : live_temps()) ::unlink(p.c_str());
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

std::string errno_text() { return std::strerror(errno); }

}  // namespace

Result<uint64_t> file_size(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) return Status::error(path + ": cannot stat: " + errno_text());
  if (S_ISDIR(st.st_mode)) return Status::error(path + ": expected a file, found a directory");
  return static_cast<uint64_t>(st.st_size);
}

bool file_exists(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 && !S_ISDIR(st.st_mode);
}

FileStamp file_stamp(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return {};
  return {int64_t(st.st_size),
          int64_t(st.st_mtim.tv_sec) * 1000000000 + int64_t(st.st_mtim.tv_nsec)};
}

bool is_directory(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

Result<std::vector<uint8_t>> read_file(const std::string& path, uint64_t max_bytes) {
  MACRO_ASSIGN_OR_RETURN(uint64_t size, file_size(path));
  if (size > max_bytes) {
    return Status::error(path + ": file is " + std::to_string(size) + " bytes, limit is " +
                         std::to_string(max_bytes));
  }
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return Status::error(path + ": cannot open: " + errno_text());
  std::vector<uint8_t> data(size);
  size_t got = size ? std::fread(data.data(), 1, size, f) : 0;
  std::fclose(f);
  if (got != size) return Status::error(path + ": short read (" + std::to_string(got) + " of " +
                                        std::to_string(size) + " bytes)");
  return data;
}

Result<std::string> read_text_file(const std::string& path, uint64_t max_bytes) {
  MACRO_ASSIGN_OR_RETURN(auto bytes, read_file(path, max_bytes));
  return std::string(bytes.begin(), bytes.end());
}

std::string temp_path_for(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  std::string temp = path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  register_temp(temp);  // removed on SIGINT/SIGTERM until committed or removed
  return temp;
}

Status commit_temp_file(const std::string& temp, const std::string& path) {
  if (std::rename(temp.c_str(), path.c_str()) != 0) {
    Status s = Status::error(path + ": cannot rename the temporary into place: " + errno_text());
    remove_temp_file(temp);
    return s;
  }
  unregister_temp(temp);
  return Status::ok();
}

void remove_temp_file(const std::string& temp) {
  ::unlink(temp.c_str());
  unregister_temp(temp);
}

AtomicFile::~AtomicFile() { discard(); }

void AtomicFile::discard() {
  if (file_) {
    std::fclose(file_);
    file_ = nullptr;
  }
  if (!temp_path_.empty()) {
    remove_temp_file(temp_path_);
    temp_path_.clear();
  }
}

Status AtomicFile::open(const std::string& path) {
  discard();
  path_ = path;
  temp_path_ = temp_path_for(path);
  file_ = std::fopen(temp_path_.c_str(), "wb");
  if (!file_) {
    Status s = Status::error(path + ": cannot create output: " + errno_text());
    unregister_temp(temp_path_);
    temp_path_.clear();
    return s;
  }
  return Status::ok();
}

Status AtomicFile::write(const void* data, size_t bytes) {
  if (!file_) return Status::error(path_ + ": write to a file that is not open");
  if (bytes && std::fwrite(data, 1, bytes, file_) != bytes) {
    Status s = Status::error(path_ + ": write failed: " + errno_text());
    discard();
    return s;
  }
  return Status::ok();
}

Status AtomicFile::commit() {
  if (!file_) return Status::error(path_ + ": commit of a file that is not open");
  bool ok = std::fflush(file_) == 0;
  ok = (std::fclose(file_) == 0) && ok;
  file_ = nullptr;
  if (!ok) {
    Status s = Status::error(path_ + ": flushing the output failed: " + errno_text());
    discard();
    return s;
  }
  Status s = commit_temp_file(temp_path_, path_);
  temp_path_.clear();
  return s;
}

Status write_file_atomic(const std::string& path, const void* data, size_t bytes) {
  AtomicFile f;
  MACRO_TRY(f.open(path));
  MACRO_TRY(f.write(data, bytes));
  return f.commit();
}

void install_interrupt_cleanup() {
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
}

}  // namespace macro
