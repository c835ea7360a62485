// Fused attention and block-sparse masks (attention/runtime/attention.h, attention_mask.h):
// every path against a naive double-precision reference with materialised scores, ISA paths
// against the scalar twin, thread-count invariance, mask builders against dense masks and against
// the MACRO masks of the goldens.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "attention/runtime/attention.h"
#include "attention/runtime/attention_mask.h"
#include "attention/runtime/half.h"
#include "attention/runtime/io/safetensors.h"
#include "test_support.h"

using namespace macro;

namespace {

// A fused qkv buffer [n, 3C + pad] so q, k and v are strided slices, like the networks use.
struct Problem {
  int nq = 0, nk = 0, heads = 1, d = 16;
  float scale = 0;
  std::vector<float> qkv_q, qkv_kv;  // query rows and key rows (separate so nq != nk works)
  size_t stride = 0;
  const float* q() const { return qkv_q.data(); }
  const float* k() const { return qkv_kv.data() + size_t(heads) * d; }
  const float* v() const { return qkv_kv.data() + 2 * size_t(heads) * d; }
};

Problem make_problem(int nq, int nk, int heads, int d, uint32_t seed, float spread = 1.0f) {
  Problem p;
  p.nq = nq;
  p.nk = nk;
  p.heads = heads;
  p.d = d;
  p.scale = 1.0f / std::sqrt(float(d));
  p.stride = 3 * size_t(heads) * d + 5;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-spread, spread);
  p.qkv_q.resize(size_t(nq) * p.stride);
  p.qkv_kv.resize(size_t(std::max(nk, 1)) * p.stride);
  for (float& x : p.qkv_q) x = u(rng);
  for (float& x : p.qkv_kv) x = u(rng);
  return p;
}

AttentionArgs args_for(const Problem& p, std::vector<float>& out, const BlockSparseMask* mask,
                       bool causal = false) {
  out.assign(size_t(p.nq) * size_t(p.heads) * p.d + 3, -7.0f);  // poison, incl. a tail guard
  AttentionArgs a;
  a.q = p.q();
  a.k = p.k();
  a.v = p.v();
  a.out = out.data();
  a.q_stride = a.k_stride = a.v_stride = p.stride;
  a.out_stride = size_t(p.heads) * p.d;
  a.nq = p.nq;
  a.nk = p.nk;
  a.heads = p.heads;
  a.head_dim = p.d;
  a.scale = p.scale;
  a.causal = causal;
  a.mask = mask;
  return a;
}

float round_bf16(float x) {
  return bf16_to_f32(f32_to_bf16(x));
}

// Materialised scores in double; dense mask [nq, nk] (null = all allowed); empty rows -> 0.
// bf16: the reference of a bf16 request, the same maths on the kernel's rounded operands
// (bf16(scale log2(e) Q), bf16(K), bf16(V)). What is left between this and the kernel is the
// rounding of each probability to bf16 (relative <= 2^-8, so |out - ref| <= 2^-8 max|V| per
// output) and fp32 accumulation.
std::vector<float> reference(const Problem& p, const uint8_t* dense, bool causal,
                             bool bf16 = false) {
  const size_t c = size_t(p.heads) * p.d;
  const float s2 = p.scale * 1.4426950408889634f;  // scale log2(e), as the kernels pre-scale Q
  auto rq = [&](float q) { return bf16 ? double(round_bf16(q * s2)) / s2 : double(q); };
  auto rkv = [&](float x) { return bf16 ? double(round_bf16(x)) : double(x); };
  std::vector<float> out(size_t(p.nq) * c, 0.0f);
  std::vector<double> s(size_t(p.nk));
  for (int h = 0; h < p.heads; ++h)
    for (int i = 0; i < p.nq; ++i) {
      const float* q = p.q() + size_t(i) * p.stride + size_t(h) * p.d;
      double mx = -INFINITY;
      for (int j = 0; j < p.nk; ++j) {
        const bool ok = (!dense || dense[size_t(i) * p.nk + j]) && (!causal || j <= i);
        if (!ok) {
          s[size_t(j)] = -INFINITY;
          continue;
        }
        const float* k = p.k() + size_t(j) * p.stride + size_t(h) * p.d;
        double acc = 0;
        for (int e = 0; e < p.d; ++e) acc += rq(q[e]) * rkv(k[e]);
        s[size_t(j)] = acc * p.scale;
        mx = std::max(mx, s[size_t(j)]);
      }
      if (mx == -INFINITY) continue;
      double sum = 0;
      for (int j = 0; j < p.nk; ++j) sum += s[size_t(j)] = std::exp(s[size_t(j)] - mx);
      for (int e = 0; e < p.d; ++e) {
        double acc = 0;
        for (int j = 0; j < p.nk; ++j)
          acc += s[size_t(j)] * rkv(p.v()[size_t(j) * p.stride + size_t(h) * p.d + e]);
        out[size_t(i) * c + size_t(h) * p.d + e] = float(acc / sum);
      }
    }
  return out;
}

