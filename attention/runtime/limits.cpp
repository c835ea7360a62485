#include "attention/runtime/limits.h"

#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace macro {
namespace {

std::atomic<uint64_t> g_test_memory{0};

ResourceLimits& current() {
  static ResourceLimits limits = default_resource_limits();
  return limits;
}

// First line of a small file, "" if unreadable.
std::string first_line(const char* path) {
  std::ifstream f(path);
  std::string line;
  if (f) std::getline(f, line);
  return line;
}
bool parse_u64(const std::string& s, uint64_t* out) {
  if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos) return false;
  try {
    *out = std::stoull(s);
  } catch (...) {
    return false;
  }
  return true;
}

void take(MemoryFigure* best, uint64_t bytes, const std::string& source) {
  if (bytes == 0) bytes = 1;  // no room at all, but a known figure
  if (best->bytes == 0 || bytes < best->bytes) *best = {bytes, source};
}

}  // namespace

std::string format_bytes(uint64_t b) {
  char buf[48];
  if (b >= (1ull << 30))
    std::snprintf(buf, sizeof buf, "%.2f GiB", double(b) / double(1ull << 30));
  else if (b >= (1ull << 20))
    std::snprintf(buf, sizeof buf, "%.1f MiB", double(b) / double(1ull << 20));
  else
    std::snprintf(buf, sizeof buf, "%llu bytes", static_cast<unsigned long long>(b));
  return buf;
}

void set_available_memory_for_testing(uint64_t bytes) {
  g_test_memory.store(bytes);
}

MemoryFigure available_memory() {
  if (const uint64_t t = g_test_memory.load()) return {t, "a figure set for a test"};
  MemoryFigure best;
  {  // MemAvailable: what the kernel can hand out without swapping.
    std::ifstream f("/proc/meminfo");
    std::string key, unit;
    uint64_t kb = 0;
    while (f >> key >> kb) {
      std::getline(f, unit);
      if (key == "MemAvailable:") {
        take(&best, kb * 1024, "MemAvailable in /proc/meminfo");
        break;
      }
    }
  }
  {  // cgroup v2, then v1: the limit minus what the group already uses.
    uint64_t limit = 0, used = 0;
    if (parse_u64(first_line("/sys/fs/cgroup/memory.max"), &limit)) {
      parse_u64(first_line("/sys/fs/cgroup/memory.current"), &used);
      take(&best, limit > used ? limit - used : 0, "the cgroup's memory.max");
    } else if (parse_u64(first_line("/sys/fs/cgroup/memory/memory.limit_in_bytes"), &limit) &&
               limit < (1ull << 60)) {
      parse_u64(first_line("/sys/fs/cgroup/memory/memory.usage_in_bytes"), &used);
      take(&best, limit > used ? limit - used : 0, "the cgroup's memory.limit_in_bytes");
    }
  }
  {  // RLIMIT_AS: address space left under the soft limit.
    struct rlimit rl {};
    if (::getrlimit(RLIMIT_AS, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY) {
      std::istringstream statm(first_line("/proc/self/statm"));
      uint64_t pages = 0;
      statm >> pages;
      const uint64_t used = pages * 4096;
      const uint64_t lim = uint64_t(rl.rlim_cur);
      take(&best, lim > used ? lim - used : 0, "RLIMIT_AS (ulimit -v)");
    }
  }
  return best;
}

ResourceLimits default_resource_limits(const MemoryFigure& memory) {
  ResourceLimits l;
  if (memory.bytes == 0) return l;
  const uint64_t budget = std::max<uint64_t>(1, uint64_t(double(memory.bytes) * kMemoryFraction));
  l.max_tile_pairs =
      std::min<uint64_t>(l.max_tile_pairs, std::max<uint64_t>(1, budget / kTilePairBytes));
  l.max_gaussians =
      std::min<uint64_t>(l.max_gaussians, std::max<uint64_t>(1, budget / kGaussianBytes));
  l.max_tensor_bytes = std::min<uint64_t>(l.max_tensor_bytes, budget);
  char frac[16];
  std::snprintf(frac, sizeof frac, "%.0f%%", kMemoryFraction * 100);
  l.sized_from = std::string(frac) + " of the " + format_bytes(memory.bytes) +
                 " of memory available (" + memory.source + ")";
  return l;
}

const ResourceLimits& resource_limits() { return current(); }
void set_resource_limits(const ResourceLimits& limits) { current() = limits; }

}  // namespace macro
