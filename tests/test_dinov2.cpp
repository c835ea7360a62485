// The DINOv2 distance (enhance/feature_metrics.*): torch-bilinear input resize against
// hand-computed values, full-size synthetic timm vit_small_patch14_dinov2 weights (exact names and
// shapes, seeded random, written as safetensors) through the metric and the CLI, the model cache,
// and loader errors that name the tensors.
#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/metrics/feature_metrics.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;

namespace {

using Weights = std::map<std::string, nets::OverrideTensor>;

// The synthetic checkpoint (timm names and shapes), optionally edited, written to dir/name.
std::string write_dinov2(const test::TempDir& dir, const std::string& name,
                         const std::function<void(Weights&)>& edit = {}) {
  Weights ws = nets::vit_random_weights(dinov2_config(), 2024);
  if (edit) edit(ws);
  std::vector<TensorToWrite> t;
  for (const auto& [n, ten] : ws) t.push_back({n, DType::kF32, ten.shape, ten.values.data()});
  const std::string path = dir.file(name);
  REQUIRE(write_safetensors(path, t).is_ok());
  return path;
}

// A smooth colour pattern and a perturbed copy.
gs::Image pattern(int w, int h, float shift) {
  gs::Image im(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        im.at(y, x, c) = float(0.5 + 0.4 * std::sin(0.11 * x + 0.07 * y + c + shift));
  return im;
}

std::string slurp(const std::string& path) {
  auto t = read_text_file(path);
  return t ? *t : std::string();
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

TEST_CASE("dinov2: bilinear resize is torch's align_corners=False antialias=False", "[dinov2]") {
  // pixel (y, x, c) = row[y] + (c + 1) * col[x]: bilinear is linear, so the result is
  // resample(row)[y] + (c + 1) * resample(col)[x].
  const float row[2] = {0.f, 10.f};
  const float col[5] = {0.f, 1.f, 2.f, 4.f, 8.f};
  gs::Image im(5, 2, 3);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 5; ++x)
      for (int c = 0; c < 3; ++c) im.at(y, x, c) = row[y] + float(c + 1) * col[x];
  // Height 2 -> 4 (scale 0.5): source y = (o + 0.5) / 2 - 0.5 = -0.25 (clamped to 0), 0.25, 0.75,
  // 1.25 (upper neighbour clamped): 0, 2.5, 7.5, 10.
  const double ry[4] = {0.0, 2.5, 7.5, 10.0};
  // Width 5 -> 3 (scale 5/3, no antialias): source x = 1/3, 2, 11/3:
  // (2/3) 0 + (1/3) 1 = 1/3; 2; (1/3) 4 + (2/3) 8 = 20/3.
  const double rx[3] = {1.0 / 3.0, 2.0, 20.0 / 3.0};
  const std::vector<float> out = resize_bilinear_chw(im, 4, 3);
  REQUIRE(out.size() == 3u * 4u * 3u);
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 3; ++x)
        CHECK(out[size_t((c * 4 + y) * 3 + x)] == Approx(ry[y] + (c + 1) * rx[x]).margin(2e-6));
  // Same size: the identity.
  const std::vector<float> same = resize_bilinear_chw(im, 2, 5);
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 5; ++x) CHECK(same[size_t((c * 2 + y) * 5 + x)] == im.at(y, x, c));
  // The DINOv2 input: 518 x 518, ImageNet mean/std per channel.
  gs::Image flat(7, 3, 3);
  for (size_t i = 0; i < flat.data.size(); ++i) flat.data[i] = 0.25f * float(i % 3 + 1);
  const std::vector<float> x = dinov2_input(flat);
  REQUIRE(x.size() == 3u * 518u * 518u);
  for (int c = 0; c < 3; ++c) {
    const double want = (0.25 * (c + 1) - kDinov2Mean[c]) / kDinov2Std[c];
    CHECK(x[size_t(c) * 518 * 518] == Approx(want).margin(1e-6));
    CHECK(x[size_t(c) * 518 * 518 + 518 * 518 - 1] == Approx(want).margin(1e-6));
  }
}

