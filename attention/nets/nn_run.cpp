#include "attention/nets/nn_run.h"

#include <cmath>
#include <cstring>
#include <set>

#include "attention/nets/clip_text.h"
#include "attention/nets/difix.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/tensor.h"

namespace macro::nets {

const char* model_kind_name(ModelKind k) {
  switch (k) {
    case ModelKind::kTaesd:
      return "taesd";
    case ModelKind::kUNet:
      return "unet";
    case ModelKind::kVae:
      return "vae";
    case ModelKind::kDifix:
      return "difix";
    case ModelKind::kClipText:
      return "clip_text";
  }
  return "?";
}

Result<ModelKind> detect_model_kind(const std::string& folder) {
  if (!is_directory(folder)) return Status::error(folder + ": expected a model folder");
  if (Taesd::is_taesd_folder(folder)) return ModelKind::kTaesd;
  if (DifixPipeline::is_pipeline_folder(folder)) return ModelKind::kDifix;
  if (file_exists(folder + "/config.json")) {
    MACRO_ASSIGN_OR_RETURN(std::string cls, config_class_name(folder + "/config.json"));
    if (cls == "UNet2DConditionModel") return ModelKind::kUNet;
    if (cls == "AutoencoderKL") return ModelKind::kVae;
    if (cls == "CLIPTextModel") return ModelKind::kClipText;
    return Status::error(folder +
                         "/config.json: field '_class_name' / 'architectures': expected "
                         "UNet2DConditionModel, AutoencoderKL or CLIPTextModel, found '" +
                         cls + "'");
  }
  return Status::error(folder +
                       ": unknown model folder (looked for taesd_encoder.safetensors / "
                       "taesd_decoder.safetensors, model_index.json with unet/ and vae/, "
                       "config.json)");
}

Status check_finite(const float* x, size_t n, const std::string& file, const std::string& name) {
  for (size_t i = 0; i < n; ++i)
    if (!std::isfinite(x[i]))
      return Status::error(file + ": tensor '" + name + "': element " + std::to_string(i) + " is " +
                           (std::isnan(x[i]) ? "NaN" : "infinite") + "; inputs must be finite");
  return Status::ok();
}

Result<Tensor> read_input(const SafeTensors& f, const std::string& name, int rank) {
  const TensorEntry* e = f.find(name);
  if (!e) return Status::error(f.path() + ": missing input tensor '" + name + "'");
  if (e->dtype != DType::kF32 && e->dtype != DType::kF16 && e->dtype != DType::kBF16 &&
      e->dtype != DType::kF64)
    return Status::error(f.path() + ": tensor '" + name + "': expected a float dtype, found " +
                         dtype_name(e->dtype));
  if (int(e->shape.size()) != rank)
    return Status::error(f.path() + ": tensor '" + name + "': expected rank " +
                         std::to_string(rank) + ", found shape " + shape_to_string(e->shape));
  for (int64_t d : e->shape)
    if (d < 1)
      return Status::error(f.path() + ": tensor '" + name + "': expected non-empty dims, found " +
                           shape_to_string(e->shape));
  Tensor t = Tensor::f32(e->shape);
  MACRO_TRY(convert_to_f32(*e, t.f32(), size_t(t.numel())).with_context(f.path()));
  MACRO_TRY(check_finite(t.f32(), size_t(t.numel()), f.path(), name));
  return t;
}

namespace {


Status check_names(const SafeTensors& f, const std::set<std::string>& allowed, const char* kind) {
  for (const std::string& n : f.names())
    if (!allowed.count(n)) {
      std::string list;
      for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
      return Status::error(f.path() + ": unexpected tensor '" + n + "' (a " + kind +
                           " model takes " + list + ")");
    }
  return Status::ok();
}

Status run_taesd(const NnRunOptions& opt, const SafeTensors& in) {
  MACRO_TRY(check_names(in, {"input.image"}, "taesd"));
  MACRO_ASSIGN_OR_RETURN(Tensor image, read_input(in, "input.image", 4));
  if (image.dim(1) != 3 || image.dim(0) < 1 || image.dim(2) < 1 || image.dim(3) < 1)
    return Status::error(in.path() + ": tensor 'input.image': expected [N,3,H,W], found " +
                         shape_to_string(image.shape()));
  MACRO_ASSIGN_OR_RETURN(Taesd taesd, Taesd::load(opt.model, opt.precision));
  if (!taesd.has_encoder() || !taesd.has_decoder())
    return Status::error(opt.model +
                         ": a taesd run needs both taesd_encoder.safetensors and "
                         "taesd_decoder.safetensors");
  MACRO_ASSIGN_OR_RETURN(Tensor latent, taesd.encode(image, opt.pool, in.path() + ": input.image"));
  MACRO_ASSIGN_OR_RETURN(Tensor decoded, taesd.decode(latent, opt.pool, "output.latent"));
  return write_safetensors(opt.out,
                           {{"output.latent", DType::kF32, latent.shape(), latent.f32()},
                            {"output.decoded", DType::kF32, decoded.shape(), decoded.f32()}},
                           {{"model", "taesd"}, {"precision", precision_name(opt.precision)}});
}

// input.ids [B, L] (I64 or I32) -> output.hidden [B, L, D].
Status run_clip_text(const NnRunOptions& opt, const SafeTensors& in) {
  MACRO_TRY(check_names(in, {"input.ids"}, "clip_text"));
  const TensorEntry* e = in.find("input.ids");
  if (!e) return Status::error(in.path() + ": missing input tensor 'input.ids'");
  if (e->dtype != DType::kI64 && e->dtype != DType::kI32)
    return Status::error(in.path() + ": tensor 'input.ids': expected I64 or I32, found " +
                         dtype_name(e->dtype));
  if (e->shape.size() != 2 || e->shape[0] < 1 || e->shape[1] < 1)
    return Status::error(in.path() + ": tensor 'input.ids': expected [B,L], found " +
                         shape_to_string(e->shape));
  MACRO_ASSIGN_OR_RETURN(auto model, ClipTextModel::load(opt.model, opt.precision));
  if (e->shape[1] > model->config().max_position_embeddings)
    return Status::error(in.path() + ": tensor 'input.ids': expected at most " +
                         std::to_string(model->config().max_position_embeddings) +
                         " tokens per row, found " + shape_to_string(e->shape));
  const size_t n = size_t(e->numel());
  std::vector<int32_t> ids(n);
  for (size_t i = 0; i < n; ++i) {
    int64_t v = 0;
    if (e->dtype == DType::kI64) {
      std::memcpy(&v, e->data + 8 * i, 8);
    } else {
      int32_t v32 = 0;
      std::memcpy(&v32, e->data + 4 * i, 4);
      v = v32;
    }
    if (v < 0 || v >= model->config().vocab_size)
      return Status::error(in.path() + ": tensor 'input.ids': element " + std::to_string(i) +
                           ": expected an id in [0, " + std::to_string(model->config().vocab_size) +
                           "), found " + std::to_string(v));
    ids[i] = int32_t(v);
  }
  MACRO_ASSIGN_OR_RETURN(Tensor hidden, model->forward(ids, e->shape[0], opt.pool, in.path()));
  return write_safetensors(opt.out, {{"output.hidden", DType::kF32, hidden.shape(), hidden.f32()}},
                           {{"model", "clip_text"}, {"precision", precision_name(opt.precision)}});
}

}  // namespace

Status nn_run(const NnRunOptions& opt) {
  MACRO_ASSIGN_OR_RETURN(ModelKind kind, detect_model_kind(opt.model));
  MACRO_ASSIGN_OR_RETURN(SafeTensors in, SafeTensors::open(opt.inputs));
  switch (kind) {
    case ModelKind::kTaesd:
      return run_taesd(opt, in);
    case ModelKind::kUNet:
      return nn_run_unet(opt, in);
    case ModelKind::kVae:
      return nn_run_vae(opt, in);
    case ModelKind::kDifix:
      return nn_run_difix(opt, in);
    case ModelKind::kClipText:
      return run_clip_text(opt, in);
  }
  return Status::error("internal: unhandled model kind");
}

}  // namespace macro::nets