using test::supported_isas;

// Runs every supported path, checks against the reference and the scalar twin, returns the
// scalar result.
void check_all_paths(const Problem& p, const BlockSparseMask* mask, const uint8_t* dense,
                     bool causal, double tol = 2e-6) {
  const std::vector<float> ref = reference(p, dense, causal);
  std::vector<float> scalar_out;
  for (Isa isa : supported_isas()) {
    INFO("path " << isa_name(isa) << ", nq " << p.nq << ", nk " << p.nk << ", heads " << p.heads
                 << ", D " << p.d << (causal ? ", causal" : "") << (mask ? ", masked" : ""));
    std::vector<float> out;
    REQUIRE(attention_with_isa(args_for(p, out, mask, causal), isa).is_ok());
    const size_t n = ref.size();
    CHECK(out[n] == -7.0f);  // nothing written past the output
    const test::Diff diff = test::compare(out.data(), ref.data(), n);
    CHECK(diff.max_abs <= tol);
    CHECK(diff.rel_l2 <= tol);
    if (isa == Isa::kScalar) {
      scalar_out = out;
    } else {
      const test::Diff twin = test::compare(out.data(), scalar_out.data(), n);
      CHECK(twin.max_abs <= tol);
    }
  }
}

std::vector<uint8_t> random_dense(int nq, int nk, double density, uint32_t seed) {
  std::mt19937 rng(seed);
  std::bernoulli_distribution b(density);
  std::vector<uint8_t> m(size_t(nq) * nk);
  for (auto& x : m) x = b(rng);
  return m;
}

}  // namespace

TEST_CASE("attention matches a double reference without a mask", "[attention]") {
  struct Case {
    int nq, nk, heads, d;
  };
  const Case cases[] = {{1, 1, 1, 16},     {37, 53, 2, 16}, {130, 77, 3, 64}, {64, 64, 1, 64},
                        {200, 129, 2, 32}, {65, 300, 1, 8}, {33, 70, 2, 40},  {70, 45, 1, 24},
                        {20, 150, 1, 512}, {9, 5, 2, 3}};
  uint32_t seed = 1;
  for (const Case& c : cases)
    check_all_paths(make_problem(c.nq, c.nk, c.heads, c.d, seed++), nullptr, nullptr, false);
  // Peaked softmax (large logits) stresses the running max and rescaling.
  check_all_paths(make_problem(150, 200, 2, 64, 99, 3.0f), nullptr, nullptr, false, 1e-5);
}

TEST_CASE("attention with dense masks of random density", "[attention][mask]") {
  uint32_t seed = 10;
  for (double density : {0.03, 0.3, 0.9}) {
    for (bool group : {false, true}) {
      const int nq = 150, nk = 211;
      Problem p = make_problem(nq, nk, 2, 16, seed++);
      std::vector<uint8_t> dense = random_dense(nq, nk, density, seed++);
      for (int j = 0; j < nk; ++j) dense[size_t(7) * nk + j] = 0;  // a fully masked row
      auto mask = mask_from_dense(dense.data(), nq, nk, 0, group);
      REQUIRE(mask.is_ok());
      REQUIRE(mask->validate().is_ok());
      REQUIRE(mask->to_dense() == dense);
      int64_t ones = 0;
      for (uint8_t x : dense) ones += x;
      REQUIRE(mask->allowed_pairs() == ones);
      check_all_paths(p, &*mask, dense.data(), false);
    }
  }
}

