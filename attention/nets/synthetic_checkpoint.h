// Synthetic checkpoints: a diffusers component folder (config.json + diffusion_pytorch_model.
// safetensors) with the exact tensor names and shapes of a real download, listed in a manifest
// (data/manifests/{unet,vae}.json: {config, parameters, tensors: {name: {dtype, shape}},
// lora_targets?}), filled with seeded random values. Used to test loaders and to benchmark the
// full-size networks without the real weights.
//
// Values (deterministic in the seed and the tensor name, independent of order): norm weights
// 1 + 0.05 u, biases 0.02 u, LoRA B 0.01 n, other weights n / sqrt(fan_in) (fan_in = product of all
// but the first dim), u ~ U(-1, 1), n ~ N(0, 1). They keep activations bounded through deep stacks;
// they are not a trained network.
#pragma once

#include <cstdint>
#include <string>

#include "attention/runtime/status.h"

namespace macro::nets {

struct SyntheticCheckpointOptions {
  uint64_t seed = 1;
  bool bf16 = false;  // store weights as BF16 (the real files are F32)
};

// Writes <out_dir>/config.json and <out_dir>/diffusion_pytorch_model.safetensors (atomically;
// creates out_dir). class_name goes into config.json's _class_name.
Status write_synthetic_component(const std::string& manifest_path, const std::string& out_dir,
                                 const std::string& class_name,
                                 const SyntheticCheckpointOptions& options);

// A Difix pipeline folder: model_index.json, unet/ and vae/ from the two manifests.
Status write_synthetic_pipeline(const std::string& unet_manifest, const std::string& vae_manifest,
                                const std::string& out_dir, const SyntheticCheckpointOptions& options);

}  // namespace macro::nets
