// bench attention: fused block-sparse attention against the machine's own rates, measured in the
// same run.
//
//   bench attention [--threads N] [--reps R] [--quick] [--unet-only] [--bf16] [--closeup]
//
// --bf16: every case also runs with bf16 products (AttentionArgs::bf16) and prints its time and
// the fp32 / bf16 ratio (the fp32 run of the same case is the baseline); adds the VAE mid-block
// shape (960x536 / 8 = 8040 tokens, 1 head x 512) and times the bf16 kernel's online softmax
// alone on one in-cache 64 x 64 tile.
// --closeup: only the U-Net level-0 attention of the MACRO close-up 960x536, K = P = 3 (a close-up
// and 9 crops of 120 x 67 tokens, 5 heads x 64, the close-up mask rule), against dense attention
// over one view of the same size: the masked time should be the dense time scaled by the allowed
// pairs.
//
// Baselines (same run, same thread count):
//  - FMA peak: a register-only FMA loop of the active path (per thread, times threads);
//  - the score micro-GEMM (S = Q K^T on one in-cache 64 x 64 x 64 tile) that attention runs on;
//  - dense (unmasked) attention of the same shape, for the masked runs.
// Shapes: MACRO level 1 (5 views x 2040 tokens, 10 heads x 64) dense and with MACRO-like masks of
// about 10%, 30% and 100% allowed pairs; U-Net level 0 Difix-ref (2 views x 4096, 5 heads x 64).
// attention FLOP = 4 * allowed pairs * D per head (QK^T and PV, 2 FLOP per MAC).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "attention/runtime/attention.h"
#include "attention/runtime/attention_mask.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/thread_pool.h"
#include "bench_registry.h"

