// `macro nn-run` for the Difix folder kinds: a U-Net, a Difix VAE, a Difix pipeline (difix.h).
//
//   unet      input.z [V,Cin,h,w], input.ctx [V|1,Lc,Dc], input.timestep (optional, default 199),
//             mask.levelL (optional, uint8/bool [V*N_L, V*N_L], 1 = may attend)  ->  output.eps
//   vae       input.image [N,3,H,W] in [-1,1]  ->  output.moments, output.z, output.skip0..n-1,
//             output.decoded_view0 (view 0 decoded from its own z and skips, not clamped)
//   pipeline  input.images [V,3,H,W] in [-1,1], input.ctx? (default: the cached embedding of
//             "remove degradation" from text_encoder/ + tokenizer/), input.timestep?, mask.levelL?
//             -> output.z, output.eps, output.z0, output.image (not clamped)
#include <cmath>
#include <set>

#include "attention/nets/difix.h"
#include "attention/nets/nn_run.h"
#include "attention/runtime/attention_mask.h"
#include "attention/runtime/io/safetensors.h"

namespace macro::nets {
namespace {

Status check_allowed(const SafeTensors& f, const std::set<std::string>& fixed, bool masks,
                     const char* kind) {
  for (const std::string& n : f.names()) {
    if (fixed.count(n)) continue;
    if (masks && n.rfind("mask.level", 0) == 0) continue;
    std::string list;
    for (const std::string& a : fixed) list += (list.empty() ? "" : ", ") + a;
    if (masks) list += ", mask.levelL";
    return Status::error(f.path() + ": unexpected tensor '" + n + "' (a " + kind + " model takes " +
                         list + ")");
  }
  return Status::ok();
}

Result<int> read_timestep(const SafeTensors& f, int num_train) {
  const TensorEntry* e = f.find("input.timestep");
  if (!e) return DifixPipeline::kDefaultTimestep;
  if (e->numel() != 1)
    return Status::error(f.path() + ": tensor 'input.timestep': expected one value, found shape " +
                         shape_to_string(e->shape));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> v, f.read_f32("input.timestep"));
  if (!(v[0] >= 0 && v[0] < float(num_train)) || v[0] != std::floor(v[0]))
    return Status::error(f.path() + ": tensor 'input.timestep': expected an integer in [0, " +
                         std::to_string(num_train - 1) + "], found " + std::to_string(v[0]));
  return int(v[0]);
}

// mask.levelL tensors -> block-sparse masks for the token grids of a latent h x w.
Status read_masks(const SafeTensors& f, const UNet2DConditionModel& unet, int64_t views, int64_t h,
                  int64_t w, std::vector<BlockSparseMask>* store, UNetMasks* masks) {
  const auto grids = unet.level_grids(h, w);
  store->clear();
  store->reserve(grids.size());
  masks->level.assign(grids.size(), nullptr);
  for (const std::string& name : f.names()) {
    if (name.rfind("mask.level", 0) != 0) continue;
    const std::string idx = name.substr(10);
    if (idx.empty() || idx.size() > 2 || (idx.size() > 1 && idx[0] == '0') ||
        idx.find_first_not_of("0123456789") != std::string::npos ||
        std::stoi(idx) >= int(grids.size()))
      return Status::error(f.path() + ": tensor '" + name +
                           "': expected mask.level0 .. mask.level" +
                           std::to_string(grids.size() - 1));
    const size_t level = size_t(std::stoi(idx));
    const TensorEntry* e = f.find(name);
    const int64_t tokens = views * grids[level].first * grids[level].second;
    if (e->dtype != DType::kU8 && e->dtype != DType::kBool)
      return Status::error(f.path() + ": tensor '" + name + "': expected U8 or BOOL, found " +
                           dtype_name(e->dtype));
    if (e->shape != std::vector<int64_t>{tokens, tokens})
      return Status::error(
          f.path() + ": tensor '" + name + "': expected [" + std::to_string(tokens) + "," +
          std::to_string(tokens) + "] (" + std::to_string(views) + " views x " +
          std::to_string(grids[level].first) + "x" + std::to_string(grids[level].second) +
          " tokens), found " + shape_to_string(e->shape));
    MACRO_ASSIGN_OR_RETURN(BlockSparseMask m, mask_from_dense(e->data, int(tokens), int(tokens), 0,
                                                              /*group_tokens=*/true));
    store->push_back(std::move(m));
    masks->level[level] = &store->back();
  }
  return Status::ok();
}

// The tensor's dims against `want` (-1 = any); the error names the file, the tensor and `layout`.
Status expect_dims(const SafeTensors& f, const std::string& name, const Tensor& t,
                   const std::vector<int64_t>& want, const std::string& layout) {
  bool ok = int64_t(t.shape().size()) == int64_t(want.size());
  for (size_t i = 0; ok && i < want.size(); ++i) ok = want[i] < 0 || t.dim(int(i)) == want[i];
  if (ok) return Status::ok();
  return Status::error(f.path() + ": tensor '" + name + "': expected " + layout + ", found " +
                       shape_to_string(t.shape()));
}

// ctx [V or 1, L, Dc] for V views.
Status expect_ctx(const SafeTensors& f, const Tensor& ctx, int64_t views, int64_t dc) {
  if (ctx.dim(2) == dc && (ctx.dim(0) == views || ctx.dim(0) == 1)) return Status::ok();
  return Status::error(f.path() + ": tensor 'input.ctx': expected [" + std::to_string(views) +
                       " or 1, L, " + std::to_string(dc) + "], found " +
                       shape_to_string(ctx.shape()));
}

std::map<std::string, std::string> meta(const char* model, Precision p) {
  return {{"model", model}, {"precision", precision_name(p)}};
}

}  // namespace

