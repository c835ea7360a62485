#include "attention/nets/diffusers_config.h"

#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"

namespace macro::nets {
namespace {

using json = nlohmann::json;

Result<json> parse(const std::string& text, const std::string& origin) {
  json j = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object())
    return Status::error(origin + ": expected a JSON object, found malformed JSON");
  return j;
}

// Typed field readers: absent -> keep the default; present with the wrong type -> error.
struct Reader {
  const json& j;
  const std::string& origin;
  std::string error;

  // Every bad field is reported, joined by "; ".
  void fail(const std::string& key, const std::string& expected) {
    error += (error.empty() ? origin + ": " : std::string("; ")) + "field '" + key + "': expected " +
             expected + ", found " + (j.contains(key) ? j.at(key).dump() : std::string("nothing"));
  }
  void integer(const std::string& key, int* out, int min_value = 0, int max_value = 1 << 20) {
    if (!j.contains(key) || j.at(key).is_null()) return;
    const json& v = j.at(key);
    if (!v.is_number_integer() || v.get<int64_t>() < min_value || v.get<int64_t>() > max_value)
      return fail(key, "an integer in [" + std::to_string(min_value) + ", " +
                           std::to_string(max_value) + "]");
    *out = v.get<int>();
  }
  void number(const std::string& key, double* out) {
    if (!j.contains(key) || j.at(key).is_null()) return;
    if (!j.at(key).is_number()) return fail(key, "a number");
    *out = j.at(key).get<double>();
  }
  void boolean(const std::string& key, bool* out) {
    if (!j.contains(key) || j.at(key).is_null()) return;
    if (!j.at(key).is_boolean()) return fail(key, "true or false");
    *out = j.at(key).get<bool>();
  }
  void string(const std::string& key, std::string* out) {
    if (!j.contains(key) || j.at(key).is_null()) return;
    if (!j.at(key).is_string()) return fail(key, "a string");
    *out = j.at(key).get<std::string>();
  }
  void strings(const std::string& key, std::vector<std::string>* out) {
    if (!j.contains(key)) return fail(key, "a list of strings");
    const json& v = j.at(key);
    if (!v.is_array()) return fail(key, "a list of strings");
    out->clear();
    for (const auto& e : v) {
      if (!e.is_string()) return fail(key, "a list of strings");
      out->push_back(e.get<std::string>());
    }
  }
  // An integer or a list of integers (diffusers allows both for head counts).
  void ints(const std::string& key, std::vector<int>* out, size_t broadcast_to) {
    if (!j.contains(key) || j.at(key).is_null()) return;
    const json& v = j.at(key);
    out->clear();
    if (v.is_number_integer() && v.get<int64_t>() > 0 && v.get<int64_t>() < (1 << 20)) {
      out->assign(broadcast_to, v.get<int>());
      return;
    }
    if (!v.is_array()) return fail(key, "a positive integer or a list of them");
    for (const auto& e : v) {
      if (!e.is_number_integer() || e.get<int64_t>() <= 0 || e.get<int64_t>() >= (1 << 20))
        return fail(key, "a list of positive integers");
      out->push_back(e.get<int>());
    }
  }
  Status status() const { return error.empty() ? Status::ok() : Status::error(error); }
};

}  // namespace

Result<UNetConfig> parse_unet_config(const std::string& text, const std::string& origin) {
  MACRO_ASSIGN_OR_RETURN(json j, parse(text, origin));
  UNetConfig c;
  Reader r{j, origin, {}};
  r.integer("in_channels", &c.in_channels, 1);
  r.integer("out_channels", &c.out_channels, 1);
  r.strings("down_block_types", &c.down_block_types);
  r.strings("up_block_types", &c.up_block_types);
  std::vector<int> widths;
  r.ints("block_out_channels", &widths, 0);
  c.block_out_channels = widths;
  r.integer("layers_per_block", &c.layers_per_block, 1, 16);
  r.integer("cross_attention_dim", &c.cross_attention_dim, 1);
  r.boolean("use_linear_projection", &c.use_linear_projection);
  r.integer("norm_num_groups", &c.norm_num_groups, 1);
  r.number("norm_eps", &c.norm_eps);
  r.boolean("flip_sin_to_cos", &c.flip_sin_to_cos);
  r.integer("freq_shift", &c.freq_shift, 0, 1 << 20);
  if (j.contains("transformer_layers_per_block") && j["transformer_layers_per_block"].is_array()) {
    std::vector<int> t;
    r.ints("transformer_layers_per_block", &t, 0);
    for (int v : t)
      if (v != 1) r.fail("transformer_layers_per_block", "1 (as SD-Turbo)");
  } else {
    r.integer("transformer_layers_per_block", &c.transformer_layers_per_block, 1, 1);
  }
  const size_t levels = c.block_out_channels.size();
  if (j.contains("num_attention_heads") && !j["num_attention_heads"].is_null())
    r.ints("num_attention_heads", &c.num_heads, levels);
  else
    r.ints("attention_head_dim", &c.num_heads, levels);
  MACRO_TRY(r.status());
  auto bad = [&](const std::string& field, const std::string& expected, const std::string& found) {
    return Status::error(origin + ": field '" + field + "': expected " + expected + ", found " + found);
  };
  if (levels == 0) return bad("block_out_channels", "at least one level", "none");
  if (c.down_block_types.size() != levels)
    return bad("down_block_types", std::to_string(levels) + " entries (one per level)",
               std::to_string(c.down_block_types.size()));
  if (c.up_block_types.size() != levels)
    return bad("up_block_types", std::to_string(levels) + " entries (one per level)",
               std::to_string(c.up_block_types.size()));
  if (c.num_heads.size() != levels)
    return bad("attention_head_dim", std::to_string(levels) + " head counts",
               std::to_string(c.num_heads.size()));
  for (size_t i = 0; i < levels; ++i) {
    const std::string& d = c.down_block_types[i];
    const std::string& u = c.up_block_types[i];
    if (d != "CrossAttnDownBlock2D" && d != "DownBlock2D")
      return bad("down_block_types[" + std::to_string(i) + "]", "CrossAttnDownBlock2D or DownBlock2D", d);
    if (u != "CrossAttnUpBlock2D" && u != "UpBlock2D")
      return bad("up_block_types[" + std::to_string(i) + "]", "CrossAttnUpBlock2D or UpBlock2D", u);
    if (c.block_out_channels[i] % c.norm_num_groups != 0)
      return bad("block_out_channels[" + std::to_string(i) + "]",
                 "a multiple of norm_num_groups " + std::to_string(c.norm_num_groups),
                 std::to_string(c.block_out_channels[i]));
    if (c.block_out_channels[i] % c.num_heads[i] != 0)
      return bad("attention_head_dim[" + std::to_string(i) + "]",
                 "a head count dividing " + std::to_string(c.block_out_channels[i]),
                 std::to_string(c.num_heads[i]));
  }
  if (!c.use_linear_projection)
    return bad("use_linear_projection", "true (SD 2.x linear projections)", "false");
  if (j.contains("act_fn") && j["act_fn"] != "silu")
    return bad("act_fn", "\"silu\"", j["act_fn"].dump());
  return c;
}

