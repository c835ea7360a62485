// Process-wide resource limits: the largest input the loaders and the renderer accept, checked
// before anything is allocated from a size a file claims. Each has a flag every `macro` command
// takes (apps/args.cpp apply_common_flags) to raise or lower it. The memory-bound defaults are
// sized from the memory this process may use (available_memory(): the least of MemAvailable,
// the cgroup's free allowance and RLIMIT_AS headroom), kMemoryFraction of it, and never above the
// fixed caps:
//
//   limit             default                                 flag                 checked by
//   max_gaussians     min(50 M, budget / kGaussianBytes)      --max-gaussians N    scene loaders
//   max_image_pixels  2^27 (134 M)                            --max-image-pixels N image decoders,
//                                                                                  cameras
//   max_tile_pairs    min(2^31, budget / kTilePairBytes)      --max-tile-pairs N   renderer, after
//                                                                                  projection,
//                                                                                  before binning
//   max_tensor_bytes  min(16 GiB, budget)                     --max-tensor-bytes N safetensors,
//                                                                                  checkpoints
//
// (budget = kMemoryFraction x available memory; docs/reliability.md.) With no memory figure (no
// /proc) the fixed caps apply. The structs that carry a limit (gs::LoadLimits, gs::ImageLimits,
// gs::RenderOptions) take their default from here when they are constructed, so a flag applies to
// everything built after it.
#pragma once

#include <cstdint>
#include <string>

namespace macro {

inline constexpr double kMemoryFraction = 0.5;  // of the available memory, for one allocation
// Bytes the renderer's binning allocates per (Gaussian, tile) pair: pair tile, pair id and the
// sorted output, uint32 each (gs/raster/raster_bin.cpp bin_scratch_bytes).
inline constexpr uint64_t kTilePairBytes = 12;
// Bytes a loaded Gaussian takes, about: 59 floats of attributes (degree-3 SH) plus the
// renderer's per-Gaussian projection and sort records.
inline constexpr uint64_t kGaussianBytes = 320;

struct ResourceLimits {
  uint64_t max_gaussians = 50'000'000;
  uint64_t max_image_pixels = 1ull << 27;
  uint64_t max_tile_pairs = 1ull << 31;
  uint64_t max_tensor_bytes = 16ull << 30;
  // How the memory-bound defaults were sized ("" = the fixed caps): named by refusals.
  std::string sized_from;
};

// Memory this process may still allocate, and where the figure comes from.
struct MemoryFigure {
  uint64_t bytes = 0;  // 0 = unknown
  std::string source;  // "MemAvailable in /proc/meminfo", "cgroup memory.max", "RLIMIT_AS", ...
};
MemoryFigure available_memory();
// Tests: use `bytes` instead of measuring (0 = measure again). Takes effect for the limits
// through set_resource_limits(default_resource_limits()).
void set_available_memory_for_testing(uint64_t bytes);

// The defaults for `memory` (the fixed caps when memory.bytes is 0).
ResourceLimits default_resource_limits(const MemoryFigure& memory);
inline ResourceLimits default_resource_limits() {
  return default_resource_limits(available_memory());
}

// The current limits (default_resource_limits() until set_resource_limits is called).
const ResourceLimits& resource_limits();
// Replaces the limits; not thread-safe against concurrent loads (call it at start-up, as the CLI
// does, or from a test before loading).
void set_resource_limits(const ResourceLimits& limits);

// "7.50 GiB" style.
std::string format_bytes(uint64_t bytes);

}  // namespace macro
