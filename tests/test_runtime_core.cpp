// Thread pool, CPU dispatch, atomic files, argument errors.
#include <atomic>
#include <catch2/catch.hpp>
#include <filesystem>
#include <numeric>

#include "attention/runtime/cpu.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/limits.h"
#include "attention/runtime/thread_pool.h"
#include "test_support.h"

using namespace macro;

TEST_CASE("thread pool covers every index exactly once", "[runtime][threads]") {
  for (int threads : {1, 2, 3}) {
    ThreadPool pool(threads);
    REQUIRE(pool.size() == threads);
    for (size_t n : {size_t(0), size_t(1), size_t(7), size_t(1000), size_t(100003)}) {
      std::vector<std::atomic<int>> hits(n);
      pool.parallel_for(n, [&](size_t b, size_t e, int worker) {
        REQUIRE(worker >= 0);
        REQUIRE(worker < threads);
        for (size_t i = b; i < e; ++i) hits[i]++;
      }, 3);
      for (size_t i = 0; i < n; ++i) REQUIRE(hits[i].load() == 1);
    }
    // Reuse many times (no lost wake-ups).
    std::atomic<long> sum{0};
    for (int rep = 0; rep < 200; ++rep)
      pool.parallel_for(64, [&](size_t b, size_t e, int) { sum += long(e - b); }, 1);
    REQUIRE(sum.load() == 200 * 64);
  }
}

TEST_CASE("ISA selection: scalar always available, unsupported paths refused", "[runtime][cpu]") {
  REQUIRE(isa_supported(Isa::kScalar));
  REQUIRE(isa_supported(best_isa()));
  REQUIRE(parse_isa("avx512").value() == Isa::kAvx512);
  REQUIRE_FALSE(parse_isa("sse9").is_ok());
  Isa before = active_isa();
  REQUIRE(set_isa(Isa::kScalar).is_ok());
  REQUIRE(active_isa() == Isa::kScalar);
  if (!isa_supported(Isa::kAmx)) REQUIRE_FALSE(set_isa(Isa::kAmx).is_ok());
  REQUIRE(set_isa(before).is_ok());
}

TEST_CASE("atomic files: committed or absent, never partial", "[runtime][files]") {
  test::TempDir dir("atomic");
  const std::string path = dir.file("out.bin");
  {
    AtomicFile f;
    REQUIRE(f.open(path).is_ok());
    REQUIRE(f.write("hello").is_ok());
    REQUIRE_FALSE(file_exists(path));  // only the temporary exists so far
    // destroyed without commit
  }
  REQUIRE_FALSE(file_exists(path));
  REQUIRE(std::distance(std::filesystem::directory_iterator(dir.path),
                        std::filesystem::directory_iterator{}) == 0);
  REQUIRE(write_file_atomic(path, "data").is_ok());
  auto text = read_text_file(path);
  REQUIRE(text.is_ok());
  REQUIRE(*text == "data");
  // Unwritable destination: error names the path.
  Status s = write_file_atomic(dir.file("no/such/dir/x.bin"), "x");
  REQUIRE_FALSE(s.is_ok());
  REQUIRE(s.message().find("no/such/dir/x.bin") != std::string::npos);
  // Bounded reads.
  auto big = read_file(path, 2);
  REQUIRE_FALSE(big.is_ok());
  REQUIRE(big.status().message().find("limit") != std::string::npos);
  REQUIRE_FALSE(read_file(dir.file("missing")).is_ok());
}

TEST_CASE("resource limits: memory-bound defaults follow the available memory",
          "[runtime][limits]") {
  // No figure: the fixed caps.
  const ResourceLimits caps = default_resource_limits(MemoryFigure{});
  CHECK(caps.max_tile_pairs == (1ull << 31));
  CHECK(caps.max_gaussians == 50'000'000);
  CHECK(caps.max_tensor_bytes == (16ull << 30));
  CHECK(caps.sized_from.empty());
  // A laptop with 6 GiB free: half of it.
  const uint64_t avail = 6ull << 30;
  const ResourceLimits l =
      default_resource_limits(MemoryFigure{avail, "MemAvailable in /proc/meminfo"});
  const uint64_t budget = uint64_t(double(avail) * kMemoryFraction);
  CHECK(l.max_tile_pairs == budget / kTilePairBytes);
  CHECK(l.max_tile_pairs < (1ull << 31));
  CHECK(l.max_gaussians == std::min<uint64_t>(50'000'000, budget / kGaussianBytes));
  CHECK(l.max_tensor_bytes == budget);
  CHECK(l.max_image_pixels == caps.max_image_pixels);
  CHECK_THAT(l.sized_from, Catch::Contains("6.00 GiB") && Catch::Contains("MemAvailable"));
  // A big machine keeps the caps.
  const ResourceLimits big = default_resource_limits(MemoryFigure{1ull << 40, "x"});
  CHECK(big.max_tile_pairs == caps.max_tile_pairs);
  CHECK(big.max_tensor_bytes == caps.max_tensor_bytes);
  // The injected figure wins over the measured one; 0 measures again.
  set_available_memory_for_testing(12345);
  CHECK(available_memory().bytes == 12345);
  set_available_memory_for_testing(0);
  const MemoryFigure m = available_memory();
  CHECK(m.bytes > 0);  // /proc/meminfo on Linux
  CHECK_FALSE(m.source.empty());
}