Status nn_run_unet(const NnRunOptions& opt, const SafeTensors& in) {
  MACRO_TRY(check_allowed(in, {"input.z", "input.ctx", "input.timestep"}, true, "unet"));
  MACRO_ASSIGN_OR_RETURN(Tensor z, read_input(in, "input.z", 4));
  MACRO_ASSIGN_OR_RETURN(Tensor ctx, read_input(in, "input.ctx", 3));
  MACRO_ASSIGN_OR_RETURN(UNetConfig cfg, load_unet_config(opt.model + "/config.json"));
  MACRO_TRY(expect_dims(in, "input.z", z, {-1, cfg.in_channels, -1, -1},
                        "[V," + std::to_string(cfg.in_channels) + ",h,w]"));
  MACRO_TRY(expect_ctx(in, ctx, z.dim(0), cfg.cross_attention_dim));
  MACRO_ASSIGN_OR_RETURN(auto unet, UNet2DConditionModel::load(opt.model, opt.precision));
  MACRO_ASSIGN_OR_RETURN(int t, read_timestep(in, 1000));
  std::vector<BlockSparseMask> store;
  UNetMasks masks;
  MACRO_TRY(read_masks(in, *unet, z.dim(0), z.dim(2), z.dim(3), &store, &masks));
  MACRO_ASSIGN_OR_RETURN(Tensor eps, unet->forward(z, float(t), ctx, masks, opt.pool));
  return write_safetensors(opt.out, {{"output.eps", DType::kF32, eps.shape(), eps.f32()}},
                           meta("unet", opt.precision));
}