Result<VaeConfig> parse_vae_config(const std::string& text, const std::string& origin) {
  MACRO_ASSIGN_OR_RETURN(json j, parse(text, origin));
  VaeConfig c;
  Reader r{j, origin, {}};
  r.integer("in_channels", &c.in_channels, 1);
  r.integer("out_channels", &c.out_channels, 1);
  r.ints("block_out_channels", &c.block_out_channels, 0);
  r.integer("layers_per_block", &c.layers_per_block, 1, 16);
  r.integer("latent_channels", &c.latent_channels, 1);
  r.integer("norm_num_groups", &c.norm_num_groups, 1);
  r.number("scaling_factor", &c.scaling_factor);
  r.number("gamma", &c.gamma);
  r.boolean("ignore_skip", &c.ignore_skip);
  r.integer("lora_rank", &c.lora_rank, 0, 4096);
  std::vector<std::string> down, up;
  if (j.contains("down_block_types")) r.strings("down_block_types", &down);
  if (j.contains("up_block_types")) r.strings("up_block_types", &up);
  MACRO_TRY(r.status());
  for (const auto& d : down)
    if (d != "DownEncoderBlock2D")
      return Status::error(origin + ": field 'down_block_types': expected DownEncoderBlock2D, found " + d);
  for (const auto& u : up)
    if (u != "UpDecoderBlock2D")
      return Status::error(origin + ": field 'up_block_types': expected UpDecoderBlock2D, found " + u);
  if (c.block_out_channels.empty())
    return Status::error(origin + ": field 'block_out_channels': expected a list, found none");
  if (!down.empty() && down.size() != c.block_out_channels.size())
    return Status::error(origin + ": field 'down_block_types': expected one per level");
  // LoRA scale: explicit ratio, else alpha / r with PEFT's default alpha of 8.
  if (j.contains("lora_alpha_over_rank")) {
    r.number("lora_alpha_over_rank", &c.lora_scale);
  } else if (c.lora_rank > 0) {
    double alpha = 8.0;
    r.number("lora_alpha", &alpha);
    c.lora_scale = alpha / c.lora_rank;
  }
  MACRO_TRY(r.status());
  return c;
}

Result<ClipTextConfig> parse_clip_text_config(const std::string& text, const std::string& origin) {
  MACRO_ASSIGN_OR_RETURN(json j, parse(text, origin));
  ClipTextConfig c;
  Reader r{j, origin, {}};
  r.integer("hidden_size", &c.hidden_size, 1);
  r.integer("intermediate_size", &c.intermediate_size, 1);
  r.integer("num_attention_heads", &c.num_attention_heads, 1);
  r.integer("num_hidden_layers", &c.num_hidden_layers, 1, 1024);
  r.integer("max_position_embeddings", &c.max_position_embeddings, 1);
  r.integer("vocab_size", &c.vocab_size, 1, 1 << 24);
  r.string("hidden_act", &c.hidden_act);
  r.number("layer_norm_eps", &c.layer_norm_eps);
  MACRO_TRY(r.status());
  if (c.hidden_size % c.num_attention_heads != 0)
    return Status::error(origin + ": field 'num_attention_heads': expected a divisor of hidden_size " +
                         std::to_string(c.hidden_size) + ", found " +
                         std::to_string(c.num_attention_heads));
  if (c.hidden_act != "gelu" && c.hidden_act != "quick_gelu")
    return Status::error(origin + ": field 'hidden_act': expected gelu or quick_gelu, found " +
                         c.hidden_act);
  return c;
}

Result<UNetConfig> load_unet_config(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 1 << 20));
  return parse_unet_config(text, path);
}
Result<VaeConfig> load_vae_config(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 1 << 20));
  return parse_vae_config(text, path);
}
Result<ClipTextConfig> load_clip_text_config(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 1 << 20));
  return parse_clip_text_config(text, path);
}

Result<std::string> config_class_name(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 1 << 20));
  MACRO_ASSIGN_OR_RETURN(json j, parse(text, path));
  if (j.contains("_class_name") && j["_class_name"].is_string()) return j["_class_name"].get<std::string>();
  if (j.contains("architectures") && j["architectures"].is_array() && !j["architectures"].empty() &&
      j["architectures"][0].is_string())
    return j["architectures"][0].get<std::string>();
  return std::string();
}

}  // namespace macro::nets
