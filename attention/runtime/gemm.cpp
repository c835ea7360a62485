// GEMM driver (cache blocking, packing, threading) and the scalar kernel path.
//
// Blocking (Goto/BLIS style, loop order chosen for a 32-48 KB L1 and 1 MB L2 per core):
//   task  = MC rows x a column range of C        (tasks spread over the thread pool)
//     pc  : K in blocks of KC                    (A block MC x KC packed once per pc)
//       jc: the task's columns in blocks of NC   (B block KC x NC packed, or prepacked weights)
//         ir: MR rows  (A micro-panel MR x KC stays in L1)
//           jr: NR columns (B micro-panels stream from L2) -> micro-kernel MR x NR
// KC <= kern.kc (from the L1 size for AVX-512, kc_for_l1) with K cut into equal blocks; NC sized so
// the B block is about 7/16 of the L2 (448 KB of 1 MB; cpu.h l2_block_bytes); MC about 192 rows,
// the row tasks a multiple of the thread count (equal shares for 1 and 2 threads), columns split
// only when there are fewer row blocks than threads. Results never depend on the split (K blocking
// depends on K alone), so they are thread-count invariant. (Tried: columns outermost with K
// inside, to keep C in L2 for the conv's prepacked A: 3-5 points slower on the 128-channel VAE
// convs, 2026-11-22.)
// The scalar path runs the same driver with a small plain-C++ micro-kernel, so packing and
// blocking are exercised by every path; the tests also compare against a naive loop.
#include "attention/runtime/gemm.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <numeric>

#include "attention/runtime/half.h"
#include "attention/runtime/ops.h"
#include "attention/runtime/scratch.h"
#include "attention/runtime/status.h"