Status nn_run_vae(const NnRunOptions& opt, const SafeTensors& in) {
  MACRO_TRY(check_allowed(in, {"input.image"}, false, "vae"));
  MACRO_ASSIGN_OR_RETURN(Tensor image, read_input(in, "input.image", 4));
  MACRO_ASSIGN_OR_RETURN(VaeConfig cfg, load_vae_config(opt.model + "/config.json"));
  const int64_t f = int64_t(1) << (cfg.block_out_channels.size() - 1);
  MACRO_TRY(expect_dims(in, "input.image", image, {-1, cfg.in_channels, -1, -1},
                        "[N," + std::to_string(cfg.in_channels) + ",H,W]"));
  if (image.dim(2) % f || image.dim(3) % f)
    return Status::error(in.path() + ": tensor 'input.image': expected H and W multiples of " +
                         std::to_string(f) + ", found " + shape_to_string(image.shape()));
  MACRO_ASSIGN_OR_RETURN(auto vae, DifixVae::load(opt.model, opt.precision));
  MACRO_ASSIGN_OR_RETURN(VaeEncoding enc, vae->encode(image, image.dim(0), opt.pool));
  std::vector<TensorView> skips0;
  for (const Tensor& s : enc.skips) skips0.push_back(s.view().slice(0, 0, 1));
  MACRO_ASSIGN_OR_RETURN(Tensor dec, vae->decode(enc.z.view().slice(0, 0, 1), skips0, opt.pool));
  std::vector<TensorToWrite> outs = {
      {"output.moments", DType::kF32, enc.moments.shape(), enc.moments.f32()},
      {"output.z", DType::kF32, enc.z.shape(), enc.z.f32()},
      {"output.decoded_view0", DType::kF32, dec.shape(), dec.f32()}};
  for (size_t i = 0; i < enc.skips.size(); ++i)
    outs.push_back(
        {"output.skip" + std::to_string(i), DType::kF32, enc.skips[i].shape(), enc.skips[i].f32()});
  return write_safetensors(opt.out, outs, meta("vae", opt.precision));
}

Status nn_run_difix(const NnRunOptions& opt, const SafeTensors& in) {
  MACRO_TRY(check_allowed(in, {"input.images", "input.ctx", "input.timestep"}, true, "pipeline"));
  MACRO_ASSIGN_OR_RETURN(Tensor images, read_input(in, "input.images", 4));
  // Without input.ctx the folder's text encoder gives the "remove degradation" embedding (cached).
  const bool has_ctx = in.find("input.ctx") != nullptr;
  if (!has_ctx && !has_text_encoder(opt.model))
    return Status::error(in.path() + ": missing input tensor 'input.ctx' (and " + opt.model +
                         " has no text_encoder/ + tokenizer/ to compute it)");
  Tensor ctx;
  if (has_ctx) {
    MACRO_ASSIGN_OR_RETURN(ctx, read_input(in, "input.ctx", 3));
  }
  {
    MACRO_ASSIGN_OR_RETURN(UNetConfig ucfg, load_unet_config(opt.model + "/unet/config.json"));
    MACRO_ASSIGN_OR_RETURN(VaeConfig vcfg, load_vae_config(opt.model + "/vae/config.json"));
    MACRO_TRY(expect_dims(in, "input.images", images, {-1, vcfg.in_channels, -1, -1},
                          "[V," + std::to_string(vcfg.in_channels) + ",H,W] in [-1,1]"));
    if (has_ctx) MACRO_TRY(expect_ctx(in, ctx, images.dim(0), ucfg.cross_attention_dim));
  }
  MACRO_ASSIGN_OR_RETURN(auto pipe, DifixPipeline::load(opt.model, opt.precision));
  if (!has_ctx) {
    MACRO_ASSIGN_OR_RETURN(ctx, pipe->prompt_context(kDifixPrompt, opt.pool));
  }
  MACRO_ASSIGN_OR_RETURN(int t, read_timestep(in, pipe->schedule().num_train_timesteps));
  const int64_t f = pipe->vae().downscale();
  if (images.dim(2) % f || images.dim(3) % f)
    return Status::error(in.path() + ": tensor 'input.images': expected H and W multiples of " +
                         std::to_string(f) + ", found " + shape_to_string(images.shape()));
  std::vector<BlockSparseMask> store;
  UNetMasks masks;
  MACRO_TRY(read_masks(in, pipe->unet(), images.dim(0), images.dim(2) / f, images.dim(3) / f,
                       &store, &masks));
  MACRO_ASSIGN_OR_RETURN(DifixOutputs o, pipe->step(images, ctx, masks, opt.pool, t));
  return write_safetensors(opt.out,
                           {{"output.z", DType::kF32, o.z.shape(), o.z.f32()},
                            {"output.eps", DType::kF32, o.eps.shape(), o.eps.f32()},
                            {"output.z0", DType::kF32, o.z0.shape(), o.z0.f32()},
                            {"output.image", DType::kF32, o.image.shape(), o.image.f32()}},
                           meta("difix", opt.precision));
}

}  // namespace macro::nets
