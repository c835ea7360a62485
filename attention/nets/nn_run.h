// Run a network on tensors from a safetensors file and write its outputs (`macro nn-run`).
//
// The model folder's kind decides the inputs and outputs (detect_model_kind):
//   taesd  (taesd_encoder.safetensors + taesd_decoder.safetensors)
//          input.image [N,3,H,W] in [0,1]  ->  output.latent [N,4,ceil(H/8),ceil(W/8)],
//                                               output.decoded [N,3,8h,8w] (decoder(latent), not
//                                               clamped)
//   unet / vae / difix (config.json UNet2DConditionModel / AutoencoderKL; a pipeline folder with
//          model_index.json, unet/, vae/): see attention/nets/nn_run_difix.cpp
//   clip_text (config.json architectures CLIPTextModel + model.safetensors)
//          input.ids [B,L] I64 or I32 (L <= 77)  ->  output.hidden [B,L,D] (last_hidden_state)
// Inputs are validated before anything runs: only the listed names, the documented rank and
// channel count, finite values (a NaN or infinity is refused naming the tensor and the element).
// Float inputs of any float dtype (F32/F16/BF16/F64) are widened to fp32. Outputs are F32, written
// atomically, with metadata {model, precision}.
#pragma once

#include <string>

#include "attention/nets/taesd.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/status.h"
#include "attention/runtime/tensor.h"
#include "attention/runtime/thread_pool.h"

namespace macro::nets {

enum class ModelKind { kTaesd, kUNet, kVae, kDifix, kClipText };
const char* model_kind_name(ModelKind k);
// Which network a folder holds; the error lists what was looked for.
Result<ModelKind> detect_model_kind(const std::string& folder);

struct NnRunOptions {
  std::string model;   // folder
  std::string inputs;  // safetensors with input.* tensors
  std::string out;     // safetensors to write
  Precision precision = Precision::kF32;
  ThreadPool* pool = nullptr;
};

Status nn_run(const NnRunOptions& opt);

// Every element finite? Error "<file>: tensor '<name>': element <i> is nan" otherwise.
Status check_finite(const float* x, size_t n, const std::string& file, const std::string& name);

// A float input tensor (F32/F16/BF16/F64) as an owning fp32 Tensor, after checking that it exists,
// has the given rank, no empty dimension, and only finite values; errors name file and tensor.
Result<Tensor> read_input(const SafeTensors& f, const std::string& name, int rank);

}  // namespace macro::nets