namespace macro {
namespace {

// ---- scalar micro-kernels ----------------------------------------------------------------------

constexpr int kScalarMr = 4, kScalarNr = 16;

void scalar_store(const MicroTile& t, const float* acc, int ld) {
  for (int i = 0; i < t.m; ++i) {
    float* c = t.c + i * t.ldc;
    for (int j = 0; j < t.n; ++j) {
      float v = t.alpha * acc[i * ld + j];
      if (t.load_c) v += t.beta * c[j];
      if (t.bias_n) v += t.bias_n[j];
      if (t.bias_m) v += t.bias_m[i];
      if (t.res) v += t.res[i * t.ldr + j];
      if (t.relu) v = v > 0.0f ? v : 0.0f;
      c[j] = v;
    }
  }
}

void scalar_f32(const MicroTile& t) {
  float acc[kScalarMr * kScalarNr] = {};
  const float* a = static_cast<const float*>(t.a);
  const float* b = static_cast<const float*>(t.b);
  for (int64_t k = 0; k < t.kc; ++k) {
    for (int i = 0; i < kScalarMr; ++i) {
      const float ai = a[k * kScalarMr + i];
      for (int j = 0; j < kScalarNr; ++j) acc[i * kScalarNr + j] += ai * b[k * kScalarNr + j];
    }
  }
  scalar_store(t, acc, kScalarNr);
}

// bf16 pairs: acc += a[2p+1] * b[2p+1]; acc += a[2p] * b[2p] (the vdpbf16ps order; the products of
// two bf16 are exact in fp32, so FMA or not gives the same bits).
void scalar_bf16(const MicroTile& t) {
  float acc[kScalarMr * kScalarNr] = {};
  const uint16_t* a = static_cast<const uint16_t*>(t.a);
  const uint16_t* b = static_cast<const uint16_t*>(t.b);
  for (int64_t kp = 0; kp < t.kc / 2; ++kp) {
    const uint16_t* ak = a + kp * kScalarMr * 2;
    const uint16_t* bk = b + kp * kScalarNr * 2;
    for (int i = 0; i < kScalarMr; ++i) {
      const float a0 = bf16_to_f32(ak[2 * i]), a1 = bf16_to_f32(ak[2 * i + 1]);
      for (int j = 0; j < kScalarNr; ++j) {
        float& c = acc[i * kScalarNr + j];
        c += a1 * bf16_to_f32(bk[2 * j + 1]);
        c += a0 * bf16_to_f32(bk[2 * j]);
      }
    }
  }
  scalar_store(t, acc, kScalarNr);
}

double scalar_probe(int64_t iters) {
  float x[8] = {1, 1, 1, 1, 1, 1, 1, 1};
  for (int64_t i = 0; i < iters; ++i)
    for (float& v : x) v = v * 0.9999f + 1e-4f;
  volatile float sink = x[0] + x[7];
  (void)sink;
  return 16.0 * double(iters);
}

// ---- per-thread packing buffers (grown once, reused) -------------------------------------------

thread_local detail::AlignedScratch t_scratch_a, t_scratch_b, t_scratch_c;

// ---- packing -----------------------------------------------------------------------------------

// f32_to_bf16 (half.h) without branches, so the packing loops vectorise: nearest-even, NaN quiet.
inline uint16_t round_bf16(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  const uint32_t r = (u + 0x7fffu + ((u >> 16) & 1u)) >> 16;
  const uint32_t q = (u >> 16) | 0x40u;
  return uint16_t((u & 0x7fffffffu) > 0x7f800000u ? q : r);
}

inline int64_t packed_index(PackLayout l, int64_t k, int64_t r, int w) {
  switch (l) {
    case PackLayout::kF32:
      return k * w + r;
    case PackLayout::kBf16Pairs:
      return (k >> 1) * w * 2 + r * 2 + (k & 1);
    case PackLayout::kBf16Amx:
      return (k >> 5) * w * 32 + r * 32 + (k & 31);
  }
  return 0;
}

template <typename Src, typename Dst, typename Conv>
void pack_generic(const Src* src, int64_t ld, bool transposed, int64_t R, int64_t K, PackLayout l,
                  int w, int64_t r0, int64_t rows, int64_t k0, int64_t kc, int64_t kcp, Dst* dst,
                  Conv conv) {
  const int64_t panels = (rows + w - 1) / w;
  const int64_t kend = std::min(k0 + kc, K);
  const int64_t rend = std::min(r0 + rows, R);
  for (int64_t p = 0; p < panels; ++p) {
    Dst* d = dst + p * kcp * w;
    const int64_t pr0 = r0 + p * w;
    const int valid_r = int(std::clamp<int64_t>(rend - pr0, 0, w));
    const int64_t valid_k = std::max<int64_t>(kend - k0, 0);
    if (l == PackLayout::kF32 && transposed) {
      // Source rows of the panel are contiguous along r: copy w at a time.
      for (int64_t k = 0; k < kcp; ++k) {
        Dst* dk = d + k * w;
        if (k < valid_k) {
          const Src* s = src + (k0 + k) * ld + pr0;
          for (int r = 0; r < valid_r; ++r) dk[r] = conv(s[r]);
          for (int r = valid_r; r < w; ++r) dk[r] = Dst(0);
        } else {
          for (int r = 0; r < w; ++r) dk[r] = Dst(0);
        }
      }
      continue;
    }
    if (l == PackLayout::kF32) {
      // Row-major source: walk each row along k (contiguous reads, strided writes).
      for (int r = 0; r < w; ++r) {
        if (r < valid_r) {
          const Src* s = src + (pr0 + r) * ld + k0;
          for (int64_t k = 0; k < valid_k; ++k) d[k * w + r] = conv(s[k]);
          for (int64_t k = valid_k; k < kcp; ++k) d[k * w + r] = Dst(0);
        } else {
          for (int64_t k = 0; k < kcp; ++k) d[k * w + r] = Dst(0);
        }
      }
      continue;
    }
    if constexpr (sizeof(Dst) == 2) {
      if (l == PackLayout::kBf16Pairs && !transposed) {
        // Row-major source into k pairs: each (k, k+1) of a row is one 32-bit word of the panel.
        uint32_t* d32 = reinterpret_cast<uint32_t*>(d);
        const int64_t pairs = kcp / 2;
        for (int r = 0; r < w; ++r) {
          if (r >= valid_r) {
            for (int64_t q = 0; q < pairs; ++q) d32[q * w + r] = 0;
            continue;
          }
          const Src* s = src + (pr0 + r) * ld + k0;
          const int64_t full = valid_k / 2;
          for (int64_t q = 0; q < full; ++q)
            d32[q * w + r] = uint32_t(conv(s[2 * q])) | (uint32_t(conv(s[2 * q + 1])) << 16);
          for (int64_t q = full; q < pairs; ++q) {
            const int64_t k = 2 * q;
            d32[q * w + r] = k < valid_k ? uint32_t(conv(s[k])) : 0u;
          }
        }
        continue;
      }
    }
    for (int r = 0; r < w; ++r) {
      for (int64_t k = 0; k < kcp; ++k) {
        Dst v = Dst(0);
        if (r < valid_r && k < valid_k) {
          v = transposed ? conv(src[(k0 + k) * ld + pr0 + r]) : conv(src[(pr0 + r) * ld + k0 + k]);
        }
        d[packed_index(l, k, r, w)] = v;
      }
    }
  }
}

// ---- tables ------------------------------------------------------------------------------------

struct Tables {
  KernelTable t[5];
  bool filled[5] = {};
  Tables() {
    for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
      if (!isa_supported(isa)) continue;
      KernelTable& k = t[int(isa)];
      switch (isa) {
        case Isa::kScalar:
          detail::fill_scalar_kernels(k);
          break;
        case Isa::kAvx2:
          detail::fill_avx2_kernels(k);
          break;
        case Isa::kAvx512:
          detail::fill_avx512_kernels(k);
          break;
        case Isa::kAvx512Bf16:
          detail::fill_avx512bf16_kernels(k);
          break;
        case Isa::kAmx:
          detail::fill_amx_kernels(k);
          break;
      }
      k.isa = isa;
      filled[int(isa)] = true;
    }
  }
};
const Tables& tables() {
  static const Tables t;
  return t;
}

// Block-size overrides for tuning experiments (MACRO_GEMM_KC / _MC / _NC; 0 = the defaults).
struct Tuning {
  int64_t kc = 0, mc = 0, nc = 0;
};
const Tuning& tuning() {
  static const Tuning t = [] {
    Tuning r;
    if (const char* v = std::getenv("MACRO_GEMM_KC")) r.kc = std::atoll(v);
    if (const char* v = std::getenv("MACRO_GEMM_MC")) r.mc = std::atoll(v);
    if (const char* v = std::getenv("MACRO_GEMM_NC")) r.nc = std::atoll(v);
    return r;
  }();
  return t;
}

}  // namespace

