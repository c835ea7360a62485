#include "attention/runtime/file_io.h"
#include "attention/runtime/interrupt_note.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>

namespace macro {
namespace {

// Temporaries not yet committed, in fixed slots the signal handler can walk without locking or
// allocating (a std::set is not async-signal-safe). A slot is free (0), being filled (1) or live
// (2).
constexpr int kTempSlots = 64;
constexpr size_t kTempPathMax = 4096;
struct TempSlot {
  std::atomic<int> state{0};
  char path[kTempPathMax];
};
TempSlot g_temps[kTempSlots];
// Outputs committed so far: the interrupt line says whether any finished before the signal.
std::atomic<int> g_committed{0};

void register_temp(const std::string& p) {
  if (p.size() + 1 > kTempPathMax)
    return;  // no signal cleanup for such a path; still removed on error
  for (TempSlot& slot : g_temps) {
    int expected = 0;
    if (slot.state.compare_exchange_strong(expected, 1)) {
      std::memcpy(slot.path, p.c_str(), p.size() + 1);
      slot.state.store(2);
      return;
    }
  }
}
void unregister_temp(const std::string& p) {
  for (TempSlot& slot : g_temps) {
    if (slot.state.load() == 2 && std::strcmp(slot.path, p.c_str()) == 0) {
      slot.state.store(0);
      return;
    }
  }
}

// The note printed after the interrupt line: written into the buffer not in use, then published.
char g_note_buf[2][1024];
std::atomic<int> g_note_len[2] = {0, 0};
std::atomic<int> g_note_which{-1};

// Signal handler: async-signal-safe calls only (unlink, write, signal, raise). Removes the live
// temporaries, prints one line, then dies of the same signal.
void on_signal(int sig) {
  for (TempSlot& slot : g_temps) {
    if (slot.state.load() == 2) ::unlink(slot.path);
  }
  static const char kNone[] = "interrupted: no output written\n";
  static const char kSome[] =
      "interrupted: the unfinished output was removed; outputs finished before were kept\n";
  const bool some = g_committed.load() > 0;
  const ssize_t ignored =
      ::write(2, some ? kSome : kNone, some ? sizeof kSome - 1 : sizeof kNone - 1);
  (void)ignored;
  const int which = g_note_which.load();
  if (which >= 0) {
    const ssize_t ignored2 = ::write(2, g_note_buf[which], size_t(g_note_len[which].load()));
    (void)ignored2;
  }
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

std::string errno_text() {
  return std::strerror(errno);
}

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
  if (got != size)
    return Status::error(path + ": short read (" + std::to_string(got) + " of " +
                         std::to_string(size) + " bytes)");
  return data;
}

Result<std::string> read_text_file(const std::string& path, uint64_t max_bytes) {
  MACRO_ASSIGN_OR_RETURN(auto bytes, read_file(path, max_bytes));
  return std::string(bytes.begin(), bytes.end());
}

// ---- outputs
// -------------------------------------------------------------------------------------

Result<OutputTarget> resolve_output(const std::string& path) {
  if (path.empty()) return Status::error("output path: expected a file name, found ''");
  constexpr int kMaxLinks = 40;  // as the kernel's own limit on nested links
  std::string cur = path;
  for (int hop = 0; hop <= kMaxLinks; ++hop) {
    struct stat st {};
    if (::lstat(cur.c_str(), &st) != 0) {
      if (errno == ENOENT) return OutputTarget{OutputTarget::kRegular, cur};  // a new file
      return Status::error(path + ": cannot stat the output: " + errno_text());
    }
    if (S_ISLNK(st.st_mode)) {
      std::vector<char> buf(size_t(st.st_size > 0 ? st.st_size : 255) + 2);
      const ssize_t n = ::readlink(cur.c_str(), buf.data(), buf.size() - 1);
      if (n < 0)
        return Status::error(path + ": cannot read the symbolic link " + cur + ": " + errno_text());
      const std::filesystem::path target(std::string(buf.data(), size_t(n)));
      cur = target.is_absolute() ? target.string()
                                 : (std::filesystem::path(cur).parent_path() / target).string();
      continue;
    }
    if (S_ISREG(st.st_mode)) return OutputTarget{OutputTarget::kRegular, cur};
    if (S_ISDIR(st.st_mode)) {
      return Status::error(path + ": expected an output file, found a directory" +
                           (cur == path ? std::string() : " (" + cur + ")"));
    }
    if (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode))
      return OutputTarget{OutputTarget::kSpecial, cur};
    const char* kind = S_ISSOCK(st.st_mode)  ? "a socket"
                       : S_ISBLK(st.st_mode) ? "a block device"
                                             : "a special file";
    return Status::error(path + ": expected an output file, a character device or a pipe, found " +
                         kind + (cur == path ? std::string() : " (" + cur + ")"));
  }
  return Status::error(path + ": more than " + std::to_string(kMaxLinks) +
                       " symbolic links to follow (a loop?)");
}

namespace {

// Opens an existing special file (character device, FIFO) for writing in place: no O_CREAT, so a
// file that vanished in between is not replaced by a regular one. A FIFO blocks until a reader.
Result<std::FILE*> open_special(const std::string& shown, const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);
  if (fd < 0) return Status::error(shown + ": cannot open the output for writing: " + errno_text());
  std::FILE* f = ::fdopen(fd, "wb");
  if (!f) {
    Status s = Status::error(shown + ": cannot open the output for writing: " + errno_text());
    ::close(fd);
    return s;
  }
  return f;
}

std::string temp_folder() {
  const char* env = std::getenv("TMPDIR");
  return env && *env ? env : "/tmp";
}

}  // namespace

