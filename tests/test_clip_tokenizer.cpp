// CLIP BPE tokenizer against OpenCLIP's ids for the real vocabulary (golden/clip/tokens.json).
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "attention/nets/clip_tokenizer.h"
#include "attention/runtime/file_io.h"
#include "test_support.h"

using namespace macro;

TEST_CASE("CLIP tokenizer reproduces the golden ids exactly", "[clip][tokenizer]") {
  const std::string dir = test::golden_dir() + "/clip";
  auto tok = nets::ClipTokenizer::load(dir + "/tokenizer");
  INFO(tok.status().message());
  REQUIRE(tok.is_ok());
  auto text = read_text_file(dir + "/tokens.json");
  REQUIRE(text.is_ok());
  auto golden = nlohmann::json::parse(*text);
  REQUIRE(golden["start_id"].get<int>() == tok->start_id());
  REQUIRE(golden["end_id"].get<int>() == tok->end_id());
  REQUIRE(golden["pad_id"].get<int>() == tok->pad_id());
  REQUIRE(golden["cases"].size() >= 5);
  for (const auto& c : golden["cases"]) {
    const std::string prompt = c["text"].get<std::string>();
    std::vector<int32_t> expected = c["ids"].get<std::vector<int32_t>>();
    INFO("prompt: " << prompt);
    REQUIRE(tok->encode(prompt) == expected);
  }
}

TEST_CASE("CLIP tokenizer: cleaning and truncation rules", "[clip][tokenizer]") {
  auto tok = nets::ClipTokenizer::load(test::golden_dir() + "/clip/tokenizer");
  INFO(tok.status().message());
  REQUIRE(tok.is_ok());
  // Case, whitespace and HTML entities do not change the ids.
  REQUIRE(tok->encode("Remove   Degradation") == tok->encode("remove degradation"));
  REQUIRE(tok->encode("a &amp; b") == tok->encode("a & b"));
  REQUIRE(tok->encode("a &amp;amp; b") == tok->encode("a & b"));  // unescaped twice
  // Long input: 77 ids, the end token last, no padding.
  std::string long_text;
  for (int i = 0; i < 200; ++i) long_text += "word ";
  auto ids = tok->encode(long_text);
  REQUIRE(ids.size() == 77);
  REQUIRE(ids.front() == tok->start_id());
  REQUIRE(ids.back() == tok->end_id());
  // Arbitrary bytes (invalid UTF-8, control characters) never crash and stay within the vocabulary.
  std::string junk = "\xff\xfe\x01 caf\xc3\xa9 \xe2\x82\xac 12";
  auto junk_ids = tok->encode(junk);
  REQUIRE(junk_ids.size() == 77);
  for (int32_t id : junk_ids) REQUIRE((id >= 0 && id < 49408));
}

TEST_CASE("CLIP tokenizer: bad tokenizer folders are reported by file", "[clip][tokenizer][badinput]") {
  test::TempDir dir("clip-bad");
  auto missing = nets::ClipTokenizer::load(dir.path);
  REQUIRE_FALSE(missing.is_ok());
  REQUIRE(missing.status().message().find("vocab.json") != std::string::npos);
  REQUIRE(write_file_atomic(dir.file("vocab.json"), "{not json").is_ok());
  REQUIRE(write_file_atomic(dir.file("merges.txt"), "#version: 0.2\na b\n").is_ok());
  auto bad_json = nets::ClipTokenizer::load(dir.path);
  REQUIRE_FALSE(bad_json.is_ok());
  REQUIRE(bad_json.status().message().find("vocab.json") != std::string::npos);
  REQUIRE(write_file_atomic(dir.file("vocab.json"),
                            R"({"!":0,"<|startoftext|>":1,"<|endoftext|>":2})").is_ok());
  REQUIRE(write_file_atomic(dir.file("merges.txt"), "#version: 0.2\nabc\n").is_ok());
  auto bad_merge = nets::ClipTokenizer::load(dir.path);
  REQUIRE_FALSE(bad_merge.is_ok());
  REQUIRE(bad_merge.status().message().find("merges.txt: line 2") != std::string::npos);
}
