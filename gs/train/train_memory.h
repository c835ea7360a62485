// What training holds in memory (the float path, gs/train/fast_render.h; the double reference
// holds more), in bytes, from the counts it depends on:
//   per Gaussian   parameters (3 + 3 + 4 + 1 + 3 + 3 (K - 1) floats), gradients (the same + the
//                  2D mean), Adam's two moments (2 x the parameters), the default strategy's
//                  grad2d and count (12 B), the render state (the projected record, tile count,
//                  depth key, flags, the backward's pair sums: 153 B) and the bin stage's scratch
//                  (sorted record, keys, offsets: 92 B)
//   per pair       a (Gaussian, tile) pair: the bin stage's 3 indices, its 9-float gradient and its
//                  slot in the per-Gaussian grouping (52 B)
//   per pixel      of the largest view: colour, alpha, final T, last index, dL/dcolor and the
//                  loss's 13 planes (88 B)
//   photos         every training and held-out photo as float RGB (12 B per pixel)
// K = (sh_degree + 1)^2.
#pragma once

#include <cstddef>
#include <string>

namespace macro::gs::train {

struct TrainMemory {
  size_t gaussians = 0;
  size_t parameters = 0, gradients = 0, adam = 0, strategy = 0, render = 0;  // bytes, all N
  size_t per_gaussian = 0;                                                   // their sum / N
  size_t per_pair = 52, per_pixel = 88;
  size_t pixels = 0;  // the largest view's
  size_t photos = 0;  // bytes
  // Everything but the pairs: N per_gaussian + pixels per_pixel + photos.
  size_t fixed() const { return fixed_at(gaussians); }
  // The same at another Gaussian count (e.g. the --max-gaussians bound).
  size_t fixed_at(size_t n) const { return n * per_gaussian + pixels * per_pixel + photos; }
};

TrainMemory train_memory(size_t gaussians, int sh_degree, size_t largest_view_pixels,
                         size_t photo_pixels);

// One line: "21402 Gaussians x 1209 B (parameters 236, gradients 244, Adam 472, strategy 12,
// render 245) = 24.7 MiB, photos 8.7 MiB, 88 B x 263340 pixels = 22.1 MiB, + 52 B per (Gaussian,
// tile) pair".
std::string describe(const TrainMemory& m);

}  // namespace macro::gs::train