namespace detail {

void fill_scalar_kernels(KernelTable& t) {
  t.f32 = GemmKernel{kScalarMr, kScalarNr, 1, 256, PackLayout::kF32, scalar_f32, "scalar f32 4x16"};
  t.bf16 = GemmKernel{kScalarMr,   kScalarNr,         2, 256, PackLayout::kBf16Pairs,
                      scalar_bf16, "scalar bf16 4x16"};
  t.probe_fma = scalar_probe;
  t.probe_bf16 = scalar_probe;
}

void pack_panels_f32(const float* src, int64_t ld, bool transposed, int64_t R, int64_t K,
                     PackLayout layout, int w, int64_t r0, int64_t rows, int64_t k0, int64_t kc,
                     int64_t kcp, void* dst) {
  if (layout == PackLayout::kF32) {
    pack_generic(src, ld, transposed, R, K, layout, w, r0, rows, k0, kc, kcp,
                 static_cast<float*>(dst), [](float v) { return v; });
  } else {
    pack_generic(src, ld, transposed, R, K, layout, w, r0, rows, k0, kc, kcp,
                 static_cast<uint16_t*>(dst), [](float v) { return round_bf16(v); });
  }
}

void pack_panels_bf16(const uint16_t* src, int64_t ld, bool transposed, int64_t R, int64_t K,
                      PackLayout layout, int w, int64_t r0, int64_t rows, int64_t k0, int64_t kc,
                      int64_t kcp, void* dst) {
  if (layout == PackLayout::kF32) {
    pack_generic(src, ld, transposed, R, K, layout, w, r0, rows, k0, kc, kcp,
                 static_cast<float*>(dst), [](uint16_t v) { return bf16_to_f32(v); });
  } else {
    pack_generic(src, ld, transposed, R, K, layout, w, r0, rows, k0, kc, kcp,
                 static_cast<uint16_t*>(dst), [](uint16_t v) { return v; });
  }
}

namespace {
std::atomic<int64_t> g_kc_cap{0};
}  // namespace

// The B block's bytes: 7/16 of this CPU's L2 (448 KB where the L2 size is unknown).
static int64_t b_block_bytes() {
  static const int64_t bytes = l2_block_bytes(7, 16, 448 * 1024);
  return bytes;
}

int64_t kc_for_l1(int mr, int elem_bytes, int64_t fallback, long l1d_bytes) {
  const long l1 = l1d_bytes < 0 ? cpu_features().l1d : l1d_bytes;
  if (l1 <= 0 || mr <= 0 || elem_bytes <= 0) return fallback;
  const int64_t kc = int64_t(l1) / (int64_t(mr) * elem_bytes) / 64 * 64;
  return std::clamp<int64_t>(kc, 256, 2048);
}

int64_t gemm_set_kc_cap(int64_t kc) {
  return g_kc_cap.exchange(std::max<int64_t>(0, kc));
}

int64_t gemm_k_block(const GemmKernel& kern, int64_t K) {
  const Tuning& tun = tuning();
  int64_t kc_max = tun.kc > 0 ? round_up(tun.kc, kern.k_align) : kern.kc;
  if (const int64_t cap = g_kc_cap.load(); cap > 0)
    kc_max = std::min(kc_max, round_up(cap, kern.k_align));
  const int64_t k_blocks = std::max<int64_t>(1, (K + kc_max - 1) / kc_max);
  return round_up((K + k_blocks - 1) / k_blocks, kern.k_align);
}

bool gemm_folds_aliased_residual(const GemmKernel& kern, int64_t K) {
  return !kern.terms_first && gemm_k_block(kern, K) < K;
}

namespace {

// task(t) for every t < total: one task per pool job, or inline.
template <typename Task>
void run_tasks(ThreadPool* pool, int64_t total, const Task& task) {
  if (!pool || pool->size() == 1 || total == 1) {
    for (int64_t t = 0; t < total; ++t) task(t);
    return;
  }
  pool->parallel_for(
      size_t(total),
      [&](size_t b0, size_t b1, int) {
        for (size_t t = b0; t < b1; ++t) task(int64_t(t));
      },
      1);
}

// GemmParams::geglu_group: every task packs its A rows for all K blocks, then takes one strip of
// MR rows x NC columns at a time through all K blocks into a per-thread buffer (each tile sums as
// in run_gemm: the same blocks, terms and kernel calls, so the same bits) and writes value *
// GELU(gate) of the strip's column pairs into C. The [M, N] product stays in cache.
void run_gemm_geglu(const GemmKernel& kern, const DriverShape& s, const Operand& a,
                    const Operand& b, const GemmParams& p, ThreadPool* pool) {
  const int64_t M = s.M, N = s.N, K = s.K;
  const int g = p.geglu_group;
  MACRO_CHECK(g > 0 && N % (2 * g) == 0 && b.prepacked && K > 0);
  MACRO_CHECK(p.alpha == 1.0f && p.beta == 0.0f && !p.bias_m && !p.residual && !p.relu);
  const int mr = kern.mr, nr = kern.nr;
  const int64_t esz = packed_elem_bytes(kern.layout);
  const Tuning& tun = tuning();
  const int64_t KC = gemm_k_block(kern, K);
  const int64_t threads = pool ? pool->size() : 1;
  // Column blocks hold whole tiles and whole groups; B of a block over all of K about 7/16 of the
  // L2 (448 KB of a 1 MB L2).
  const int64_t unit = std::lcm(int64_t(nr), int64_t(2 * g));
  const int64_t nc_target =
      tun.nc > 0 ? tun.nc
                 : std::max<int64_t>(unit, b_block_bytes() / std::max<int64_t>(1, K * esz));
  const int64_t nc = unit * std::max<int64_t>(1, nc_target / unit);
  const int64_t mc_target = tun.mc > 0 ? tun.mc : 192;
  int64_t m_tasks = (M + mc_target - 1) / mc_target;
  if (threads > 1)
    m_tasks = std::min(round_up(m_tasks, threads), std::max<int64_t>(1, M / (4 * mr)));
  const int64_t mc = round_up((M + m_tasks - 1) / m_tasks, mr);
  m_tasks = (M + mc - 1) / mc;
  int64_t n_tasks = 1;
  if (threads > 1 && m_tasks < threads)
    n_tasks = std::clamp<int64_t>((4 * threads + m_tasks - 1) / m_tasks, 1, (N + unit - 1) / unit);
  const int64_t n_per_task = round_up((N + n_tasks - 1) / n_tasks, unit);
  n_tasks = (N + n_per_task - 1) / n_per_task;
  const int64_t k_blocks = (K + KC - 1) / KC;
  const OpsKernels& ops = ops_kernels();

  auto task = [&](int64_t t) {
    const int64_t ti = t / n_tasks, tj = t % n_tasks;
    const int64_t i0 = ti * mc, i1 = std::min(M, i0 + mc);
    const int64_t j0 = tj * n_per_task, j1 = std::min(N, j0 + n_per_task);
    if (j0 >= j1) return;
    const int64_t mrows = i1 - i0, mrows_p = round_up(mrows, mr);
    // A for every K block: block pc at a_off[pc / KC], micro-panels a_stride[] bytes apart.
    std::vector<const unsigned char*> a_base(static_cast<size_t>(k_blocks));
    std::vector<int64_t> a_stride(static_cast<size_t>(k_blocks));
    if (a.prepacked) {
      for (int64_t bi = 0; bi < k_blocks; ++bi) {
        a_base[size_t(bi)] = static_cast<const unsigned char*>(a.prepacked) +
                             ((i0 / mr) * a.kp * mr + bi * KC * mr) * esz;
        a_stride[size_t(bi)] = a.kp * mr * esz;
      }
    } else {
      int64_t total = 0;
      for (int64_t pc = 0; pc < K; pc += KC)
        total += mrows_p * round_up(std::min(KC, K - pc), kern.k_align) * esz;
      auto* buf = static_cast<unsigned char*>(t_scratch_a.get(size_t(total)));
      int64_t off = 0;
      for (int64_t pc = 0, bi = 0; pc < K; pc += KC, ++bi) {
        const int64_t kc = std::min(KC, K - pc), kcp = round_up(kc, kern.k_align);
        a.pack(a.ctx, kern, true, i0, mrows, pc, kc, buf + off);
        a_base[size_t(bi)] = buf + off;
        a_stride[size_t(bi)] = kcp * mr * esz;
        off += mrows_p * kcp * esz;
      }
    }
    float* strip = static_cast<float*>(t_scratch_c.get(size_t(mr * nc) * sizeof(float)));
    const int64_t b_stride = b.kp * nr * esz;
    for (int64_t jc = j0; jc < j1; jc += nc) {
      const int64_t ncols = std::min(nc, j1 - jc);
      for (int64_t ir = 0; ir < mrows; ir += mr) {
        const int64_t i = i0 + ir;
        MicroTile mt;
        mt.ldc = nc;
        mt.m = int(std::min<int64_t>(mr, i1 - i));
        for (int64_t pc = 0, bi = 0; pc < K; pc += KC, ++bi) {
          const int64_t kc = std::min(KC, K - pc);
          const bool first = pc == 0, last = pc + kc >= K;
          const bool terms = kern.terms_first ? first : last;
          mt.kc = round_up(kc, kern.k_align);
          mt.a = a_base[size_t(bi)] + (ir / mr) * a_stride[size_t(bi)];
          mt.beta = first ? 0.0f : 1.0f;
          mt.load_c = !first;
          const unsigned char* bbase = static_cast<const unsigned char*>(b.prepacked) +
                                       ((jc / nr) * b.kp * nr + pc * nr) * esz;
          if (kern.strip) {
            mt.b = bbase;
            mt.c = strip;
            mt.bias_n = terms && p.bias_n ? p.bias_n + jc : nullptr;
            kern.strip(mt, ncols, b_stride);
            continue;
          }
          for (int64_t jr = 0; jr < ncols; jr += nr) {
            mt.b = bbase + (jr / nr) * b_stride;
            mt.n = int(std::min<int64_t>(nr, ncols - jr));
            mt.c = strip + jr;
            mt.bias_n = terms && p.bias_n ? p.bias_n + jc + jr : nullptr;
            kern.micro(mt);
          }
        }
        for (int r = 0; r < mt.m; ++r) {
          const float* sr = strip + r * nc;
          float* cr = s.C + (i + r) * s.ldc + jc / 2;
          for (int64_t q = 0; q < ncols; q += 2 * g) ops.geglu(cr + q / 2, sr + q, sr + q + g, g);
        }
      }
    }
  };
  run_tasks(pool, m_tasks * n_tasks, task);
}

}  // namespace

void run_gemm(const GemmKernel& kern, const DriverShape& s, const Operand& a, const Operand& b,
              const GemmParams& p_in, ThreadPool* pool) {
  const int64_t M = s.M, N = s.N, K = s.K;
  if (M <= 0 || N <= 0) return;
  if (p_in.geglu_group > 0) {
    run_gemm_geglu(kern, s, a, b, p_in, pool);
    return;
  }
  GemmParams p = p_in;
  // A residual that is C itself, added after the last of several K blocks: fold it into beta so
  // that block does not read a C the earlier blocks overwrote. Added with the first block (or in
  // the only one), each tile reads it before it writes C, so it stays a residual and the sums
  // keep the order of a separate residual.
  if (p.residual == s.C && p.ldr == s.ldc && p.beta == 0.0f &&
      gemm_folds_aliased_residual(kern, K)) {
    p.residual = nullptr;
    p.beta = 1.0f;
  }
  const int mr = kern.mr, nr = kern.nr;
  const int64_t esz = packed_elem_bytes(kern.layout);
  const Tuning& tun = tuning();
  // K blocks of equal length (K = 1280 runs as 4 x 320, not 3 x 384 + 128: a short last block
  // pays the C read-back and the epilogue for few FMAs). KC depends on K only, never on the thread
  // count, so every split below gives bit-identical results.
  const int64_t KC = gemm_k_block(kern, K);
  const int64_t threads = pool ? pool->size() : 1;
  // B block KC x NC (streamed through L2 once per MR rows): about 7/16 of the L2 (448 KB of a
  // 1 MB L2), leaving room for C and for part of the A block (MC x KC: ~300 KB at KC 384, ~660 KB
  // at the KC of a 48 KB L1, which still ran faster, 2026-12-06).
  const int64_t nc_target =
      tun.nc > 0 ? tun.nc : std::max<int64_t>(nr, b_block_bytes() / std::max<int64_t>(1, KC * esz));
  const int64_t nc = s.nc > 0 ? s.nc : int64_t(nr) * std::max<int64_t>(1, nc_target / nr);
  // Tasks: row blocks of about MC rows, as many as a multiple of the thread count so the threads
  // get equal shares, but at least 4 micro-rows each; the columns are split only when there are
  // fewer row blocks than threads (then every task repacks its A block, so only as far as needed).
  const int64_t mc_target = tun.mc > 0 ? tun.mc : 192;
  int64_t mc, m_tasks, n_tasks;
  if (s.mc > 0) {
    mc = s.mc;
    m_tasks = (M + mc - 1) / mc;
  } else {
    m_tasks = (M + mc_target - 1) / mc_target;
    if (threads > 1)
      m_tasks = std::min(round_up(m_tasks, threads), std::max<int64_t>(1, M / (4 * mr)));
    mc = round_up((M + m_tasks - 1) / m_tasks, mr);
    m_tasks = (M + mc - 1) / mc;
  }
  if (threads == 1 || (s.mc == 0 && m_tasks >= threads) || (s.mc > 0 && s.m_only))
    n_tasks = 1;
  else
    n_tasks = std::clamp<int64_t>((4 * threads + m_tasks - 1) / m_tasks, 1, (N + nr - 1) / nr);
  const int64_t n_per_task = round_up((N + n_tasks - 1) / n_tasks, nr);
  n_tasks = (N + n_per_task - 1) / n_per_task;

  if (K <= 0) {
    // Nothing to accumulate: C = beta * C + bias + residual.
    for (int64_t i = 0; i < M; ++i)
      for (int64_t j = 0; j < N; ++j) {
        float& c = s.C[i * s.ldc + j];
        float v = p.beta != 0.0f ? p.beta * c : 0.0f;
        if (p.bias_n) v += p.bias_n[j];
        if (p.bias_m) v += p.bias_m[i];
        if (p.residual) v += p.residual[i * p.ldr + j];
        if (p.relu) v = v > 0.0f ? v : 0.0f;
        c = v;
      }
    return;
  }

  auto task = [&](int64_t t) {
    const int64_t ti = t / n_tasks, tj = t % n_tasks;
    const int64_t i0 = ti * mc, i1 = std::min(M, i0 + mc);
    const int64_t j0 = tj * n_per_task, j1 = std::min(N, j0 + n_per_task);
    if (j0 >= j1) return;
    const int64_t mrows = i1 - i0;
    for (int64_t pc = 0; pc < K; pc += KC) {
      const int64_t kc = std::min(KC, K - pc);
      const int64_t kcp = round_up(kc, kern.k_align);
      const bool first = pc == 0, last = pc + kc >= K;
      const bool terms = kern.terms_first ? first : last;  // this block adds bias and residual
      const unsigned char* abase;
      int64_t a_stride;  // bytes between A micro-panels
      if (a.prepacked) {
        abase = static_cast<const unsigned char*>(a.prepacked) +
                ((i0 / mr) * a.kp * mr + pc * mr) * esz;
        a_stride = a.kp * mr * esz;
      } else {
        void* buf = t_scratch_a.get(size_t(round_up(mrows, mr) * kcp * esz));
        a.pack(a.ctx, kern, true, i0, mrows, pc, kc, buf);
        abase = static_cast<const unsigned char*>(buf);
        a_stride = kcp * mr * esz;
      }
      for (int64_t jc = j0; jc < j1; jc += nc) {
        const int64_t ncols = std::min(nc, j1 - jc);
        const unsigned char* bbase;
        int64_t b_stride;
        if (b.prepacked) {
          bbase = static_cast<const unsigned char*>(b.prepacked) +
                  ((jc / nr) * b.kp * nr + pc * nr) * esz;
          b_stride = b.kp * nr * esz;
        } else {
          void* buf = t_scratch_b.get(size_t(round_up(ncols, nr) * kcp * esz));
          b.pack(b.ctx, kern, false, jc, ncols, pc, kc, buf);
          bbase = static_cast<const unsigned char*>(buf);
          b_stride = kcp * nr * esz;
        }
        MicroTile mt;
        mt.kc = kcp;
        mt.ldc = s.ldc;
        mt.alpha = p.alpha;
        mt.beta = first ? p.beta : 1.0f;
        mt.load_c = !first || p.beta != 0.0f;
        mt.ldr = p.ldr;
        for (int64_t ir = 0; ir < mrows; ir += mr) {
          const int64_t i = i0 + ir;
          mt.a = abase + (ir / mr) * a_stride;
          mt.m = int(std::min<int64_t>(mr, i1 - i));
          mt.bias_m = terms && p.bias_m ? p.bias_m + i : nullptr;
          mt.relu = last && p.relu;
          if (kern.strip) {
            mt.b = bbase;
            mt.c = s.C + i * s.ldc + jc;
            mt.bias_n = terms && p.bias_n ? p.bias_n + jc : nullptr;
            mt.res = terms && p.residual ? p.residual + i * p.ldr + jc : nullptr;
            kern.strip(mt, ncols, b_stride);
            continue;
          }
          for (int64_t jr = 0; jr < ncols; jr += nr) {
            const int64_t j = jc + jr;
            mt.b = bbase + (jr / nr) * b_stride;
            mt.n = int(std::min<int64_t>(nr, j1 - j));
            mt.c = s.C + i * s.ldc + j;
            mt.bias_n = terms && p.bias_n ? p.bias_n + j : nullptr;
            mt.res = terms && p.residual ? p.residual + i * p.ldr + j : nullptr;
            kern.micro(mt);
          }
        }
      }
    }
  };
  run_tasks(pool, m_tasks * n_tasks, task);
}

}  // namespace detail