TEST_CASE("dinov2: the config is timm vit_small_patch14_dinov2 with its exact tensor list",
          "[dinov2]") {
  // Written from timm (models/vision_transformer.py): vit_small_patch14_dinov2 = patch 14, D 384,
  // 12 blocks, 6 heads, init_values 1e-5 (LayerScale), mlp_ratio 4, qkv_bias True, pre_norm False
  // (so the patch conv has a bias and norm_pre is Identity), global_pool 'token' (fc_norm Identity,
  // `norm` before the pool); fixed_input_size makes img_size the cfg's 518 (37 x 37 grid); timm's
  // LayerNorm eps 1e-6; act nn.GELU (exact erf).
  const nets::VitConfig c = dinov2_config();
  CHECK(c.prefix.empty());
  CHECK(c.width == 384);
  CHECK(c.depth == 12);
  CHECK(c.heads == 6);
  CHECK(c.mlp_hidden == 1536);
  CHECK(c.patch == 14);
  CHECK(c.grid_h == 37);
  CHECK(c.grid_w == 37);
  CHECK(c.ln_eps == 1e-6f);
  CHECK(c.act == nets::VitAct::kGelu);
  CHECK(c.layer_scale);
  CHECK(c.qkv_bias);
  CHECK(c.patch_bias);
  CHECK_FALSE(c.norm_pre);
  CHECK(c.final_norm);
  CHECK(c.proj_dim == 0);
  CHECK(c.out_dim() == 384);
  CHECK(kDinov2Size == 518);
  CHECK(kDinov2Size == c.grid_h * c.patch);  // the stored pos_embed is used as is
  CHECK(kDinov2Mean[0] == 0.485f);
  CHECK(kDinov2Mean[1] == 0.456f);
  CHECK(kDinov2Mean[2] == 0.406f);
  CHECK(kDinov2Std[0] == 0.229f);
  CHECK(kDinov2Std[1] == 0.224f);
  CHECK(kDinov2Std[2] == 0.225f);
  // The timm state_dict names and shapes, hand-listed: the loader asks for exactly these.
  std::map<std::string, std::vector<int64_t>> want = {{"cls_token", {1, 1, 384}},
                                                      {"pos_embed", {1, 1370, 384}},
                                                      {"patch_embed.proj.weight", {384, 3, 14, 14}},
                                                      {"patch_embed.proj.bias", {384}},
                                                      {"norm.weight", {384}},
                                                      {"norm.bias", {384}}};
  for (int i = 0; i < 12; ++i) {
    const std::string b = "blocks." + std::to_string(i) + ".";
    for (const char* n : {"norm1.weight", "norm1.bias", "norm2.weight", "norm2.bias", "ls1.gamma",
                          "ls2.gamma", "attn.proj.bias", "mlp.fc2.bias"})
      want[b + n] = {384};
    want[b + "attn.qkv.weight"] = {1152, 384};
    want[b + "attn.qkv.bias"] = {1152};
    want[b + "attn.proj.weight"] = {384, 384};
    want[b + "mlp.fc1.weight"] = {1536, 384};
    want[b + "mlp.fc1.bias"] = {1536};
    want[b + "mlp.fc2.weight"] = {384, 1536};
  }
  REQUIRE(want.size() == 174u);
  const Weights got = nets::vit_random_weights(c, 1);
  std::map<std::string, std::vector<int64_t>> got_shapes;
  for (const auto& [n, t] : got) got_shapes[n] = t.shape;
  CHECK(got_shapes == want);
}

