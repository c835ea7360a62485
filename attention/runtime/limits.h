// Process-wide resource limits: the largest input the loaders and the renderer accept, checked
// before anything is allocated from a size a file claims. Each has a flag every `macro` command
// takes (apps/args.cpp apply_common_flags) to raise or lower it; the defaults fit a 64 GB machine.
//
//   limit             default        flag                 checked by
//   max_gaussians     50,000,000     --max-gaussians N    scene loaders (count from the header)
//   max_image_pixels  2^27 (134 M)   --max-image-pixels N image decoders (size from the header),
//                                                         cameras given to the renderer
//   max_tile_pairs    2^31           --max-tile-pairs N   renderer, after projection, before binning
//   max_tensor_bytes  16 GiB         --max-tensor-bytes N safetensors (each tensor, from its header)
//
// The structs that carry a limit (gs::LoadLimits, gs::ImageLimits, gs::RenderOptions) take their
// default from here when they are constructed, so a flag applies to everything built after it.
#pragma once

#include <cstdint>

namespace macro {

struct ResourceLimits {
  uint64_t max_gaussians = 50'000'000;
  uint64_t max_image_pixels = 1ull << 27;
  uint64_t max_tile_pairs = 1ull << 31;
  uint64_t max_tensor_bytes = 16ull << 30;
};

// The current limits (the defaults above until set_resource_limits is called).
const ResourceLimits& resource_limits();
// Replaces the limits; not thread-safe against concurrent loads (call it at start-up, as the CLI
// does, or from a test before loading).
void set_resource_limits(const ResourceLimits& limits);

}  // namespace macro