std::string temp_path_for(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  const std::string suffix = ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  std::string temp = path + suffix;
  if (auto target = resolve_output(path); target.is_ok()) {
    if (target->kind == OutputTarget::kRegular) {
      temp = target->path + suffix;  // beside the file a symlink points to, renamed onto it
    } else {  // a device or pipe: written in place from a temporary in the temp folder
      temp = temp_folder() + "/macro-" + std::filesystem::path(target->path).filename().string() +
             suffix;
    }
  }
  register_temp(temp);  // removed on SIGINT/SIGTERM until committed or removed
  return temp;
}

Status commit_temp_file(const std::string& temp, const std::string& path) {
  auto target = resolve_output(path);
  if (!target.is_ok()) {
    remove_temp_file(temp);
    return target.status();
  }
  if (target->kind == OutputTarget::kSpecial) {  // copy the bytes into the device or pipe
    AtomicFile out;
    Status s = out.open(path);
    std::FILE* in = s.is_ok() ? std::fopen(temp.c_str(), "rb") : nullptr;
    if (s.is_ok() && !in)
      s = Status::error(temp + ": cannot reopen the temporary: " + errno_text());
    std::vector<char> buf(1 << 16);
    while (s.is_ok()) {
      const size_t n = std::fread(buf.data(), 1, buf.size(), in);
      if (n == 0) break;
      s = out.write(buf.data(), n);
    }
    if (in) std::fclose(in);
    if (s.is_ok()) s = out.commit();
    remove_temp_file(temp);
    return s;
  }
  if (std::rename(temp.c_str(), target->path.c_str()) != 0) {
    Status s = Status::error(path + ": cannot rename the temporary into place: " + errno_text());
    remove_temp_file(temp);
    return s;
  }
  unregister_temp(temp);
  g_committed.fetch_add(1);
  return Status::ok();
}

void remove_temp_file(const std::string& temp) {
  ::unlink(temp.c_str());
  unregister_temp(temp);
}

AtomicFile::~AtomicFile() {
  discard();
}

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
  MACRO_ASSIGN_OR_RETURN(OutputTarget target, resolve_output(path));
  if (target.kind == OutputTarget::kSpecial) {  // streamed in place; nothing to rename
    MACRO_ASSIGN_OR_RETURN(file_, open_special(path, target.path));
    return Status::ok();
  }
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
  const bool flushed = std::fflush(file_) == 0;
  const int flush_errno = errno;
  const bool ok = (std::fclose(file_) == 0) && flushed;
  if (!flushed) errno = flush_errno;  // ENOSPC from /dev/full shows here, not in fclose
  file_ = nullptr;
  if (!ok) {
    Status s = Status::error(path_ + ": writing the output failed: " + errno_text());
    discard();
    return s;
  }
  if (temp_path_.empty()) {  // a special file written in place
    g_committed.fetch_add(1);
    return Status::ok();
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

void set_interrupt_note(const std::string& note) {
  if (note.empty()) {
    g_note_which.store(-1);
    return;
  }
  const int next = g_note_which.load() == 0 ? 1 : 0;
  const size_t n = std::min(note.size(), sizeof g_note_buf[0] - 1);
  std::memcpy(g_note_buf[next], note.data(), n);
  g_note_len[next].store(int(n));
  g_note_which.store(next);
}

void install_interrupt_cleanup() {
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
}

}  // namespace macro
