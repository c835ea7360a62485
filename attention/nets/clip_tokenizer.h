// The CLIP byte-pair-encoding tokenizer (OpenCLIP SimpleTokenizer behaviour), loaded from a
// diffusers `tokenizer/` folder (vocab.json + merges.txt).
//
// encode(text) -> 77 ids: <start> tokens... <end>, padded with 0 (the id of "!", as SD 2.x /
// SD-Turbo pad), truncated to 77 keeping <end> last. Text cleaning: HTML entities unescaped
// (twice), whitespace runs collapsed to one space and trimmed, lower-cased. Pre-tokenisation splits
// into the special tokens, the contractions 's 't 're 've 'm 'll 'd, runs of letters, single
// digits, and runs of other non-space characters. Letters/digits outside ASCII and Latin-1 are
// classified by code-point range (an approximation of Unicode \p{L} / \p{N}; see
// docs/spec/difix-spec.md §1.3); ftfy's mojibake repair is not done.
#pragma once

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::nets {

class ClipTokenizer {
 public:
  static constexpr int kContextLength = 77;

  // dir holds vocab.json and merges.txt.
  static Result<ClipTokenizer> load(const std::string& dir);

  std::vector<int32_t> encode(const std::string& text) const;  // kContextLength ids
  // BPE ids of the text without start/end/padding.
  std::vector<int32_t> encode_tokens(const std::string& text) const;

  int32_t start_id() const { return start_id_; }
  int32_t end_id() const { return end_id_; }
  int32_t pad_id() const { return pad_id_; }

 private:
  std::vector<std::string> bpe(const std::string& word_unicode) const;

  std::unordered_map<std::string, int32_t> vocab_;
  std::unordered_map<std::string, int32_t> merge_rank_;  // "a b" -> rank
  std::string byte_to_unicode_[256];                     // UTF-8 of the byte's stand-in character
  int32_t start_id_ = 49406, end_id_ = 49407, pad_id_ = 0;
};

}  // namespace macro::nets
