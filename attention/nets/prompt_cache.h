// The text conditioning of a pipeline folder, computed once and cached on disk.
//
// Difix uses one fixed prompt ("remove degradation", docs/spec/difix-spec.md §1.3), so its CLIP
// embedding [1, 77, D] is computed once per pipeline folder (tokenizer/ + text_encoder/, always
// fp32: a one-off 45 GFLOP at SD-Turbo size) and stored as a small safetensors file:
//
//   <pipeline>/text_encoder/prompt_cache/<key>.safetensors        (preferred: beside the weights)
//   $XDG_CACHE_HOME/macro/prompt_cache/<key>.safetensors          (if the folder is not writable;
//   ($HOME/.cache when XDG_CACHE_HOME is unset)                     also searched when reading)
//
// <key> = 16 hex digits of a 64-bit FNV-1a hash over a format tag, the 77 token ids of the prompt,
// the text encoder's config.json text, and its weights file's path, size and modification time,
// so editing the prompt, the tokenizer or the weights gives a new key (stale files are left in
// place; delete the folder to reclaim them). The file holds `prompt_embedding` F32 [1, 77, D] and
// metadata {key, prompt, weights}; a file whose key, shape or values do not check out is ignored
// and rewritten. Writes are atomic (temporary + rename), so concurrent runs at worst both compute.
// A cache that cannot be written is not an error: the embedding is still returned (info.note says
// why nothing was stored).
#pragma once

#include <string>

#include "attention/runtime/status.h"
#include "attention/runtime/tensor.h"
#include "attention/runtime/thread_pool.h"

namespace macro::nets {

inline constexpr const char* kDifixPrompt = "remove degradation";

struct PromptCacheOptions {
  bool use_cache = true;  // false: always compute, never read or write
  std::string cache_dir;  // non-empty: use only this folder (tests, read-only installs)
};

struct PromptCacheInfo {
  bool hit = false;  // read from `path`
  std::string path;  // the cache file read or written; empty if none
  std::string note;  // why nothing was written, when that happened
};

// Does the folder have text_encoder/ (config.json + weights) and tokenizer/?
bool has_text_encoder(const std::string& pipeline_folder);

// The embedding [1, 77, D] of `prompt` for a pipeline folder (see above).
Result<Tensor> prompt_embedding(const std::string& pipeline_folder, const std::string& prompt,
                                ThreadPool* pool, const PromptCacheOptions& options = {},
                                PromptCacheInfo* info = nullptr);

// The cache key (16 hex digits) and the default cache folders, in search order.
Result<std::string> prompt_cache_key(const std::string& pipeline_folder, const std::string& prompt);
std::string prompt_cache_folder(const std::string& pipeline_folder);
std::string user_prompt_cache_folder();  // empty when neither XDG_CACHE_HOME nor HOME is set

}  // namespace macro::nets
