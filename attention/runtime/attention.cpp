// Fused attention: argument checks, work split, per-thread scratch and the scalar twin of the
// block kernel (see attention.h). The SIMD block kernels live in attention_avx2.cpp and
// attention_avx512.cpp (shared template in attention_simd.h).
//
// Algorithm of one (head h, query block) item, all paths:
//   m = -inf, l = 0, O = 0                                  // per row, base-2 logits
//   for each listed key block (ascending):
//     S = (Q K^T) * scale * log2(e), -inf where masked or beyond Nk     // [BQ, BK]
//     m' = max(m, rowmax S); alpha = 2^(m - m'); P = 2^(S - m')         // rows with m' = -inf: P =
//     0 l = alpha l + rowsum P;  O = alpha O + P V;  m = m'
//   out = O / l, or 0 where l == 0 (a row that may attend to nothing).
#include "attention/runtime/attention.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "attention/runtime/half.h"

namespace macro {
namespace attention_detail {
namespace {

constexpr int kBQ = kAttnBlockQ;
constexpr int kBK = kAttnBlockK;
constexpr float kLog2e = 1.4426950408889634f;

// ---- scalar twin ------------------------------------------------------------------------------

// m = -inf, l = 0, O = 0 for the job's rows.
void reset_rows(const BlockJob& job, const BlockScratch& sc) {
  for (int r = 0; r < job.rows; ++r) {
    sc.m[r] = -std::numeric_limits<float>::infinity();
    sc.l[r] = 0;
    std::fill(sc.o + size_t(r) * job.d, sc.o + size_t(r + 1) * job.d, 0.0f);
  }
}

// Online-softmax update of one row's base-2 scores s[cols] in place (probabilities out); returns
// alpha, the factor the row's accumulator must be rescaled by.
float softmax_row(float* s, int cols, float& m, float& l) {
  const float neg_inf = -std::numeric_limits<float>::infinity();
  float mx = neg_inf;
  for (int c = 0; c < cols; ++c) mx = std::max(mx, s[c]);
  const float m_new = std::max(m, mx);
  if (m_new == neg_inf) {
    std::fill(s, s + cols, 0.0f);
    return 1.0f;
  }
  const float alpha = std::exp2(m - m_new);
  float sum = 0;
  for (int c = 0; c < cols; ++c) {
    s[c] = std::exp2(s[c] - m_new);
    sum += s[c];
  }
  l = l * alpha + sum;
  m = m_new;
  return alpha;
}

// out = O / l, or 0 for a row that attended to nothing.
void finish_rows(const BlockJob& job, const BlockScratch& sc) {
  for (int r = 0; r < job.rows; ++r) {
    const float inv = sc.l[r] > 0 ? 1.0f / sc.l[r] : 0.0f;
    const float* o = sc.o + size_t(r) * job.d;
    for (int i = 0; i < job.d; ++i) job.out_rows[r][i] = o[i] * inv;
  }
}

void block_scalar(const BlockJob& job, const BlockScratch& sc) {
  const int d = job.d;
  const float neg_inf = -std::numeric_limits<float>::infinity();
  reset_rows(job, sc);
  const float* k_rows[kBK];
  for (int e = 0; e < job.entries; ++e) {
    const int kb = job.key_blocks[e];
    const int cols = std::min(kBK, job.nk - kb * kBK);
    const uint8_t* tile = job.tiles[e];
    key_block_rows(job, kb, cols, job.k, job.v, job.k_stride, job.v_stride, k_rows, sc.v_rows);
    for (int r = 0; r < job.rows; ++r) {
      float* s = sc.s + size_t(r) * kBK;
      const float* q = job.q_rows[r];
      for (int c = 0; c < cols; ++c) {
        float acc = 0;
        for (int i = 0; i < d; ++i) acc += q[i] * k_rows[c][i];
        s[c] = (tile && !tile[tile_offset(r, c)]) ? neg_inf : acc * job.scale_log2e;
      }
      const float alpha = softmax_row(s, cols, sc.m[r], sc.l[r]);
      float* o = sc.o + size_t(r) * d;
      for (int i = 0; i < d; ++i) o[i] *= alpha;
      for (int c = 0; c < cols; ++c) {
        const float p = s[c];
        const float* vr = sc.v_rows[c];
        for (int i = 0; i < d; ++i) o[i] += p * vr[i];
      }
    }
  }
  finish_rows(job, sc);
}

void blocks_scalar(const BlockJob* jobs, int count, const BlockScratch* scratch) {
  for (int g = 0; g < count; ++g) block_scalar(jobs[g], scratch[g]);
}

// The bf16 twin: the roundings of the avx512bf16 kernel (Q pre-scaled then rounded, K and V from
// the rounded copies, P rounded per tile) and vdpbf16ps's order within a pair (odd element, then
// even, each product exact, each sum rounded in fp32). exp2 is std::exp2 here, a polynomial there.
// sum over pairs of q[i+1] k[i+1] + q[i] k[i], one rounding per addition (vdpbf16ps's order).
// The empty asm keeps the loop scalar: GCC 12.2's -O3 loop vectorizer miscompiles this in-order
// reduction (it counted the first product twice).
float dot_pairs(const float* q, const uint16_t* k, int d) {
  float acc = 0;
  for (int i = 0; i < d; i += 2) {
    acc += q[i + 1] * bf16_to_f32(k[i + 1]);
    acc += q[i] * bf16_to_f32(k[i]);
    __asm__("" : "+x"(acc));
  }
  return acc;
}

void block_scalar_bf16(const BlockJob& job, const BlockScratch& sc) {
  const int d = job.d;
  const float neg_inf = -std::numeric_limits<float>::infinity();
  auto r16 = [](float x) { return bf16_to_f32(f32_to_bf16(x)); };
  float* qr = sc.qt;  // [BQ, D] rounded, pre-scaled Q
  reset_rows(job, sc);
  for (int r = 0; r < job.rows; ++r)
    for (int i = 0; i < d; ++i) qr[size_t(r) * d + i] = r16(job.q_rows[r][i] * job.scale_log2e);
  const uint16_t* k_rows[kBK];
  const uint16_t* v_rows[kBK];
  float p[kBK + 1];
  for (int e = 0; e < job.entries; ++e) {
    const int kb = job.key_blocks[e];
    const int cols = std::min(kBK, job.nk - kb * kBK);
    const uint8_t* tile = job.tiles[e];
    key_block_rows(job, kb, cols, job.k16, job.v16, job.kv16_stride, job.kv16_stride, k_rows,
                   v_rows);
    for (int r = 0; r < job.rows; ++r) {
      float* s = sc.s + size_t(r) * kBK;
      const float* q = qr + size_t(r) * d;
      for (int c = 0; c < cols; ++c) {
        s[c] = (tile && !tile[tile_offset(r, c)]) ? neg_inf : dot_pairs(q, k_rows[c], d);
      }
      const float alpha = softmax_row(s, cols, sc.m[r], sc.l[r]);
      for (int c = 0; c < cols; ++c) p[c] = r16(s[c]);
      p[cols] = 0;
      float* o = sc.o + size_t(r) * d;
      for (int i = 0; i < d; ++i) o[i] *= alpha;
      for (int c = 0; c < cols; c += 2) {
        const uint16_t* va = v_rows[c];
        const uint16_t* vb = c + 1 < cols ? v_rows[c + 1] : nullptr;
        for (int i = 0; i < d; ++i) {
          o[i] += p[c + 1] * (vb ? bf16_to_f32(vb[i]) : 0.0f);
          o[i] += p[c] * bf16_to_f32(va[i]);
        }
      }
    }
  }
  finish_rows(job, sc);
}

void blocks_scalar_bf16(const BlockJob* jobs, int count, const BlockScratch* scratch) {
  for (int g = 0; g < count; ++g) block_scalar_bf16(jobs[g], scratch[g]);
}

void to_bf16_scalar(const float* src, uint16_t* dst, size_t n) {
  for (size_t i = 0; i < n; ++i) dst[i] = f32_to_bf16(src[i]);
}

void score_tile_scalar(const float* const* k_rows, int keys, const float* qt, int d, float* s) {
  for (int c = 0; c < keys; ++c) {
    float* sc = s + size_t(c) * kBQ;
    std::fill(sc, sc + kBQ, 0.0f);
    for (int i = 0; i < d; ++i) {
      const float k = k_rows[c][i];
      const float* q = qt + size_t(i) * kBQ;
      for (int r = 0; r < kBQ; ++r) sc[r] += k * q[r];
    }
  }
}

double fma_peak_scalar(int64_t iterations) {
  float a[8] = {1, 1, 1, 1, 1, 1, 1, 1};
  const float x = 0.999999f, y = 1e-7f;
  for (int64_t it = 0; it < iterations; ++it)
    for (float& v : a) v = v * x + y;
  volatile float sink = a[0] + a[1] + a[2] + a[3] + a[4] + a[5] + a[6] + a[7];
  (void)sink;
  return 2.0 * 8 * double(iterations);
}

// ---- driver ------------------------------------------------------------------------------------

size_t align_up(size_t n) {
  return (n + 15) & ~size_t(15);
}  // floats, to 64 bytes

struct ScratchLayout {
  size_t qt, s, o, m, l, alpha, pp, vp, total;  // offsets in floats; pp, vp: bf16 kernels only
  ScratchLayout(int d, bool bf16) {
    qt = 0;
    s = qt + align_up(size_t(d) * kBQ);
    o = s + align_up(size_t(kBQ) * kBK);
    m = o + align_up(size_t(kBQ) * d);
    l = m + align_up(kBQ);
    alpha = l + align_up(kBQ);
    pp = alpha + align_up(kBQ);
    vp = pp + (bf16 ? align_up(size_t(kBK / 2) * kBQ) : 0);
    total = vp + (bf16 ? align_up(size_t(kBK / 2) * d) : 0);
  }
};

// K and V rounded to bf16 for the bf16 kernels: per calling thread, grown to the largest call and
// reused (attention is not re-entrant on one thread).
std::vector<uint16_t>& kv16_buffer() {
  thread_local std::vector<uint16_t> buf;
  return buf;
}

Status check_args(const AttentionArgs& a) {
  auto fail = [](const std::string& what) { return Status::error("attention: " + what); };
  if (a.nq < 0 || a.nk < 0)
    return fail("negative token count (nq " + std::to_string(a.nq) + ", nk " +
                std::to_string(a.nk) + ")");
  if (a.heads <= 0) return fail("heads must be positive, found " + std::to_string(a.heads));
  if (a.head_dim <= 0 || a.head_dim > kMaxHeadDim)
    return fail("head_dim must be in [1, " + std::to_string(kMaxHeadDim) + "], found " +
                std::to_string(a.head_dim));
  const size_t c = size_t(a.heads) * size_t(a.head_dim);
  auto check_stride = [&](size_t s, const char* name) -> Status {
    if (s != 0 && s < c)
      return fail(std::string(name) + " row stride " + std::to_string(s) +
                  " is smaller than heads * head_dim = " + std::to_string(c));
    return Status::ok();
  };
  MACRO_TRY(check_stride(a.q_stride, "q"));
  MACRO_TRY(check_stride(a.k_stride, "k"));
  MACRO_TRY(check_stride(a.v_stride, "v"));
  MACRO_TRY(check_stride(a.out_stride, "out"));
  if (a.nq > 0 && (!a.q || !a.out)) return fail("null q or out");
  if (a.nq > 0 && a.nk > 0 && (!a.k || !a.v)) return fail("null k or v");
  if (!(a.scale >= 0) || !std::isfinite(a.scale))
    return fail("scale must be finite and >= 0 (0 = 1/sqrt(head_dim)), found " +
                std::to_string(a.scale));
  if (a.mask) {
    const BlockSparseMask& m = *a.mask;
    if (m.nq != a.nq || m.nk != a.nk)
      return fail("mask is " + std::to_string(m.nq) + " x " + std::to_string(m.nk) +
                  ", expected nq x nk = " + std::to_string(a.nq) + " x " + std::to_string(a.nk));
    MACRO_TRY(m.validate().with_context("attention"));
    if (a.causal && (!m.query_index.empty() || !m.key_index.empty()))
      return fail("causal attention cannot combine with a mask that reorders tokens");
  }
  return Status::ok();
}

const AttentionKernels& pick_kernels(Isa isa, int d) {
  // Fall back to narrower paths when the head dim does not fit the vector width.
  const AttentionKernels* k = &kernels_for(isa);
  if (d % k->d_multiple && k->isa >= Isa::kAvx512) k = &avx2_kernels();
  if (d % k->d_multiple) k = &scalar_kernels();
  return *k;
}

// bf16_ok: kern is the path's own table (not a fallback for an awkward head dim), so a bf16 request
// may use its bf16 kernel.
Status run(const AttentionArgs& in, const AttentionKernels& kern, bool bf16_ok, ThreadPool& pool) {
  MACRO_TRY(check_args(in));
  AttentionArgs a = in;
  const int d = a.head_dim;
  const size_t c = size_t(a.heads) * size_t(d);
  if (!a.q_stride) a.q_stride = c;
  if (!a.k_stride) a.k_stride = c;
  if (!a.v_stride) a.v_stride = c;
  if (!a.out_stride) a.out_stride = c;
  if (a.scale == 0) a.scale = 1.0f / std::sqrt(float(d));
  if (a.nq == 0) return Status::ok();

  const BlockSparseMask* mask = a.mask;
  const int nqb = (a.nq + kBQ - 1) / kBQ, nkb = (a.nk + kBK - 1) / kBK;
  const bool bf16 = a.bf16 && bf16_ok && kern.block_bf16 && d % kern.bf16_d_multiple == 0;
  const BlockFn block = bf16 ? kern.block_bf16 : kern.block;
  const ScratchLayout layout(d, bf16);
  const uint16_t* k16 = nullptr;
  const uint16_t* v16 = nullptr;
  const Bf16Layout layout16 = bf16 ? kern.bf16_layout : Bf16Layout::kRows;
  const bool tiles = layout16 == Bf16Layout::kTiles, pairs = layout16 == Bf16Layout::kPairs;
  // Tile layouts: whole key blocks of mask columns (zero past nk).
  const size_t ncol = tiles ? size_t(nkb) * kBK : size_t(a.nk);
  if (bf16 && a.nk > 0) {
    std::vector<uint16_t>& buf = kv16_buffer();
    // Pairs: V padded to whole key blocks (the missing partner of an odd last column is zero).
    const size_t need = ncol * c + (pairs ? size_t(nkb) * kBK : ncol) * c;
    if (buf.size() < need) buf.resize(need);
    uint16_t* kb16 = buf.data();
    uint16_t* vb16 = kb16 + ncol * c;
    const int32_t* key_index = mask && !mask->key_index.empty() ? mask->key_index.data() : nullptr;
    auto token = [&](size_t j) { return key_index ? size_t(key_index[j]) : j; };
    if (layout16 == Bf16Layout::kRows) {
      pool.parallel_for(size_t(a.nk), [&](size_t begin, size_t end, int) {
        for (size_t j = begin; j < end; ++j) {
          kern.to_bf16(a.k + j * a.k_stride, kb16 + j * c, c);
          kern.to_bf16(a.v + j * a.v_stride, vb16 + j * c, c);
        }
      });
    } else if (tiles) {
      // K row of mask column j, and V transposed per key block:
      // vb16[(kb * c + i) * BK + jj] = V[token of column kb * BK + jj][i].
      pool.parallel_for(size_t(nkb), [&](size_t begin, size_t end, int) {
        std::vector<uint16_t> row(c);
        for (size_t kb = begin; kb < end; ++kb) {
          uint16_t* vt = vb16 + kb * c * kBK;
          for (size_t jj = 0; jj < size_t(kBK); ++jj) {
            const size_t j = kb * kBK + jj;
            if (j >= size_t(a.nk)) {
              std::fill(kb16 + j * c, kb16 + (j + 1) * c, uint16_t(0));
              for (size_t i = 0; i < c; ++i) vt[i * kBK + jj] = 0;
              continue;
            }
            kern.to_bf16(a.k + token(j) * a.k_stride, kb16 + j * c, c);
            kern.to_bf16(a.v + token(j) * a.v_stride, row.data(), c);
            for (size_t i = 0; i < c; ++i) vt[i * kBK + jj] = row[i];
          }
        }
      });
    } else {
      // Per head h: K row of mask column j at kb16 + (h nk + j) D; V pair words of columns
      // (2p, 2p + 1) of the whole padded sequence at vb16 + 2 ((h nkb BK / 2 + p) D + i).
      const size_t dd = size_t(d), npairs = size_t(nkb) * kBK / 2;
      // Column j: its K rows into place, its V row (zero past nk) into `row`; V is rounded by the
      // table's to_bf16 like K, then interleaved into pair words (once per call, off the hot loop).
      auto column = [&](size_t j, std::vector<uint16_t>& row) {
        if (j >= size_t(a.nk)) {
          std::fill(row.begin(), row.end(), uint16_t(0));
          return;
        }
        kern.to_bf16(a.v + token(j) * a.v_stride, row.data(), c);
        for (int h = 0; h < a.heads; ++h)
          kern.to_bf16(a.k + token(j) * a.k_stride + size_t(h) * dd,
                       kb16 + (size_t(h) * a.nk + j) * dd, dd);
      };
      pool.parallel_for(npairs, [&](size_t begin, size_t end, int) {
        std::vector<uint16_t> lo(c), hi(c);
        for (size_t p = begin; p < end; ++p) {
          column(2 * p, lo);
          column(2 * p + 1, hi);
          for (int h = 0; h < a.heads; ++h) {
            uint16_t* w = vb16 + 2 * ((size_t(h) * npairs + p) * dd);
            const uint16_t* l = lo.data() + size_t(h) * dd;
            const uint16_t* u = hi.data() + size_t(h) * dd;
            for (size_t i = 0; i < dd; ++i) {
              w[2 * i] = l[i];
              w[2 * i + 1] = u[i];
            }
          }
        }
      });
    }
    k16 = kb16;
    v16 = vb16;
  }
  // Query blocks per work item: the group's blocks share each K/V block while it is in cache.
  // Keep the group's scratch near a quarter of the L2 (256 KiB of 1 MB), which holds it with the
  // K/V blocks.
  static const long group_bytes = l2_block_bytes(1, 4, 256 << 10);
  const int group =
      std::clamp(int(size_t(group_bytes) / (layout.total * sizeof(float))), 1, kMaxGroup);
  const int groups = (nqb + group - 1) / group;
  // Per worker and group slot: floats (layout), entry lists, row pointers, one causal tile.
  struct Slot {
    std::vector<int32_t> key_blocks;
    std::vector<const uint8_t*> tiles;
    std::vector<uint8_t> causal_tile;
    const float* q_rows[kBQ];
    float* out_rows[kBQ];
    const float* v_rows[kBK];
  };
  const int workers = pool.size();
  const size_t slots = size_t(workers) * size_t(group);
  std::unique_ptr<float[]> floats(new float[layout.total * slots + 16]);
  float* base =
      reinterpret_cast<float*>((reinterpret_cast<uintptr_t>(floats.get()) + 63) & ~uintptr_t(63));
  std::vector<Slot> slot(slots);
  for (auto& b : slot) {
    b.key_blocks.resize(size_t(std::max(nkb, 1)));
    b.tiles.resize(size_t(std::max(nkb, 1)));
    if (a.causal) b.causal_tile.resize(size_t(kBQ) * kBK);
  }

  // Fill job j (query block qb of head h) in slot b.
  auto prepare = [&](int h, int qb, Slot& b, BlockJob& job) {
    const int rows = std::min(kBQ, a.nq - qb * kBQ);
    for (int r = 0; r < rows; ++r) {
      const int mr = qb * kBQ + r;
      const size_t i =
          mask && !mask->query_index.empty() ? size_t(mask->query_index[size_t(mr)]) : mr;
      b.q_rows[r] = a.q + i * a.q_stride + size_t(h) * d;
      b.out_rows[r] = a.out + i * a.out_stride + size_t(h) * d;
    }
    // Key blocks this query block visits.
    int entries = 0;
    if (mask) {
      for (int e = mask->block_begin[size_t(qb)]; e < mask->block_begin[size_t(qb) + 1]; ++e) {
        b.key_blocks[size_t(entries)] = mask->key_block[size_t(e)];
        b.tiles[size_t(entries)] = mask->tile_data(mask->tile[size_t(e)]);
        ++entries;
      }
    } else {
      for (int kb = 0; kb < nkb; ++kb) {
        b.key_blocks[size_t(kb)] = kb;
        b.tiles[size_t(kb)] = nullptr;
      }
      entries = nkb;
    }
    if (a.causal) {  // keep key blocks that start at or before the last row of the block
      const int last_row = qb * kBQ + rows - 1;
      int kept = 0;
      for (int e = 0; e < entries; ++e) {
        const int kb = b.key_blocks[size_t(e)];
        if (kb * kBK > last_row) continue;
        const uint8_t* t = b.tiles[size_t(e)];
        if (kb * kBK + kBK - 1 > qb * kBQ) {  // crosses the diagonal: combine tiles
          uint8_t* ct = b.causal_tile.data();
          for (int r = 0; r < kBQ; ++r)
            for (int cc = 0; cc < kBK; ++cc)
              ct[tile_offset(r, cc)] =
                  (kb * kBK + cc <= qb * kBQ + r) && (!t || t[tile_offset(r, cc)]);
          t = ct;  // only one block per query block can cross (BQ == BK)
        }
        b.key_blocks[size_t(kept)] = kb;
        b.tiles[size_t(kept)] = t;
        ++kept;
      }
      entries = kept;
    }
    job.rows = rows;
    job.d = d;
    job.scale_log2e = a.scale * kLog2e;
    job.q_rows = b.q_rows;
    job.out_rows = b.out_rows;
    job.entries = entries;
    job.key_blocks = b.key_blocks.data();
    job.tiles = b.tiles.data();
    job.k = a.k ? a.k + size_t(h) * d : nullptr;
    job.v = a.v ? a.v + size_t(h) * d : nullptr;
    job.k_stride = a.k_stride;
    job.v_stride = a.v_stride;
    job.key_index = mask && !mask->key_index.empty() ? mask->key_index.data() : nullptr;
    job.nk = a.nk;
    if (pairs) {
      job.k16 = k16 + size_t(h) * size_t(a.nk) * d;
      job.v16 = v16 + size_t(h) * size_t(nkb) * kBK * d;
      job.kv16_stride = size_t(d);
    } else {
      job.k16 = k16 ? k16 + size_t(h) * d : nullptr;
      job.v16 = v16 ? v16 + (tiles ? size_t(h) * d * kBK : size_t(h) * d) : nullptr;
      job.kv16_stride = c;
    }
  };

  const size_t items = size_t(groups) * size_t(a.heads);
  pool.parallel_for(
      items,
      [&](size_t begin, size_t end, int worker) {
        BlockJob jobs[kMaxGroup];
        BlockScratch scratch[kMaxGroup];
        for (int g = 0; g < group; ++g) {
          const size_t k = size_t(worker) * size_t(group) + size_t(g);
          float* w = base + layout.total * k;
          scratch[g] = BlockScratch{w + layout.qt, w + layout.s,     w + layout.o,  w + layout.m,
                                    w + layout.l,  w + layout.alpha, slot[k].v_rows};
          if (bf16) {
            scratch[g].pp = reinterpret_cast<uint32_t*>(w + layout.pp);
            scratch[g].vp = reinterpret_cast<uint32_t*>(w + layout.vp);
          }
        }
        for (size_t item = begin; item < end; ++item) {
          // Head-major: the workers walk one head's query groups together, so that head's K/V
          // stays in the shared cache instead of cycling through every head's per group.
          const int h = int(item / size_t(groups));
          const int qb0 = int(item % size_t(groups)) * group;
          const int count = std::min(group, nqb - qb0);
          for (int g = 0; g < count; ++g)
            prepare(h, qb0 + g, slot[size_t(worker) * size_t(group) + size_t(g)], jobs[g]);
          block(jobs, count, scratch);
        }
      },
      1);
  return Status::ok();
}

}  // namespace

static_assert(kAttnBlockQ == kAttnBlockK, "the causal split assumes square tiles");

const AttentionKernels& scalar_kernels() {
  static const AttentionKernels k{
      Isa::kScalar,       1, blocks_scalar, score_tile_scalar, fma_peak_scalar,
      blocks_scalar_bf16, 2, to_bf16_scalar};
  return k;
}

const AttentionKernels& kernels_for(Isa isa) {
  switch (isa) {
    case Isa::kAmx:
      return amx_kernels();
    case Isa::kAvx512Bf16:
      return avx512bf16_kernels();
    case Isa::kAvx512:
      return avx512_kernels();
    case Isa::kAvx2:
      return avx2_kernels();
    case Isa::kScalar:
      break;
  }
  return scalar_kernels();
}

}  // namespace attention_detail

Status attention(const AttentionArgs& args, ThreadPool& pool) {
  return attention_with_isa(args, active_isa(), pool);
}

Status attention_with_isa(const AttentionArgs& args, Isa isa, ThreadPool& pool) {
  if (!isa_supported(isa))
    return Status::error(std::string("attention: path ") + isa_name(isa) +
                         " is not supported on this machine");
  const auto& kern = attention_detail::pick_kernels(isa, args.head_dim);
  return attention_detail::run(args, kern, &kern == &attention_detail::kernels_for(isa), pool);
}

}  // namespace macro