namespace macro::bench {
namespace {

using attention_detail::AttentionKernels;

// The machine is shared, so every timing is taken both on the wall clock and as process CPU time
// (all threads); rates per CPU-second show the kernel's efficiency on the cores it actually got.
// GFLOP/s of the FMA loop: {per wall second with all threads, per CPU-second (one core)}.
Timing fma_peak_gflops(const AttentionKernels& k, ThreadPool& pool) {
  const Rate r = probe_rate(k.fma_peak, &pool, 20'000'000, 3);
  return {r.wall, r.cpu};
}

double score_tile_gflops(const AttentionKernels& k, int d) {
  // One 64 x 64 x D tile in cache: S^T = K Q^T, K rows read in place, Q^T packed.
  LineVec kr(size_t(kAttnBlockK) * d, 0.5f), qt(size_t(d) * kAttnBlockQ, 0.25f),
      s(size_t(kAttnBlockQ) * kAttnBlockK);
  std::vector<const float*> rows(kAttnBlockK);
  for (int c = 0; c < kAttnBlockK; ++c) rows[size_t(c)] = kr.data() + size_t(c) * d;
  const int calls = 20000;
  const Timing t = median_timing(5, [&] {
    for (int i = 0; i < calls; ++i) k.score_tile(rows.data(), kAttnBlockK, qt.data(), d, s.data());
  });
  return 2.0 * kAttnBlockQ * kAttnBlockK * d * calls / t.cpu * 1e-9;  // per CPU-second
}

// CPU nanoseconds per call of the bf16 kernel's online softmax on one 64 x 64 tile of scores
// N(0, 1.5) in base 2, in cache, in the steady state (m already holds the running max).
double softmax_tile_ns(const AttentionKernels& k) {
  LineVec s(size_t(kAttnBlockK) * kAttnBlockQ), m(kAttnBlockQ), l(kAttnBlockQ, 0.0f),
      alpha(kAttnBlockQ);
  std::vector<uint32_t> pp(size_t(kAttnBlockK) / 2 * kAttnBlockQ);
  std::mt19937 rng(7);
  std::normal_distribution<float> score(0.0f, 1.5f);
  for (float& x : s) x = score(rng);
  for (float& x : m) x = -std::numeric_limits<float>::infinity();
  const int calls = 20000;
  const Timing t = median_timing(5, [&] {
    for (int i = 0; i < calls; ++i)
      k.softmax_bf16(s.data(), kAttnBlockK, m.data(), l.data(), alpha.data(), pp.data());
  });
  return t.cpu / calls * 1e9;
}

// Plane maps in spatial blobs, different per view, like depth planes of a close-up.
int plane_at(int view, int y, int x, int planes) {
  return ((y / 5) * 3 + (x / 7) * 5 + view * 2 + ((x + y) / 11)) % planes;
}

struct MaskCase {
  std::string name;
  BlockSparseMask mask;
};

// MACRO-like masks over V = 5 views x (gh x gw) tokens.
std::vector<MaskCase> macro_like_masks(int gh, int gw) {
  const int n = gh * gw, views = 5, total = n * views;
  std::vector<MaskCase> cases;
  // ~10%: plane-local joint attention, 8 depth planes in every view: a token of plane p sees the
  // valid tokens of plane p in every view (crop validity: a 10% border is padding).
  {
    const int planes = 8;
    std::vector<int32_t> qg(static_cast<size_t>(total)), kg(static_cast<size_t>(total));
    for (int v = 0; v < views; ++v)
      for (int y = 0; y < gh; ++y)
        for (int x = 0; x < gw; ++x) {
          const size_t i = size_t(v) * n + size_t(y) * gw + x;
          const int p = plane_at(v, y, x, planes);
          const bool valid = v == 0 || (x >= gw / 10 && y >= gh / 10);
          qg[i] = p;
          kg[i] = valid ? p : planes;
        }
    std::vector<uint8_t> allowed(size_t(planes) * (planes + 1), 0);
    for (int p = 0; p < planes; ++p) allowed[size_t(p) * (planes + 1) + p] = 1;
    auto m = mask_from_groups(qg, kg, planes, planes + 1, allowed);
    if (m.is_ok()) cases.push_back({"plane-local, 8 planes", std::move(m).value()});
  }
  // ~30%: the MACRO close-up rule of the goldens, K = 2 refs x P = 2 planes: every view sees
  // itself; close-up tokens of plane p also see the valid tokens of the crops of plane p.
  {
    const int planes = 2;
    std::vector<int32_t> closeup(static_cast<size_t>(n)), crop_plane = {0, 1, 0, 1};
    std::vector<uint8_t> valid(size_t(4) * n);
    for (int y = 0; y < gh; ++y)
      for (int x = 0; x < gw; ++x) {
        closeup[size_t(y) * gw + x] = plane_at(0, y, x, planes);
        for (int c = 0; c < 4; ++c)
          valid[size_t(c) * n + size_t(y) * gw + x] = x >= (c + 1) * gw / 16;
      }
    auto m = macro_closeup_mask(n, planes, closeup, crop_plane, valid);
    if (m.is_ok()) cases.push_back({"MACRO close-up rule, K=2 P=2", std::move(m).value()});
  }
  // 100%: every pair allowed, but through the grouped builder (token permutation active).
  {
    std::vector<int32_t> qg(static_cast<size_t>(total)), kg(size_t(total), 0);
    for (int i = 0; i < total; ++i) qg[size_t(i)] = plane_at(i / n, (i % n) / gw, i % gw, 3);
    auto m = mask_from_groups(qg, kg, 3, 1, {1, 1, 1});
    if (m.is_ok()) cases.push_back({"all allowed, permuted", std::move(m).value()});
  }
  return cases;
}

struct Buffers {
  LineVec q, k, v, out;
};
Buffers make_buffers(int n, int c) {
  Buffers b;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1, 1);
  for (auto* x : {&b.q, &b.k, &b.v}) {
    x->resize(size_t(n) * c);
    for (float& f : *x) f = u(rng);
  }
  b.out.resize(size_t(n) * c);
  return b;
}

int run(int argc, char** argv) {
  std::vector<int> thread_counts = {1, 2};
  int reps = 3;
  bool quick = false, unet_only = false, bf16 = false, closeup = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) {
      thread_counts = {std::atoi(argv[++i])};
    } else if (!std::strcmp(argv[i], "--reps") && i + 1 < argc) {
      reps = std::max(1, std::atoi(argv[++i]));
    } else if (!std::strcmp(argv[i], "--quick")) {
      quick = true;
    } else if (!std::strcmp(argv[i], "--unet-only")) {
      unet_only = true;
    } else if (!std::strcmp(argv[i], "--bf16")) {
      bf16 = true;
    } else if (!std::strcmp(argv[i], "--closeup")) {
      closeup = true;
    } else {
      std::fprintf(stderr, "bench attention: unknown flag '%s'\n", argv[i]);
      return 2;
    }
  }
  const Isa isa = active_isa();
  const AttentionKernels& kern = attention_detail::kernels_for(isa);
  const int heads = 10, d = 64, c = heads * d;
  const int gh = quick ? 17 : 34, gw = quick ? 30 : 60;  // 34 x 60 = 2040 tokens per view
  const int n = 5 * gh * gw;
  Buffers buf = make_buffers(n, c);
  std::vector<MaskCase> masks = macro_like_masks(gh, gw);
  const int un = quick ? 2 * 1024 : 2 * 4096, uheads = 5;
  Buffers ubuf = make_buffers(un, uheads * d);

  std::printf("attention: path %s, tile %d x %d, medians of %d runs\n", isa_name(kern.isa),
              kAttnBlockQ, kAttnBlockK, reps);
  for (const MaskCase& m : masks)
    std::printf(
        "  mask %-30s allowed %.4f, computed tiles cover %.4f of the square, %zu of %zu "
        "listed tiles partial\n",
        m.name.c_str(), double(m.mask.allowed_pairs()) / (double(n) * n),
        double(m.mask.computed_pairs()) / (double(n) * n), m.mask.partial_tiles(),
        m.mask.entries());
  const double tile_rate = score_tile_gflops(kern, d);
  if (bf16 && kern.softmax_bf16)
    std::printf("  bf16 online softmax of one %d x %d tile (in cache): %.0f ns of CPU time\n",
                kAttnBlockQ, kAttnBlockK, softmax_tile_ns(kern));
  for (int threads : thread_counts) {
    ThreadPool pool(threads);
    const Timing peak_t = fma_peak_gflops(kern, pool);
    const double peak = peak_t.cpu, gemm = tile_rate;  // per CPU-second (one core)
    std::printf(
        "\nthreads %d: FMA peak %.1f GFLOP/s per CPU-second (%.1f per wall second, all "
        "threads); score micro-GEMM %.1f GFLOP/s per CPU-second (%.0f%% of peak)\n",
        threads, peak, peak_t.wall, gemm, 100 * gemm / peak);
    std::printf("  %-44s %9s %9s %8s %8s %7s %7s\n", "case", "wall ms", "cpu ms", "GF/wall",
                "GF/cpu", "%peak", "%gemm");
    Timing last{};  // the last run of the latest case (bf16 where asked for)
    auto time_case = [&](const char* what, Buffers& b, int tokens, int h,
                         const BlockSparseMask* mask, double allowed, int head_dim) {
      AttentionArgs a;
      a.q = b.q.data();
      a.k = b.k.data();
      a.v = b.v.data();
      a.out = b.out.data();
      a.nq = a.nk = tokens;
      a.heads = h;
      a.head_dim = head_dim;
      a.mask = mask;
      const double flop = 4.0 * allowed * head_dim * h;
      Timing first{};
      for (bool b16 : {false, true}) {
        if (b16 && !bf16) break;
        a.bf16 = b16;
        bool ok = true;
        const Timing t = median_timing(reps, [&] { ok &= attention(a, pool).is_ok(); });
        const double per_cpu = flop / t.cpu * 1e-9;
        std::printf("  %-44s %9.1f %9.1f %8.1f %8.1f %6.0f%% %6.0f%%%s", b16 ? "    bf16" : what,
                    t.wall * 1e3, t.cpu * 1e3, flop / t.wall * 1e-9, per_cpu, 100 * per_cpu / peak,
                    100 * per_cpu / gemm, ok ? "" : "  [FAILED]");
        if (b16)
          std::printf("  fp32/bf16 %.2fx wall, %.2fx cpu", first.wall / t.wall, first.cpu / t.cpu);
        std::printf("\n");
        if (!b16) first = t;
        last = t;
      }
      return first;
    };
    char label[160];
    if (closeup) {
      const int cgh = quick ? 34 : 67, cgw = quick ? 60 : 120, cn = cgh * cgw, crops = 9;
      const int planes = 3;
      std::vector<int32_t> cplane(static_cast<size_t>(cn)), crop_plane(crops);
      std::vector<uint8_t> valid(size_t(crops) * cn);
      for (int c = 0; c < crops; ++c) crop_plane[size_t(c)] = c / 3;
      for (int y = 0; y < cgh; ++y)
        for (int x = 0; x < cgw; ++x) {
          cplane[size_t(y) * cgw + x] = plane_at(0, y, x, planes);
          for (int c = 0; c < crops; ++c)  // crops padded at a border of 3-19% of the width
            valid[size_t(c) * cn + size_t(y) * cgw + x] = x >= (c + 2) * cgw / 48;
        }
      auto m = macro_closeup_mask(cn, planes, cplane, crop_plane, valid);
      if (!m.is_ok()) {
        std::fprintf(stderr, "bench attention: %s\n", m.status().message().c_str());
        return 1;
      }
      const int total = cn * (crops + 1);
      Buffers cbuf = make_buffers(total, uheads * d);
      std::snprintf(label, sizeof label, "dense 1 view %d tok, %dx%d", cn, uheads, d);
      const Timing one = time_case(label, cbuf, cn, uheads, nullptr, double(cn) * cn, d);
      const Timing one_last = last;
      const double allowed = double(m.value().allowed_pairs());
      std::snprintf(label, sizeof label, "MACRO close-up L0 %d tok, K=P=3", total);
      const Timing t = time_case(label, cbuf, total, uheads, &m.value(), allowed, d);
      const double frac = allowed / (double(cn) * cn);
      std::printf("    masked / (dense 1 view x %.2f allowed squares): fp32 wall %.2f, cpu %.2f",
                  frac, t.wall / one.wall / frac, t.cpu / one.cpu / frac);
      if (bf16)
        std::printf("; bf16 wall %.2f, cpu %.2f", last.wall / one_last.wall / frac,
                    last.cpu / one_last.cpu / frac);
      std::printf("\n");
      continue;
    }
    std::snprintf(label, sizeof label, "MACRO L1 dense %d tok, %dx%d", n, heads, d);
    const Timing dense =
        unet_only ? Timing{} : time_case(label, buf, n, heads, nullptr, double(n) * n, d);
    for (const MaskCase& m : masks) {
      if (unet_only) break;
      const double frac = double(m.mask.allowed_pairs()) / (double(n) * n);
      std::snprintf(label, sizeof label, "  masked: %s", m.name.c_str());
      const Timing t = time_case(label, buf, n, heads, &m.mask, double(m.mask.allowed_pairs()), d);
      std::printf(
          "    masked/dense: wall %.3f, cpu %.3f for allowed fraction %.3f -> ratio %.2f "
          "wall, %.2f cpu (target <= 1.30)\n",
          t.wall / dense.wall, t.cpu / dense.cpu, frac, t.wall / dense.wall / frac,
          t.cpu / dense.cpu / frac);
    }
    std::snprintf(label, sizeof label, "U-Net L0 Difix-ref %d tok, %dx%d", un, uheads, d);
    time_case(label, ubuf, un, uheads, nullptr, double(un) * un, d);
    if (bf16) {
      const int vn = quick ? 2010 : 8040;
      Buffers vbuf = make_buffers(vn, 512);
      std::snprintf(label, sizeof label, "VAE mid %d tok, 1x512", vn);
      time_case(label, vbuf, vn, 1, nullptr, double(vn) * vn, 512);
    }
  }
  return 0;
}

const bool registered = register_benchmark(
    {"attention", "fused block-sparse attention vs FMA peak, micro-GEMM and dense", run});

}  // namespace
}  // namespace macro::bench
