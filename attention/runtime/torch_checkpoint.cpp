// PyTorch zip checkpoint reader (format and rules: torch_checkpoint.h).
#include "attention/runtime/torch_checkpoint.h"

#include <fcntl.h>
#include <unistd.h>

namespace macro {

Result<TorchCheckpoint> read_torch_checkpoint_from_memory(const uint8_t*, size_t,
                                                          const std::string& name,
                                                          const std::string&) {
  return Status::error(name + ": PyTorch checkpoints are not readable yet");
}

Result<TorchCheckpoint> read_torch_checkpoint(const std::string& path, const std::string& key) {
  return read_torch_checkpoint_from_memory(nullptr, 0, path, key);
}

bool file_has_zip_magic(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  unsigned char m[4] = {0, 0, 0, 0};
  ssize_t n = ::read(fd, m, 4);
  ::close(fd);
  return n == 4 && m[0] == 'P' && m[1] == 'K' && m[2] == 3 && m[3] == 4;
}

}  // namespace macro