TEST_CASE("dense masks with interleaved groups become block sparse when grouped",
          "[attention][mask]") {
  // Queries of 3 planes interleaved token by token; keys in 4 runs; rule: plane p sees key run p
  // and run 3. Ungrouped every tile outside run 3 is partial; grouped, only tiles at run edges are.
  const int nq = 1800, nk = 1500;
  std::vector<uint8_t> dense(size_t(nq) * nk);
  for (int i = 0; i < nq; ++i)
    for (int j = 0; j < nk; ++j) {
      const int run = j * 4 / nk;
      dense[size_t(i) * nk + j] = run == i % 3 || run == 3;
    }
  auto plain = mask_from_dense(dense.data(), nq, nk);
  auto grouped = mask_from_dense(dense.data(), nq, nk, 0, true);
  REQUIRE(plain.is_ok());
  REQUIRE(grouped.is_ok());
  REQUIRE(grouped->to_dense() == dense);
  INFO("plain: " << plain->partial_tiles() << " partial of " << plain->entries()
                 << "; grouped: " << grouped->partial_tiles() << " partial of "
                 << grouped->entries() << ", computed " << grouped->computed_pairs()
                 << " for allowed " << grouped->allowed_pairs());
  CHECK(plain->partial_tiles() * 4 >= plain->entries() * 3);
  CHECK(grouped->partial_tiles() * 3 < grouped->entries());
  CHECK(double(grouped->computed_pairs()) < 1.15 * double(grouped->allowed_pairs()));
  Problem p = make_problem(nq, nk, 1, 16, 5);
  check_all_paths(p, &*grouped, dense.data(), false);
}

// A MACRO mask's inputs: a close-up grid 20 x 30 with 3 planes in spatial blobs, 5 crops (one
// entirely invalid).
struct MacroMaskCase {
  int gh = 20, gw = 30, n = 600, planes = 3;
  std::vector<int32_t> closeup_plane = std::vector<int32_t>(600), crop_plane = {0, 1, 2, 0, 1};
  int crops = 5;
  std::vector<uint8_t> valid = std::vector<uint8_t>(5 * 600);
  MacroMaskCase() {
    for (int y = 0; y < gh; ++y)
      for (int x = 0; x < gw; ++x) closeup_plane[size_t(y * gw + x)] = ((x / 4) + (y / 3)) % planes;
    for (int c = 0; c < crops; ++c)
      for (int t = 0; t < n; ++t) valid[size_t(c) * n + t] = c != 4 && (t % gw) > 2 + c;
  }
};

TEST_CASE("structured MACRO masks equal their dense rule and are block sparse",
          "[attention][mask]") {
  const MacroMaskCase mc;
  const int n = mc.n, planes = mc.planes, crops = mc.crops;
  const std::vector<int32_t>& closeup_plane = mc.closeup_plane;
  const std::vector<int32_t>& crop_plane = mc.crop_plane;
  const std::vector<uint8_t>& valid = mc.valid;
  auto mask = macro_closeup_mask(n, planes, closeup_plane, crop_plane, valid);
  REQUIRE(mask.is_ok());
  REQUIRE(mask->validate().is_ok());
  const int total = n * (1 + crops);
  std::vector<uint8_t> dense(size_t(total) * total, 0);
  for (int i = 0; i < total; ++i)
    for (int j = 0; j < total; ++j) {
      const int vi = i / n, vj = j / n, tj = j % n;
      bool ok = vi == vj;
      if (vi == 0 && vj > 0)
        ok = crop_plane[size_t(vj - 1)] == closeup_plane[size_t(i)] &&
             valid[size_t(vj - 1) * n + tj];
      dense[size_t(i) * total + j] = ok;
    }
  REQUIRE(mask->to_dense() == dense);
  // Block sparsity: the computed area stays close to the allowed area.
  INFO("allowed " << mask->allowed_pairs() << ", computed " << mask->computed_pairs());
  CHECK(double(mask->computed_pairs()) < 1.35 * double(mask->allowed_pairs()));
  Problem p = make_problem(total, total, 2, 16, 17);
  check_all_paths(p, &*mask, dense.data(), false);
}