const KernelTable& kernels_for(Isa isa) {
  const Tables& t = tables();
  MACRO_CHECK(t.filled[int(isa)]);
  return t.t[int(isa)];
}

const KernelTable& kernels() {
  return kernels_for(active_isa());
}

// ---- unpacked operands -------------------------------------------------------------------------

namespace {

struct MatrixSrc {
  const void* p;
  bool bf16;
  int64_t ld;
  bool transposed;  // S[r][k] = p[k * ld + r]
  int64_t R, K;
};

void pack_matrix(const void* ctx, const GemmKernel& kern, bool is_a, int64_t r0, int64_t rows,
                 int64_t k0, int64_t kc, void* dst) {
  const MatrixSrc& m = *static_cast<const MatrixSrc*>(ctx);
  const int w = is_a ? kern.mr : kern.nr;
  const int64_t kcp = detail::round_up(kc, kern.k_align);
  // B panels are always in the pairs layout; only A uses the AMX tile layout.
  PackLayout l = kern.layout;
  if (!is_a && l == PackLayout::kBf16Amx) l = PackLayout::kBf16Pairs;
  const PackPanelF32 fast = m.transposed ? kern.pack_a_f32_t : kern.pack_a_f32;
  if (is_a && !m.bf16 && fast) {
    const float* src = static_cast<const float*>(m.p);
    const int64_t valid_k = std::clamp<int64_t>(m.K - k0, 0, kc);
    const int64_t rend = std::min(r0 + rows, m.R);
    const int64_t panel_bytes = kcp * w * detail::packed_elem_bytes(l);
    for (int64_t p = 0; p * w < rows; ++p) {
      const int64_t pr0 = r0 + p * w;
      const int valid_r = int(std::clamp<int64_t>(rend - pr0, 0, w));
      const float* s = m.transposed ? src + k0 * m.ld + pr0 : src + pr0 * m.ld + k0;
      fast(s, m.ld, valid_r, valid_k, kcp, w, static_cast<unsigned char*>(dst) + p * panel_bytes);
    }
    return;
  }
  if (m.bf16) {
    detail::pack_panels_bf16(static_cast<const uint16_t*>(m.p), m.ld, m.transposed, m.R, m.K, l, w,
                             r0, rows, k0, kc, kcp, dst);
  } else {
    detail::pack_panels_f32(static_cast<const float*>(m.p), m.ld, m.transposed, m.R, m.K, l, w, r0,
                            rows, k0, kc, kcp, dst);
  }
}

void gemm_any(const GemmKernel& kern, int64_t M, int64_t N, int64_t K, const void* A, bool a_bf16,
              int64_t lda, const void* B, bool b_bf16, int64_t ldb, float* C, int64_t ldc,
              const GemmParams& p, ThreadPool* pool) {
  // A as S[m][k]: row-major A is "not transposed"; B as S[n][k]: trans_b B ([N, K]) is row-major S.
  MatrixSrc ma{A, a_bf16, lda, p.trans_a, M, K};
  // With many row blocks, pack B once for the whole call instead of once per row block.
  const int64_t row_blocks =
      (M + kern.mr * std::max(1, 192 / kern.mr) - 1) / (kern.mr * std::max(1, 192 / kern.mr));
  if (row_blocks >= 3 && (!b_bf16 || p.trans_b) && N >= 1 && K >= 1) {
    const WeightType t = kern.layout == PackLayout::kF32 ? WeightType::kF32 : WeightType::kBf16;
    const Isa isa = kernels().isa;
    PackedWeights pw =
        b_bf16      ? PackedWeights::pack(static_cast<const uint16_t*>(B), N, K, ldb, isa)
        : p.trans_b ? PackedWeights::pack(static_cast<const float*>(B), N, K, ldb, t, isa)
                    : PackedWeights::pack_kn(static_cast<const float*>(B), K, N, ldb, t, isa);
    if (&pw.kernel() == &kern) {
      detail::Operand oa{pack_matrix, &ma, nullptr, 0};
      detail::Operand ob{nullptr, nullptr, pw.panels(), pw.k_padded()};
      detail::DriverShape s{M, N, K, C, ldc, 0, 0};
      detail::run_gemm(kern, s, oa, ob, p, pool);
      return;
    }
  }
  MatrixSrc mb{B, b_bf16, ldb, !p.trans_b, N, K};
  detail::Operand oa{pack_matrix, &ma, nullptr, 0};
  detail::Operand ob{pack_matrix, &mb, nullptr, 0};
  detail::DriverShape s{M, N, K, C, ldc, 0, 0};
  detail::run_gemm(kern, s, oa, ob, p, pool);
}

}  // namespace