TEST_CASE("dinov2: full-size synthetic weights give finite and self-zero and symmetric distances",
          "[dinov2]") {
  test::TempDir dir("dinov2-full");
  const std::string path = write_dinov2(dir, "vit_small_patch14_dinov2.safetensors");
  const gs::Image a = pattern(96, 64, 0.f), b = pattern(96, 64, 0.8f);
  auto t0 = std::chrono::steady_clock::now();
  auto model = load_dinov2(path);
  INFO((model.is_ok() ? "" : model.status().message()));
  REQUIRE(model.is_ok());
  std::printf("dinov2: load %.2f s, %.1f MiB packed\n", seconds_since(t0),
              double((*model)->weight_bytes()) / (1 << 20));
  // Cached: the same object again, also when asked from several threads at once.
  auto again = load_dinov2(path);
  REQUIRE(again.is_ok());
  CHECK(again->get() == model->get());
  {
    ThreadPool pool(2);
    std::vector<const nets::VitModel*> seen(4, nullptr);
    pool.parallel_for(
        4,
        [&](size_t b, size_t e, int) {
          for (size_t i = b; i < e; ++i) {
            auto m = load_dinov2(path);
            if (m) seen[i] = m->get();
          }
        },
        1);
    for (const nets::VitModel* p : seen) CHECK(p == model->get());
  }

  const Dinov2CacheStats s0 = dinov2_cache_stats();
  t0 = std::chrono::steady_clock::now();
  const MetricValue d_ab = dinov2_distance(a, b, path);
  std::printf("dinov2: distance of one pair (2 embeddings at 518x518) %.2f s\n", seconds_since(t0));
  INFO(d_ab.reason);
  REQUIRE(d_ab.computed);
  CHECK(d_ab.name == "dinov2");
  CHECK(std::isfinite(d_ab.value));
  CHECK(d_ab.value > 1e-6);  // different images, different embeddings
  CHECK(d_ab.value < 2.0);
  const Dinov2CacheStats s1 = dinov2_cache_stats();
  CHECK(s1.computed - s0.computed == 2);
  // Both embeddings are cached now: the same pair again, reversed, and a against itself cost no
  // forward. Symmetric and self-zero.
  const MetricValue d_ba = dinov2_distance(b, a, path);
  const MetricValue d_aa = dinov2_distance(a, a, path);
  REQUIRE(d_ba.computed);
  REQUIRE(d_aa.computed);
  CHECK(d_ba.value == d_ab.value);
  CHECK(std::abs(d_aa.value) <= 1e-6);
  const Dinov2CacheStats s2 = dinov2_cache_stats();
  CHECK(s2.computed == s1.computed);
  CHECK(s2.hits - s1.hits == 4);
  // Uncached forwards: deterministic (bit-identical embeddings, so d(x, x) = 0 without the cache
  // too) and the metric is 1 - cos of exactly these embeddings.
  auto ea = dinov2_embedding(**model, a);
  auto ea2 = dinov2_embedding(**model, a);
  auto eb = dinov2_embedding(**model, b);
  REQUIRE(ea.is_ok());
  REQUIRE(ea2.is_ok());
  REQUIRE(eb.is_ok());
  REQUIRE(ea->size() == 384u);
  CHECK(*ea == *ea2);
  // The embedding is the ViT's pooled CLS of the 518x518 normalised input, nothing else.
  const std::vector<float> xa = dinov2_input(a);
  auto direct = (*model)->forward(xa.data(), kDinov2Size, kDinov2Size, &ThreadPool::global());
  REQUIRE(direct.is_ok());
  CHECK(direct->cls == *ea);
  CHECK(cosine_distance(*ea, *ea2) == Approx(0.0).margin(1e-12));
  CHECK(cosine_distance(*ea, *eb) == cosine_distance(*eb, *ea));
  CHECK(std::abs(cosine_distance(*ea, *eb) - d_ab.value) <= 1e-12);
  // A replaced file (new modification time) is loaded again.
  const std::string path2 = write_dinov2(dir, "vit_small_patch14_dinov2.safetensors",
                                         [](Weights& ws) { ws["norm.bias"].values[0] += 1.0f; });
  REQUIRE(path2 == path);
  auto reloaded = load_dinov2(path);
  REQUIRE(reloaded.is_ok());
  CHECK(reloaded->get() != model->get());
}

TEST_CASE("dinov2: loader errors name the tensors and are 'not computed' and never a number",
          "[dinov2]") {
  test::TempDir dir("dinov2-bad");
  const gs::Image a = pattern(32, 32, 0.f);
  // Absent: the existing reason, with the path.
  const MetricValue none = dinov2_distance(a, a, dir.file("absent.safetensors"));
  CHECK_FALSE(none.computed);
  CHECK_THAT(none.reason, Catch::Contains("weights not supplied") &&
                              Catch::Contains(dir.file("absent.safetensors")));
  // Not a safetensors file.
  REQUIRE(write_file_atomic(dir.file("junk.safetensors"), std::string(64, 'x')).is_ok());
  const MetricValue junk = dinov2_distance(a, a, dir.file("junk.safetensors"));
  CHECK_FALSE(junk.computed);
  CHECK_THAT(junk.reason, Catch::Contains("junk.safetensors"));
  // torch.hub / timm extras are accepted; a missing, an extra and a mis-shaped tensor are named.
  const std::string bad = write_dinov2(dir, "bad.safetensors", [](Weights& ws) {
    ws["mask_token"] = {{1, 384}, std::vector<float>(384, 0.f)};
    ws["head.weight"] = {{1000, 384}, std::vector<float>(1000 * 384, 0.f)};
    ws["head.bias"] = {{1000}, std::vector<float>(1000, 0.f)};
    ws.erase("blocks.11.ls2.gamma");
    ws["blocks.12.norm1.weight"] = {{384}, std::vector<float>(384, 1.f)};
    ws["pos_embed"] = {{1, 257, 384}, std::vector<float>(257 * 384, 0.f)};
  });
  const MetricValue m = dinov2_distance(a, a, bad);
  CHECK_FALSE(m.computed);
  CHECK_THAT(m.reason, Catch::Contains("bad.safetensors") &&
                           Catch::Contains("missing (blocks.11.ls2.gamma [384])") &&
                           Catch::Contains("pos_embed: expected [1,1370,384], found [1,257,384]") &&
                           Catch::Contains("unused (blocks.12.norm1.weight)"));
  CHECK_THAT(m.reason, !Catch::Contains("head.weight") && !Catch::Contains("mask_token"));
  auto direct = load_dinov2(bad);
  REQUIRE_FALSE(direct.is_ok());
  CHECK_THAT(direct.status().message(), Catch::Contains("DINOv2"));
  // A bad image is refused by name, not computed.
  auto good = write_dinov2(dir, "good.safetensors", [](Weights& ws) {
    ws["mask_token"] = {{1, 384}, std::vector<float>(384, 0.f)};  // torch.hub layout
  });
  const MetricValue empty = dinov2_distance(gs::Image(), a, good);
  CHECK_FALSE(empty.computed);
  CHECK_THAT(empty.reason, Catch::Contains("prediction") && Catch::Contains("RGB image"));
}