TEST_CASE("MACRO masks built from the golden plane and validity maps match mask.levelL",
          "[attention][mask][golden]") {
  const std::string path = test::golden_dir() + "/unet-tiny/case-macro-masked.safetensors";
  auto st = SafeTensors::open(path);
  REQUIRE(st.is_ok());
  const TensorEntry* plane0 = st->find("input.plane_level0");
  const TensorEntry* valid0 = st->find("input.valid_level0");
  REQUIRE(plane0);
  REQUIRE(valid0);
  REQUIRE(plane0->dtype == DType::kI32);
  REQUIRE(valid0->dtype == DType::kU8);
  REQUIRE(plane0->shape == std::vector<int64_t>{16, 24});
  REQUIRE(valid0->shape == std::vector<int64_t>{4, 16, 24});
  const int H = 16, W = 24, crops = 4, P = 2;
  std::vector<int32_t> p0(size_t(H) * W);
  std::memcpy(p0.data(), plane0->data, p0.size() * sizeof(int32_t));
  const uint8_t* v0 = valid0->data;
  std::vector<int32_t> crop_plane(crops);
  for (int c = 0; c < crops; ++c) crop_plane[size_t(c)] = c % P;  // crop index k * P + p
  const int grids[4][2] = {{16, 24}, {8, 12}, {4, 6}, {2, 3}};
  for (int level = 0; level < 4; ++level) {
    const int h = grids[level][0], w = grids[level][1], n = h * w;
    std::vector<int32_t> plane(static_cast<size_t>(n));
    std::vector<uint8_t> valid(size_t(crops) * n);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {  // top-left sample of each cell
        const int sy = y * H / h, sx = x * W / w;
        plane[size_t(y * w + x)] = p0[size_t(sy * W + sx)];
        for (int c = 0; c < crops; ++c)
          valid[size_t(c) * n + size_t(y * w + x)] = v0[size_t(c) * H * W + size_t(sy * W + sx)];
      }
    auto mask = macro_closeup_mask(n, P, plane, crop_plane, valid);
    REQUIRE(mask.is_ok());
    const std::string name = "mask.level" + std::to_string(level);
    const TensorEntry* g = st->find(name);
    REQUIRE(g);
    REQUIRE(g->dtype == DType::kU8);
    const int total = 5 * n;
    REQUIRE(g->shape == std::vector<int64_t>{total, total});
    std::vector<uint8_t> golden(g->data, g->data + size_t(total) * total);
    for (auto& x : golden) x = x != 0;
    INFO(name);
    CHECK(mask->to_dense() == golden);
    auto from_golden = mask_from_dense(g->data, total, total, 0, true);
    REQUIRE(from_golden.is_ok());
    CHECK(from_golden->to_dense() == golden);
  }
}