void gemm_f32(int64_t M, int64_t N, int64_t K, const float* A, int64_t lda, const float* B,
              int64_t ldb, float* C, int64_t ldc, const GemmParams& p, ThreadPool* pool) {
  gemm_any(kernels().f32, M, N, K, A, false, lda, B, false, ldb, C, ldc, p, pool);
}

void gemm_bf16(int64_t M, int64_t N, int64_t K, const uint16_t* A, int64_t lda, const uint16_t* B,
               int64_t ldb, float* C, int64_t ldc, const GemmParams& p, ThreadPool* pool) {
  gemm_any(kernels().bf16, M, N, K, A, true, lda, B, true, ldb, C, ldc, p, pool);
}

void gemm_bf16(int64_t M, int64_t N, int64_t K, const float* A, int64_t lda, const uint16_t* B,
               int64_t ldb, float* C, int64_t ldc, const GemmParams& p, ThreadPool* pool) {
  gemm_any(kernels().bf16, M, N, K, A, false, lda, B, true, ldb, C, ldc, p, pool);
}

// ---- packed weights ----------------------------------------------------------------------------

const GemmKernel& PackedWeights::kernel() const {
  const KernelTable& t = kernels_for(isa_);
  return type_ == WeightType::kF32 ? t.f32 : t.bf16;
}

