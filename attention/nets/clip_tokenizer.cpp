#include "attention/nets/clip_tokenizer.h"

#include <algorithm>
#include <climits>
#include <nlohmann/json.hpp>
#include <sstream>

#include "attention/runtime/file_io.h"

namespace macro::nets {
namespace {

// ---- UTF-8 ----------------------------------------------------------------------------------------

std::string utf8_encode(uint32_t cp) {
  std::string out;
  if (cp < 0x80) {
    out += char(cp);
  } else if (cp < 0x800) {
    out += char(0xC0 | (cp >> 6));
    out += char(0x80 | (cp & 0x3F));
  } else if (cp < 0x10000) {
    out += char(0xE0 | (cp >> 12));
    out += char(0x80 | ((cp >> 6) & 0x3F));
    out += char(0x80 | (cp & 0x3F));
  } else {
    out += char(0xF0 | (cp >> 18));
    out += char(0x80 | ((cp >> 12) & 0x3F));
    out += char(0x80 | ((cp >> 6) & 0x3F));
    out += char(0x80 | (cp & 0x3F));
  }
  return out;
}

// Decodes UTF-8; invalid bytes become U+FFFD (each byte once), so any input is accepted.
std::vector<uint32_t> utf8_decode(const std::string& s) {
  std::vector<uint32_t> cps;
  size_t i = 0;
  while (i < s.size()) {
    unsigned char c = s[i];
    int len = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : (c >> 3) == 30 ? 4 : 0;
    uint32_t cp = len == 1 ? c : len == 2 ? (c & 0x1F) : len == 3 ? (c & 0x0F) : (c & 0x07);
    bool ok = len > 0 && i + len <= s.size();
    for (int k = 1; ok && k < len; ++k) {
      unsigned char cc = s[i + k];
      if ((cc >> 6) != 2) ok = false;
      cp = (cp << 6) | (cc & 0x3F);
    }
    if (!ok) {
      cps.push_back(0xFFFD);
      ++i;
    } else {
      cps.push_back(cp);
      i += len;
    }
  }
  return cps;
}

// ---- character classes (Unicode approximation, exact for ASCII and Latin-1) -------------------------

bool is_space(uint32_t c) {
  return c == ' ' || (c >= 0x09 && c <= 0x0D) || c == 0x1C || c == 0x1D || c == 0x1E || c == 0x1F ||
         c == 0x85 || c == 0xA0 || c == 0x1680 || (c >= 0x2000 && c <= 0x200A) || c == 0x2028 ||
         c == 0x2029 || c == 0x202F || c == 0x205F || c == 0x3000;
}

bool is_number(uint32_t c) {
  if (c >= '0' && c <= '9') return true;
  if (c == 0xB2 || c == 0xB3 || c == 0xB9 || (c >= 0xBC && c <= 0xBE)) return true;
  // Decimal digits of other scripts (Arabic-Indic, Devanagari, fullwidth, ...): common blocks.
  static const uint32_t kDigitStarts[] = {0x660, 0x6F0, 0x966, 0x9E6, 0xA66, 0xAE6, 0xB66, 0xBE6,
                                          0xC66, 0xCE6, 0xD66, 0xE50, 0xED0, 0xF20, 0xFF10};
  for (uint32_t s : kDigitStarts)
    if (c >= s && c < s + 10) return true;
  return (c >= 0x2160 && c <= 0x2188) || (c >= 0x2460 && c <= 0x249B) || (c >= 0x3007 && c <= 0x3007);
}

bool is_letter(uint32_t c) {
  if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z')) return true;
  if (c < 0x80) return false;
  if (c < 0x100) return c == 0xAA || c == 0xB5 || c == 0xBA || (c >= 0xC0 && c != 0xD7 && c != 0xF7);
  if (is_space(c) || is_number(c)) return false;
  // Punctuation and symbol blocks are not letters; everything else above Latin-1 is treated as one.
  if ((c >= 0x2000 && c <= 0x2BFF) || (c >= 0x3000 && c <= 0x303F) || (c >= 0xFE30 && c <= 0xFE4F) ||
      (c >= 0xFF00 && c <= 0xFF20) || (c >= 0xFF3B && c <= 0xFF40) || (c >= 0xFF5B && c <= 0xFF65) ||
      (c >= 0x1F000 && c <= 0x1FAFF) || (c >= 0xE000 && c <= 0xF8FF) || c == 0xFFFD ||
      (c >= 0x0300 && c <= 0x036F) || c == 0x37E || c == 0x387 || (c >= 0x55A && c <= 0x55F) ||
      c == 0x589 || (c >= 0x5BE && c <= 0x5C7 && c != 0x5C0) || c == 0x60C || c == 0x61B ||
      c == 0x61F || c == 0x6D4 || c == 0x964 || c == 0x965)
    return false;
  return true;
}

uint32_t to_lower(uint32_t c) {
  if (c >= 'A' && c <= 'Z') return c + 32;
  if (c >= 0xC0 && c <= 0xDE && c != 0xD7) return c + 32;
  if (c >= 0x391 && c <= 0x3A9 && c != 0x3A2) return c + 32;  // Greek
  if (c >= 0x410 && c <= 0x42F) return c + 32;                 // Cyrillic
  if (c >= 0x400 && c <= 0x40F) return c + 80;
  if (c >= 0x100 && c <= 0x17F && c != 0x130 && c != 0x138 && c != 0x149 && c != 0x178) {
    // Latin Extended-A pairs: even upper / odd lower, except the 0x139-0x148 and 0x179-0x17E runs.
    bool odd_upper = (c >= 0x139 && c <= 0x148) || (c >= 0x179 && c <= 0x17E);
    if (odd_upper ? (c & 1) : !(c & 1)) return c + 1;
  }
  if (c == 0x178) return 0xFF;
  if (c >= 0xFF21 && c <= 0xFF3A) return c + 32;  // fullwidth
  return c;
}

// ---- text cleaning ---------------------------------------------------------------------------------

std::string html_unescape(const std::string& s) {
  static const std::pair<const char*, const char*> kNamed[] = {
      {"amp", "&"}, {"lt", "<"}, {"gt", ">"}, {"quot", "\""}, {"apos", "'"}, {"nbsp", "\xC2\xA0"}};
  std::string out;
  for (size_t i = 0; i < s.size();) {
    if (s[i] == '&') {
      size_t semi = s.find(';', i + 1);
      if (semi != std::string::npos && semi - i <= 10) {
        std::string ent = s.substr(i + 1, semi - i - 1);
        bool done = false;
        if (!ent.empty() && ent[0] == '#') {
          bool hex = ent.size() > 1 && (ent[1] == 'x' || ent[1] == 'X');
          std::string digits = ent.substr(hex ? 2 : 1);
          bool valid = !digits.empty() && digits.size() <= 7 &&
                       std::all_of(digits.begin(), digits.end(), [&](char ch) {
                         return hex ? std::isxdigit(static_cast<unsigned char>(ch))
                                    : std::isdigit(static_cast<unsigned char>(ch));
                       });
          if (valid) {
            unsigned long cp = std::stoul(digits, nullptr, hex ? 16 : 10);
            if (cp > 0 && cp < 0x110000 && !(cp >= 0xD800 && cp <= 0xDFFF)) {
              out += utf8_encode(static_cast<uint32_t>(cp));
              done = true;
            }
          }
        } else {
          for (const auto& [name, value] : kNamed) {
            if (ent == name) {
              out += value;
              done = true;
              break;
            }
          }
        }
        if (done) {
          i = semi + 1;
          continue;
        }
      }
    }
    out += s[i++];
  }
  return out;
}

// Unescape twice, collapse whitespace, trim, lower-case; returns code points.
std::vector<uint32_t> clean(const std::string& text) {
  std::vector<uint32_t> cps = utf8_decode(html_unescape(html_unescape(text)));
  std::vector<uint32_t> out;
  bool pending_space = false;
  for (uint32_t c : cps) {
    if (is_space(c)) {
      pending_space = !out.empty();
      continue;
    }
    if (pending_space) out.push_back(' ');
    pending_space = false;
    out.push_back(to_lower(c));
  }
  return out;
}

// Pre-tokenisation: special tokens, contractions, letter runs, single digits, other runs.
std::vector<std::string> pre_tokenize(const std::vector<uint32_t>& cps) {
  std::vector<std::string> words;
  // The regex's literal alternatives, in its order: special tokens, then contractions.
  static const char* kLiterals[] = {"<|startoftext|>", "<|endoftext|>", "<start_of_text>",
                                    "<end_of_text>", "'s", "'t", "'re", "'ve", "'m", "'ll", "'d"};
  auto matches = [&](size_t at, const char* lit) {
    size_t n = std::char_traits<char>::length(lit);
    if (at + n > cps.size()) return false;
    for (size_t k = 0; k < n; ++k)
      if (cps[at + k] != static_cast<unsigned char>(lit[k])) return false;
    return true;
  };
  size_t i = 0;
  while (i < cps.size()) {
    if (is_space(cps[i])) {
      ++i;
      continue;
    }
    bool matched = false;
    for (const char* lit : kLiterals) {
      if (matches(i, lit)) {
        words.emplace_back(lit);
        i += std::char_traits<char>::length(lit);
        matched = true;
        break;
      }
    }
    if (matched) continue;
    std::string w;
    if (is_letter(cps[i])) {
      while (i < cps.size() && is_letter(cps[i])) w += utf8_encode(cps[i++]);
    } else if (is_number(cps[i])) {
      w = utf8_encode(cps[i++]);
    } else {
      // [^\s\p{L}\p{N}]+ : a run of "other" characters. The regex alternation tries the earlier
      // branches only at the start of a match, so a run continues through apostrophes.
      while (i < cps.size() && !is_space(cps[i]) && !is_letter(cps[i]) && !is_number(cps[i]))
        w += utf8_encode(cps[i++]);
    }
    words.push_back(std::move(w));
  }
  return words;
}

}  // namespace

Result<ClipTokenizer> ClipTokenizer::load(const std::string& dir) {
  ClipTokenizer tok;
  const std::string vocab_path = dir + "/vocab.json";
  const std::string merges_path = dir + "/merges.txt";
  MACRO_ASSIGN_OR_RETURN(std::string vocab_text, read_text_file(vocab_path, 64ull << 20));
  nlohmann::json vocab = nlohmann::json::parse(vocab_text, nullptr, false);
  if (vocab.is_discarded() || !vocab.is_object())
    return Status::error(vocab_path + ": expected a JSON object of token -> id, found " +
                         (vocab.is_discarded() ? std::string("malformed JSON")
                                               : std::string("a JSON ") + vocab.type_name()));
  for (auto it = vocab.begin(); it != vocab.end(); ++it) {
    if (!it.value().is_number_integer() || it.value().get<int64_t>() < 0 ||
        it.value().get<int64_t>() > INT32_MAX)
      return Status::error(vocab_path + ": token '" + it.key() + "': expected a non-negative id");
    tok.vocab_[it.key()] = it.value().get<int32_t>();
  }
  MACRO_ASSIGN_OR_RETURN(std::string merges_text, read_text_file(merges_path, 64ull << 20));
  std::istringstream lines(merges_text);
  std::string line;
  int rank = 0, line_no = 0;
  while (std::getline(lines, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || (line_no == 1 && line.rfind("#version", 0) == 0)) continue;
    size_t sp = line.find(' ');
    if (sp == std::string::npos || sp == 0 || sp + 1 >= line.size() ||
        line.find(' ', sp + 1) != std::string::npos)
      return Status::error(merges_path + ": line " + std::to_string(line_no) +
                           ": expected two symbols separated by one space, found '" + line + "'");
    tok.merge_rank_.emplace(line, rank++);
  }
  // The byte stand-ins: printable Latin-1 bytes map to themselves, the rest to U+0100 upwards.
  int n = 0;
  for (int b = 0; b < 256; ++b) {
    bool printable = (b >= '!' && b <= '~') || (b >= 0xA1 && b <= 0xAC) || (b >= 0xAE && b <= 0xFF);
    tok.byte_to_unicode_[b] = utf8_encode(printable ? b : 256 + n++);
  }
  // Special tokens: Hugging Face spells them <|startoftext|>, OpenCLIP <start_of_text>.
  auto special = [&](const char* hf, const char* openclip, int32_t* id) -> Status {
    if (tok.vocab_.count(hf)) *id = tok.vocab_.at(hf);
    else if (tok.vocab_.count(openclip)) *id = tok.vocab_.at(openclip);
    else return Status::error(vocab_path + ": missing the token '" + hf + "' (or '" + openclip + "')");
    return Status::ok();
  };
  MACRO_TRY(special("<|startoftext|>", "<start_of_text>", &tok.start_id_));
  MACRO_TRY(special("<|endoftext|>", "<end_of_text>", &tok.end_id_));
  if (!tok.vocab_.count("!")) return Status::error(vocab_path + ": missing the padding token '!'");
  tok.pad_id_ = tok.vocab_.at("!");
  return tok;
}

std::vector<std::string> ClipTokenizer::bpe(const std::string& word) const {
  // Symbols: the word's UTF-8 characters, "</w>" appended to the last one.
  std::vector<std::string> syms;
  for (uint32_t cp : utf8_decode(word)) syms.push_back(utf8_encode(cp));
  if (syms.empty()) return syms;
  syms.back() += "</w>";
  while (syms.size() > 1) {
    int best = INT32_MAX;
    size_t best_i = 0;
    for (size_t i = 0; i + 1 < syms.size(); ++i) {
      auto it = merge_rank_.find(syms[i] + " " + syms[i + 1]);
      if (it != merge_rank_.end() && it->second < best) {
        best = it->second;
        best_i = i;
      }
    }
    if (best == INT32_MAX) break;
    // Merge every occurrence of the best pair, left to right.
    const std::string a = syms[best_i], b = syms[best_i + 1];
    std::vector<std::string> merged;
    for (size_t i = 0; i < syms.size();) {
      if (i + 1 < syms.size() && syms[i] == a && syms[i + 1] == b) {
        merged.push_back(a + b);
        i += 2;
      } else {
        merged.push_back(syms[i++]);
      }
    }
    syms = std::move(merged);
  }
  return syms;
}

std::vector<int32_t> ClipTokenizer::encode_tokens(const std::string& text) const {
  std::vector<int32_t> ids;
  for (const std::string& word : pre_tokenize(clean(text))) {
    if (word == "<|startoftext|>" || word == "<start_of_text>") {
      ids.push_back(start_id_);
      continue;
    }
    if (word == "<|endoftext|>" || word == "<end_of_text>") {
      ids.push_back(end_id_);
      continue;
    }
    std::string mapped;
    for (unsigned char byte : word) mapped += byte_to_unicode_[byte];
    for (const std::string& sym : bpe(mapped)) {
      auto it = vocab_.find(sym);
      // Every byte-level symbol is in the real vocabulary; a custom one may lack it: skip.
      if (it != vocab_.end()) ids.push_back(it->second);
    }
  }
  return ids;
}

std::vector<int32_t> ClipTokenizer::encode(const std::string& text) const {
  std::vector<int32_t> ids;
  ids.push_back(start_id_);
  for (int32_t id : encode_tokens(text)) ids.push_back(id);
  ids.push_back(end_id_);
  if (ids.size() > size_t(kContextLength)) {
    ids.resize(kContextLength);
    ids.back() = end_id_;
  }
  ids.resize(kContextLength, pad_id_);
  return ids;
}

}  // namespace macro::nets
