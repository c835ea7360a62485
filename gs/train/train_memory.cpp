// Training memory (train_memory.h).
#include "gs/train/train_memory.h"

#include "attention/runtime/limits.h"

namespace macro::gs::train {

TrainMemory train_memory(size_t gaussians, int sh_degree, size_t largest_view_pixels,
                         size_t photo_pixels) {
  const size_t K = size_t(sh_degree + 1) * size_t(sh_degree + 1);
  const size_t param_floats = 3 + 3 + 4 + 1 + 3 + 3 * (K - 1);
  TrainMemory m;
  m.gaussians = gaussians;
  const size_t p = param_floats * 4, g = (param_floats + 2) * 4, a = 2 * param_floats * 4;
  const size_t s = 8 + 4;  // grad2d (double), count (int32)
  const size_t r = (64 + 4 + 4 + 1 + 4 + 4 + 72) + (64 + 16 + 8 + 4);
  m.parameters = p * gaussians;
  m.gradients = g * gaussians;
  m.adam = a * gaussians;
  m.strategy = s * gaussians;
  m.render = r * gaussians;
  m.per_gaussian = p + g + a + s + r;
  m.pixels = largest_view_pixels;
  m.photos = photo_pixels * 12;
  return m;
}

std::string describe(const TrainMemory& m) {
  const size_t n = m.gaussians ? m.gaussians : 1;
  auto each = [&](size_t total) { return std::to_string(total / n); };
  return std::to_string(m.gaussians) + " Gaussians x " + std::to_string(m.per_gaussian) +
         " B (parameters " + each(m.parameters) + ", gradients " + each(m.gradients) + ", Adam " +
         each(m.adam) + ", strategy " + each(m.strategy) + ", render " + each(m.render) +
         ") = " + format_bytes(uint64_t(m.gaussians) * m.per_gaussian) + ", photos " +
         format_bytes(m.photos) + ", " + std::to_string(m.per_pixel) + " B x " +
         std::to_string(m.pixels) + " pixels = " + format_bytes(uint64_t(m.pixels) * m.per_pixel) +
         ", + " + std::to_string(m.per_pair) + " B per (Gaussian, tile) pair";
}

}  // namespace macro::gs::train