PackedWeights PackedWeights::build(const void* src, bool src_bf16, bool transposed, int64_t rows,
                                   int64_t k, int64_t ld, WeightType type, Isa isa, bool as_a) {
  PackedWeights pw;
  pw.n_ = rows;
  pw.k_ = k;
  pw.type_ = type;
  pw.isa_ = isa;
  pw.as_a_ = as_a;
  const GemmKernel& kern = pw.kernel();
  const int w = as_a ? kern.mr : kern.nr;
  PackLayout l = kern.layout;
  if (!as_a && l == PackLayout::kBf16Amx) l = PackLayout::kBf16Pairs;
  pw.kp_ = detail::round_up(std::max<int64_t>(k, 1), kern.k_align);
  const int64_t elems = detail::round_up(rows, w) * pw.kp_;
  const int64_t bytes = elems * detail::packed_elem_bytes(l);
  pw.words_ = size_t((bytes + 3) / 4 + 16);
  pw.data_.reset(static_cast<float*>(large_zeroed(pw.words_ * sizeof(float))));
  if (src_bf16) {
    detail::pack_panels_bf16(static_cast<const uint16_t*>(src), ld, transposed, rows, k, l, w, 0,
                             rows, 0, k, pw.kp_, pw.data_.get());
  } else {
    detail::pack_panels_f32(static_cast<const float*>(src), ld, transposed, rows, k, l, w, 0, rows,
                            0, k, pw.kp_, pw.data_.get());
  }
  return pw;
}