TEST_CASE("fully masked rows give zeros, never NaN", "[attention][mask]") {
  const int nq = 70, nk = 90;
  Problem p = make_problem(nq, nk, 2, 16, 21);
  std::vector<uint8_t> none(size_t(nq) * nk, 0);
  for (bool group : {false, true}) {
    auto mask = mask_from_dense(none.data(), nq, nk, 0, group);
    REQUIRE(mask.is_ok());
    CHECK(mask->entries() == 0);
    for (Isa isa : supported_isas()) {
      std::vector<float> out;
      REQUIRE(attention_with_isa(args_for(p, out, &*mask), isa).is_ok());
      for (size_t i = 0; i < size_t(nq) * 2 * 16; ++i) REQUIRE(out[i] == 0.0f);
    }
  }
  // Rows masked only inside partial tiles (the tile is listed, the row has no 1s in it), and a
  // query block whose first key block is fully masked for some rows.
  std::vector<uint8_t> dense = random_dense(nq, nk, 0.5, 22);
  for (int i : {0, 5, 63, 64, 69})
    for (int j = 0; j < nk; ++j) dense[size_t(i) * nk + j] = 0;
  for (int i = 10; i < 20; ++i)
    for (int j = 0; j < 64; ++j) dense[size_t(i) * nk + j] = 0;
  auto mask = mask_from_dense(dense.data(), nq, nk);
  REQUIRE(mask.is_ok());
  check_all_paths(p, &*mask, dense.data(), false);
  for (Isa isa : supported_isas()) {
    std::vector<float> out;
    REQUIRE(attention_with_isa(args_for(p, out, &*mask), isa).is_ok());
    for (size_t i = 0; i < size_t(nq) * 32; ++i) REQUIRE(std::isfinite(out[i]));
    for (int c = 0; c < 32; ++c) CHECK(out[size_t(63) * 32 + c] == 0.0f);
  }
  // nk == 0: every row is empty.
  Problem e = make_problem(5, 0, 1, 16, 23);
  std::vector<float> out;
  REQUIRE(attention(args_for(e, out, nullptr)).is_ok());
  for (int i = 0; i < 5 * 16; ++i) CHECK(out[size_t(i)] == 0.0f);
}

TEST_CASE("causal attention (CLIP text encoder)", "[attention][causal]") {
  check_all_paths(make_problem(77, 77, 2, 32, 31), nullptr, nullptr, true);
  check_all_paths(make_problem(130, 150, 1, 16, 32), nullptr, nullptr, true);
  // The mask builder says the same as the flag, and the flag combines with a mask.
  BlockSparseMask cm = causal_mask(130, 150);
  REQUIRE(cm.validate().is_ok());
  Problem p = make_problem(130, 150, 1, 16, 33);
  check_all_paths(p, &cm, nullptr, true);
  std::vector<uint8_t> dense = random_dense(130, 150, 0.6, 34);
  auto dm = mask_from_dense(dense.data(), 130, 150);
  REQUIRE(dm.is_ok());
  check_all_paths(p, &*dm, dense.data(), true);
}

TEST_CASE("attention is bit-identical across thread counts", "[attention][threads]") {
  Problem p = make_problem(300, 260, 3, 64, 41);
  std::vector<uint8_t> dense = random_dense(300, 260, 0.4, 42);
  auto mask = mask_from_dense(dense.data(), 300, 260, 0, true);
  REQUIRE(mask.is_ok());
  for (bool bf16 : {false, true})
    for (Isa isa : supported_isas()) {
      std::vector<float> first;
      for (int threads : {1, 2, 3}) {
        ThreadPool pool(threads);
        std::vector<float> out;
        AttentionArgs a = args_for(p, out, &*mask);
        a.bf16 = bf16;
        REQUIRE(attention_with_isa(a, isa, pool).is_ok());
        if (first.empty()) {
          first = out;
        } else {
          INFO(isa_name(isa) << (bf16 ? " bf16" : " fp32") << " threads " << threads);
          CHECK(std::memcmp(first.data(), out.data(), out.size() * sizeof(float)) == 0);
        }
      }
    }
}

