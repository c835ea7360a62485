// diffusers / transformers config.json files for the networks we run, parsed and validated.
//
// Nothing here assumes the SD-Turbo sizes: widths, head counts, group counts and layers per block
// come from the file (the tiny goldens use other values). Block types must be the ones SD-Turbo and
// the Difix VAE use; anything else is an error naming the field and the value found.
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::nets {

struct UNetConfig {
  int in_channels = 4, out_channels = 4;
  std::vector<std::string> down_block_types;  // CrossAttnDownBlock2D | DownBlock2D
  std::vector<std::string> up_block_types;    // UpBlock2D | CrossAttnUpBlock2D
  std::vector<int> block_out_channels;
  int layers_per_block = 2;
  // Heads per level. diffusers' legacy `attention_head_dim` holds head COUNTS when
  // `num_attention_heads` is null (SD 2.x); `num_attention_heads`, when given, wins.
  std::vector<int> num_heads;
  int cross_attention_dim = 1024;
  bool use_linear_projection = true;
  int norm_num_groups = 32;
  double norm_eps = 1e-5;
  bool flip_sin_to_cos = true;
  int freq_shift = 0;
  int transformer_layers_per_block = 1;
  int time_embed_dim() const { return 4 * block_out_channels.at(0); }
};

struct VaeConfig {
  int in_channels = 3, out_channels = 3;
  std::vector<int> block_out_channels;
  int layers_per_block = 2;
  int latent_channels = 4;
  int norm_num_groups = 32;
  double scaling_factor = 0.18215;
  // Difix additions.
  double gamma = 1.0;        // skip scale
  bool ignore_skip = false;
  int lora_rank = 0;         // 0: no LoRA expected
  double lora_scale = 2.0;   // alpha / r: `lora_alpha_over_rank`, or `lora_alpha`/r, or PEFT's default 8/r
  bool has_skip_convs = true;
};

struct ClipTextConfig {
  int hidden_size = 1024;
  int intermediate_size = 4096;
  int num_attention_heads = 16;
  int num_hidden_layers = 23;
  int max_position_embeddings = 77;
  int vocab_size = 49408;
  std::string hidden_act = "gelu";  // gelu (exact erf) | quick_gelu
  double layer_norm_eps = 1e-5;
};

Result<UNetConfig> load_unet_config(const std::string& config_json_path);
Result<VaeConfig> load_vae_config(const std::string& config_json_path);
Result<ClipTextConfig> load_clip_text_config(const std::string& config_json_path);
// From JSON text (the manifests embed configs); `origin` names the source in errors.
Result<UNetConfig> parse_unet_config(const std::string& json_text, const std::string& origin);
Result<VaeConfig> parse_vae_config(const std::string& json_text, const std::string& origin);
Result<ClipTextConfig> parse_clip_text_config(const std::string& json_text, const std::string& origin);

// The `_class_name` (diffusers) or first `architectures` entry (transformers) of a config.json;
// empty if neither is present.
Result<std::string> config_class_name(const std::string& config_json_path);

}  // namespace macro::nets