PackedWeights PackedWeights::pack(const float* w, int64_t n, int64_t k, int64_t ldw,
                                  WeightType type, Isa isa) {
  return build(w, false, false, n, k, ldw, type, isa, false);
}
PackedWeights PackedWeights::pack(const uint16_t* w, int64_t n, int64_t k, int64_t ldw, Isa isa) {
  return build(w, true, false, n, k, ldw, WeightType::kBf16, isa, false);
}
PackedWeights PackedWeights::pack_kn(const float* b, int64_t k, int64_t n, int64_t ldb,
                                     WeightType type, Isa isa) {
  return build(b, false, true, n, k, ldb, type, isa, false);
}
PackedWeights PackedWeights::pack_as_a(const float* w, int64_t rows, int64_t k, int64_t ldw,
                                       WeightType type, Isa isa) {
  return build(w, false, false, rows, k, ldw, type, isa, true);
}

void gemm_packed(int64_t M, const float* A, int64_t lda, const PackedWeights& w, float* C,
                 int64_t ldc, const GemmParams& p, ThreadPool* pool) {
  MACRO_CHECK(!w.as_a());
  const GemmKernel& kern = w.kernel();
  MatrixSrc ma{A, false, lda, p.trans_a, M, w.k()};
  detail::Operand oa{pack_matrix, &ma, nullptr, 0};
  detail::Operand ob{nullptr, nullptr, w.panels(), w.k_padded()};
  detail::DriverShape s{M, w.n(), w.k(), C, ldc, 0, 0};
  detail::run_gemm(kern, s, oa, ob, p, pool);
}

}  // namespace macro
