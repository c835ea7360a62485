// gsplat training checkpoints (ckpt_29999.pt as gsplat's simple_trainer saves them): a torch.save
// zip (attention/runtime/io/torch_checkpoint.h) whose root dict holds "splats", the raw parameters:
//   means [N,3]; scales [N,3] (log); quats [N,4] (w, x, y, z, not normalised);
//   opacities [N] (logit); sh0 [N,1,3]; shN [N,K-1,3] (optional; coefficient-major, RGB fastest)
// Tensors may also sit at the root (a bare splats dict). Any float dtype is accepted. Values are in
// the frame gsplat trained in (COLMAP's RDF for COLMAP data), as in its exported .ply.
#include <cmath>

#include "attention/runtime/io/torch_checkpoint.h"
#include "attention/runtime/progress.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs::formats {

Result<GaussianCloud> decode_gsplat_checkpoint(const uint8_t* data, size_t size,
                                               const std::string& file, const LoadLimits& limits) {
  MACRO_ASSIGN_OR_RETURN(TorchCheckpoint ckpt,
                         read_torch_checkpoint_from_memory(data, size, file, ""));
  auto find = [&](const std::string& name) -> const TensorEntry* {
    for (const TensorEntry& t : ckpt.tensors)
      if (t.name == "splats." + name || t.name == name) return &t;
    return nullptr;
  };
  const TensorEntry* means = find("means");
  if (!means)
    return Status::error(file + ": not a gsplat checkpoint: no tensor 'splats.means' (expected a " +
                         "'splats' dict with means, scales, quats, opacities, sh0, shN)");
  if (means->shape.size() != 2 || means->shape[1] != 3)
    return Status::error(file + ": splats.means: expected shape [N,3], found " +
                         shape_text(means->shape));
  const int64_t n = means->shape[0];
  if (n < 0 || uint64_t(n) > limits.max_gaussians)
    return Status::error(file + ": splats.means: " + std::to_string(n) +
                         " Gaussians exceed the limit of " + std::to_string(limits.max_gaussians) +
                         " (--max-gaussians)");
  const size_t N = static_cast<size_t>(n);
  struct Want {
    const char* name;
    std::vector<int64_t> shape;
  };
  const std::vector<Want> wants = {
      {"scales", {n, 3}}, {"quats", {n, 4}}, {"opacities", {n}}, {"sh0", {n, 1, 3}}};
  for (const Want& w : wants) {
    const TensorEntry* t = find(w.name);
    if (!t)
      return Status::error(file + ": gsplat checkpoint: missing tensor 'splats." + w.name + "'");
    if (t->shape != w.shape)
      return Status::error(file + ": splats." + w.name + ": expected shape " + shape_text(w.shape) +
                           ", found " + shape_text(t->shape));
  }
  const TensorEntry* shn = find("shN");
  size_t rest = 0;
  if (shn) {
    if (shn->shape.size() != 3 || shn->shape[0] != n || shn->shape[2] != 3)
      return Status::error(file + ": splats.shN: expected shape [" + std::to_string(n) +
                           ",K-1,3], found " + shape_text(shn->shape));
    rest = static_cast<size_t>(shn->shape[1]);
  }
  const int degree = sh_degree_for_rest(rest);
  const size_t used_rest = static_cast<size_t>((degree + 1) * (degree + 1) - 1);
  if (used_rest != rest)
    log_info("load", file + ": splats.shN holds " + std::to_string(rest) +
                         " coefficients per channel; loading SH degree " + std::to_string(degree) +
                         " (" + std::to_string(used_rest) + ")");

  auto read = [&](const char* name, size_t count) -> Result<std::vector<float>> {
    std::vector<float> v(count);
    MACRO_TRY(convert_to_f32(*find(name), v.data(), count));
    return v;
  };
  GaussianCloud cloud;
  cloud.resize(N, degree);
  MACRO_TRY(convert_to_f32(*means, cloud.position.data(), N * 3));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> scales, read("scales", N * 3));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> quats, read("quats", N * 4));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> opac, read("opacities", N));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> sh0, read("sh0", N * 3));
  std::vector<float> shr;
  if (rest) {
    MACRO_ASSIGN_OR_RETURN(shr, read("shN", N * rest * 3));
  }
  const size_t K = static_cast<size_t>(cloud.sh_coeffs());
  for (size_t i = 0; i < N; ++i) {
    bool finite = std::isfinite(opac[i]);
    for (int a = 0; a < 3; ++a) {
      cloud.scale[i * 3 + a] = std::exp(scales[i * 3 + a]);
      finite &= std::isfinite(scales[i * 3 + a]);
      cloud.sh[i * K * 3 + a] = sh0[i * 3 + a];
    }
    for (int a = 0; a < 4; ++a) cloud.rotation[i * 4 + a] = quats[i * 4 + a];
    for (size_t k = 1; k < K; ++k)
      for (size_t c = 0; c < 3; ++c)
        cloud.sh[(i * K + k) * 3 + c] = shr[(i * rest + k - 1) * 3 + c];
    // A non-finite raw value hidden by an activation (a -inf logit) still drops the Gaussian.
    cloud.opacity[i] = finite ? sigmoid(opac[i]) : std::nanf("");
  }
  return cloud;
}

}  // namespace macro::gs::formats