TEST_CASE("dinov2: macro metrics prints a number with --dinov2 and 'not computed' without",
          "[dinov2]") {
  test::TempDir dir("dinov2-cli");
  const std::string path = write_dinov2(dir, "w.safetensors");
  const std::string img = test::shared_dir() + "/images";
  const std::string out = dir.file("out.txt"), err = dir.file("err.txt");
  const std::string base = "env -u MACRO_QUIET " + test::macro_exe() + " metrics --pred " + img +
                           "/ex_p0.png --gt " + img + "/ex_ref.png --lpips-backbone " +
                           dir.file("none.safetensors");
  REQUIRE(test::run_command(base + " --dinov2 " + path + " --json >" + out + " 2>" + err) == 0);
  const nlohmann::json j = nlohmann::json::parse(slurp(out));
  INFO(slurp(out) << slurp(err));
  REQUIRE(j["dinov2"].is_number());
  const double v = j["dinov2"].get<double>();
  CHECK(std::isfinite(v));
  CHECK(v > 0.0);
  CHECK(v < 2.0);
  // Text form: "dinov2: <number>".
  REQUIRE(test::run_command(base + " --dinov2 " + path + " >" + out + " 2>" + err) == 0);
  CHECK_THAT(slurp(out), Catch::Contains("dinov2: 0.") || Catch::Contains("dinov2: 1."));
  // Without the file.
  REQUIRE(test::run_command(base + " --dinov2 " + dir.file("absent.safetensors") + " >" + out +
                            " 2>" + err) == 0);
  CHECK_THAT(slurp(out), Catch::Contains("dinov2: not computed: weights not supplied"));
}

TEST_CASE("dinov2: bench run records the distance per pair and the report shows it",
          "[dinov2][cli]") {
  test::TempDir dir("dinov2-bench");
  const std::string weights = write_dinov2(dir, "dinov2.safetensors");
  const std::string exe = test::macro_exe();
  const auto sh = [&](const std::string& args) {
    return std::system(
        (exe + " bench " + args + " --quiet > " + dir.file("out.txt") + " 2>&1").c_str());
  };
  REQUIRE(sh("synth --size tiny --no-gt-ply --out " + dir.file("root")) == 0);
  REQUIRE(sh("run --root " + dir.file("root") + " --methods 3dgs --limit 1 --dinov2 " + weights +
             " --dreamsim " + dir.file("absent.safetensors") + " --results " +
             dir.file("r.jsonl")) == 0);
  auto records = read_records(dir.file("r.jsonl"));
  REQUIRE(records.is_ok());
  REQUIRE(records->size() == 1);
  const BenchRecord& r = records->front();
  REQUIRE(r.ok);
  bool dino = false, dream = false;
  for (const MetricValue& m : r.metrics) {
    if (m.name == "dinov2") {
      dino = true;
      CHECK(m.computed);
      CHECK(std::isfinite(m.value));
      CHECK(m.value > 0.0);  // a blurry render is not its ground truth
      CHECK(m.value <= 2.0);
    }
    if (m.name == "dreamsim") {
      dream = true;
      CHECK_FALSE(m.computed);
      CHECK_THAT(m.reason, Catch::Contains("weights not supplied") &&
                               Catch::Contains("absent.safetensors"));
    }
  }
  CHECK(dino);
  CHECK(dream);
  REQUIRE(sh("report --results " + dir.file("r.jsonl") + " --out " + dir.file("report")) == 0);
  const std::string md = slurp(dir.file("report/table.md"));
  CHECK(md.find("DINOv2") != std::string::npos);
}