TEST_CASE("attention and mask builders reject bad arguments with named errors",
          "[attention][errors]") {
  Problem p = make_problem(10, 12, 1, 16, 51);
  std::vector<float> out;
  AttentionArgs a = args_for(p, out, nullptr);
  a.head_dim = 0;
  Status s = attention(a);
  REQUIRE_FALSE(s.is_ok());
  CHECK(s.message().find("head_dim") != std::string::npos);
  a = args_for(p, out, nullptr);
  a.head_dim = 1024;
  CHECK_FALSE(attention(a).is_ok());
  a = args_for(p, out, nullptr);
  a.q_stride = 8;
  s = attention(a);
  REQUIRE_FALSE(s.is_ok());
  CHECK(s.message().find("q row stride") != std::string::npos);
  BlockSparseMask wrong = causal_mask(11, 12);
  a = args_for(p, out, &wrong);
  s = attention(a);
  REQUIRE_FALSE(s.is_ok());
  CHECK(s.message().find("11 x 12") != std::string::npos);
  auto g = mask_from_groups({0, 1, 2}, {0, 0}, 2, 1, {1, 1});
  REQUIRE_FALSE(g.is_ok());
  CHECK(g.status().message().find("query_group[2]") != std::string::npos);
  auto t = mask_from_groups({0}, {0}, 1, 2, {1});
  REQUIRE_FALSE(t.is_ok());
  CHECK(t.status().message().find("allowed table") != std::string::npos);
  auto m = macro_closeup_mask(4, 2, {0, 1, 0, 1}, {0, 2}, std::vector<uint8_t>(8, 1));
  REQUIRE_FALSE(m.is_ok());
  CHECK(m.status().message().find("crop_plane[1]") != std::string::npos);
  std::vector<uint8_t> d(12);
  CHECK_FALSE(mask_from_dense(d.data(), 3, 4, 2).is_ok());  // stride below nk
}

// ---- bf16 products (AttentionArgs::bf16) --------------------------------------------------------
namespace {

float max_abs_v(const Problem& p) {
  float m = 0;
  for (int j = 0; j < p.nk; ++j)
    for (size_t e = 0; e < size_t(p.heads) * p.d; ++e)
      m = std::max(m, std::fabs(p.v()[size_t(j) * p.stride + e]));
  return m;
}

// Every path with a bf16 request: the scalar twin and avx512bf16 against the rounded-operand
// reference within the probability-rounding bound, each other within the same bound; other paths
// (no bf16 products) must give exactly their fp32 result.
void check_bf16_paths(const Problem& p, const BlockSparseMask* mask, const uint8_t* dense,
                      bool causal) {
  const std::vector<float> ref = reference(p, dense, causal, /*bf16=*/true);
  const std::vector<float> ref32 = reference(p, dense, causal);
  const double bound = std::ldexp(double(max_abs_v(p)), -8) + 1e-5;
  std::vector<float> twin;
  for (Isa isa : supported_isas()) {
    INFO("path " << isa_name(isa) << ", nq " << p.nq << ", nk " << p.nk << ", heads " << p.heads
                 << ", D " << p.d << (causal ? ", causal" : "") << (mask ? ", masked" : ""));
    std::vector<float> out, out32;
    AttentionArgs a = args_for(p, out, mask, causal);
    a.bf16 = true;
    REQUIRE(attention_with_isa(a, isa).is_ok());
    const size_t n = ref.size();
    CHECK(out[n] == -7.0f);
    REQUIRE(attention_with_isa(args_for(p, out32, mask, causal), isa).is_ok());
    // The path's own table decides (amx answers bf16 requests with its fp32 kernel).
    const auto& table = attention_detail::kernels_for(isa);
    const bool has_bf16 = table.block_bf16 && p.d % table.bf16_d_multiple == 0;
    if (!has_bf16) {
      CHECK(std::memcmp(out.data(), out32.data(), n * sizeof(float)) == 0);
      continue;
    }
    const test::Diff diff = test::compare(out.data(), ref.data(), n);
    CHECK(diff.max_abs <= bound);
    // Against full fp32 the error is the operands' rounding too: a few times the bound, and the
    // request must have changed the result (it really ran in bf16).
    const test::Diff d32 = test::compare(out.data(), ref32.data(), n);
    CHECK(d32.rel_l2 <= 0.03);
    CHECK(std::memcmp(out.data(), out32.data(), n * sizeof(float)) != 0);
    if (isa == Isa::kScalar) {
      twin = out;
    } else if (!twin.empty()) {
      CHECK(test::compare(out.data(), twin.data(), n).max_abs <= bound);
    }
  }
}

}  // namespace

TEST_CASE("bf16 attention matches the rounded-operand reference on every path",
          "[attention][bf16]") {
  struct Case {
    int nq, nk, heads, d;
  };
  // Odd key counts leave a key without a pair partner; D 16 has no bf16 kernel on SIMD paths.
  const Case cases[] = {{1, 1, 1, 32},      {37, 53, 2, 32},   {130, 77, 3, 64}, {64, 64, 1, 64},
                        {200, 129, 2, 128}, {20, 150, 1, 512}, {70, 45, 2, 16},  {9, 5, 1, 96}};
  uint32_t seed = 101;
  for (const Case& c : cases)
    check_bf16_paths(make_problem(c.nq, c.nk, c.heads, c.d, seed++), nullptr, nullptr, false);
  check_bf16_paths(make_problem(150, 200, 2, 64, 199, 3.0f), nullptr, nullptr, false);
}

TEST_CASE("bf16 attention with block-sparse, reordered and causal masks",
          "[attention][bf16][mask]") {
  uint32_t seed = 120;
  for (double density : {0.05, 0.5}) {
    for (bool group : {false, true}) {
      const int nq = 150, nk = 211;
      Problem p = make_problem(nq, nk, 2, 64, seed++);
      std::vector<uint8_t> dense = random_dense(nq, nk, density, seed++);
      for (int j = 0; j < nk; ++j) dense[size_t(7) * nk + j] = 0;  // a fully masked row
      auto mask = mask_from_dense(dense.data(), nq, nk, 0, group);
      REQUIRE(mask.is_ok());
      check_bf16_paths(p, &*mask, dense.data(), false);
    }
  }
  check_bf16_paths(make_problem(77, 77, 2, 32, seed++), nullptr, nullptr, true);
}

TEST_CASE("a mask restricted to the first query tokens keeps their rows and their bits",
          "[attention][mask]") {
  // The MACRO mask of a close-up and 5 crops (as above), restricted to the close-up's tokens (and
  // to other limits, one that cuts a view): the same rows of the dense mask, and attention over
  // the kept queries gives the full attention's first rows bit for bit, on every path.
  const MacroMaskCase mc;
  const int n = mc.n, crops = mc.crops;
  const int total = n * (1 + crops);
  std::vector<std::pair<std::string, BlockSparseMask>> masks;
  {
    auto m = macro_closeup_mask(n, mc.planes, mc.closeup_plane, mc.crop_plane, mc.valid);
    REQUIRE(m.is_ok());
    masks.push_back({"macro (grouped, permuted rows)", *m});
    std::vector<uint8_t> dense = random_dense(total, total, 0.3, 77);
    auto d = mask_from_dense(dense.data(), total, total, 0, false);
    REQUIRE(d.is_ok());
    masks.push_back({"random dense (identity order)", *d});
  }
  Problem p = make_problem(total, total, 2, 16, 91);
  for (const auto& [name, mask] : masks) {
    const std::vector<uint8_t> dense = mask.to_dense();
    for (int limit : {n, n + 37, 1, total}) {
      INFO(name << ", first " << limit << " queries");
      auto r = restrict_queries(mask, limit);
      REQUIRE(r.is_ok());
      REQUIRE(r->validate().is_ok());
      CHECK(r->nq == limit);
      CHECK(r->to_dense() ==
            std::vector<uint8_t>(dense.begin(), dense.begin() + ptrdiff_t(limit) * total));
      for (bool bf16 : {false, true})
        for (Isa isa : supported_isas()) {
          INFO(isa_name(isa) << (bf16 ? " bf16" : " fp32"));
          std::vector<float> full, part;
          AttentionArgs a = args_for(p, full, &mask);
          a.bf16 = bf16;
          REQUIRE(attention_with_isa(a, isa).is_ok());
          Problem pq = p;
          pq.nq = limit;
          AttentionArgs b = args_for(pq, part, &*r);
          b.bf16 = bf16;
          REQUIRE(attention_with_isa(b, isa).is_ok());
          const size_t row = size_t(p.heads) * p.d;
          CHECK(std::memcmp(full.data(), part.data(), size_t(limit) * row * sizeof(float)) == 0);
        }
    }
  }
  auto bad = restrict_queries(masks[0].second, total + 1);
  REQUIRE(!bad.is_ok());
  CHECK(bad.status().message().find("limit") != std::string::npos);
}
