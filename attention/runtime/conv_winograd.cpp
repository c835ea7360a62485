// Winograd F(2x2, 3x3) bf16 and fp32 convs (conv_winograd.h): the weight transform and packing,
// the mode switch, the chunk driver over the GEMM driver, and the scalar transforms (the twins of
// conv_winograd_avx512.cpp and conv_winograd_avx512bf16.cpp, bit for bit).
//
// Per chunk of tiles (one image, T tiles in raster order, split into runs on one tile row):
//   V [16][T/NR panels][K rows][NR]  the prepacked B operand of the path's kernel: bf16 pair
//                                    words (K rows = Kp/2) or fp32 values (K rows = Cin)
//   for each block of output channels (a multiple of MR):
//     M_xi [co_blk][T] = U_xi[co block] . V_xi       16 run_gemm calls, prepacked A and B
//     y[co block, the chunk's pixels] = A^T M A + bias (+ residual) (ReLU)
// Work items are (image, chunk, part of the channel blocks) on the pool; each worker has its own
// V/M/runs slot, owned by the calling thread and grown once.
#include "attention/runtime/conv_winograd.h"

#include <algorithm>
#include <bit>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>

#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/scratch.h"
#include "attention/runtime/status.h"

namespace macro {
namespace {

// ---- mode ---------------------------------------------------------------------------------------

ConvWinograd mode_from_env() {
  const char* v = std::getenv("MACRO_CONV_WINOGRAD");
  if (!v || !*v) return ConvWinograd::kAuto;
  const std::string s(v);
  if (s == "0" || s == "off") return ConvWinograd::kOff;
  if (s == "always" || s == "2") return ConvWinograd::kAlways;
  return ConvWinograd::kAuto;
}

ConvWinograd& mode_ref() {
  static ConvWinograd m = mode_from_env();
  return m;
}
size_t g_chunk_tiles = 0;  // 0: auto

// Auto rule (measured, docs/PERFORMANCE.md "Winograd bf16 conv").
// 1280 channels is faster too (1.5x) but its packs would add ~1.6 GB to the SD-Turbo U-Net.
constexpr int64_t kAutoMinChannels = 64, kAutoMaxChannels = 640;
constexpr int64_t kAutoMinTiles = 64;  // per image
// Chunk sizing: V of a chunk (16 x T x Cin2 bf16) about kVBytes, M of a channel block
// (16 x co_blk x T fp32) about kMBytes. MACRO_WINO_V_KB / MACRO_WINO_M_KB override them (tuning).
// Measured (bench winograd, 2026-11-22): V 2-4 MB with M 128 KB (so one MR block of channels
// for T >= 128) beats V 512 KB / M 256 KB by 5-25% on every VAE and U-Net shape.
// Chunks are capped at 256 tiles: at 128 channels (T would be 512) 128 or 256 tiles are ~10%
// faster in CPU time; at 256 channels 256 tiles are ~3% faster than 128.
// Both budgets follow the CPU's L2 (twice it for V, an eighth for M; the constants are those of a
// 1 MB L2, used where its size is unknown; cpu.h's l2_block_bytes clamps to [1/2, 4] of them).
constexpr int64_t kVBytes = 2048 * 1024, kMBytes = 128 * 1024, kMaxAutoTiles = 256;
struct Budgets {
  int64_t v = kVBytes, m = kMBytes;
};
const Budgets& budgets() {
  static const Budgets b = [] {
    Budgets r;
    r.v = l2_block_bytes(2, 1, kVBytes);
    r.m = l2_block_bytes(1, 8, kMBytes);
    if (const char* e = std::getenv("MACRO_WINO_V_KB"))
      r.v = std::max<int64_t>(1, std::atoll(e)) * 1024;
    if (const char* e = std::getenv("MACRO_WINO_M_KB"))
      r.m = std::max<int64_t>(1, std::atoll(e)) * 1024;
    return r;
  }();
  return b;
}

// bf16 bits of f as vcvtne2ps2bf16 rounds: nearest even, NaN quiet, fp32 denormals to (signed)
// zero (the instruction treats denormal inputs as zero).
inline uint32_t bf16_bits_daz(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  if ((u & 0x7f800000u) == 0) return (u >> 16) & 0x8000u;
  const uint32_t r = (u + 0x7fffu + ((u >> 16) & 1u)) >> 16;
  return (u & 0x7fffffffu) > 0x7f800000u ? ((u >> 16) | 0x40u) : r;
}

// ---- scalar transforms -----------------------------------------------------------------------

// V = B^T d B for one 4x4 patch d[i * 4 + j]; the vector code does the same adds in this order.
inline void input_tile(const float* d, float* v) {
  float r[16];
  for (int j = 0; j < 4; ++j) {
    r[0 * 4 + j] = d[0 * 4 + j] - d[2 * 4 + j];
    r[1 * 4 + j] = d[1 * 4 + j] + d[2 * 4 + j];
    r[2 * 4 + j] = d[2 * 4 + j] - d[1 * 4 + j];
    r[3 * 4 + j] = d[1 * 4 + j] - d[3 * 4 + j];
  }
  for (int i = 0; i < 4; ++i) {
    const float* ri = r + i * 4;
    v[i * 4 + 0] = ri[0] - ri[2];
    v[i * 4 + 1] = ri[1] + ri[2];
    v[i * 4 + 2] = ri[2] - ri[1];
    v[i * 4 + 3] = ri[1] - ri[3];
  }
}

// The 4x4 patch of plane p (H x W) at input row iy0, column ix0 (zeros outside).
inline void load_patch(const float* p, int64_t h, int64_t w, int64_t iy0, int64_t ix0, float* d) {
  for (int i = 0; i < 4; ++i) {
    const int64_t iy = iy0 + i;
    for (int j = 0; j < 4; ++j) {
      const int64_t ix = ix0 + j;
      d[i * 4 + j] = p && iy >= 0 && iy < h && ix >= 0 && ix < w ? p[iy * w + ix] : 0.0f;
    }
  }
}

void input_scalar(const detail::WinoInput& a) {
  const int64_t hw = a.h * a.w;
  // Row q of the panels: channel q (fp32) or the pair of channels 2q, 2q + 1 (bf16).
  for (int64_t q = a.q0; q < a.q1; ++q) {
    const int64_t c0 = a.f32 ? q : 2 * q, c1 = c0 + 1;
    const float* p0 = c0 < a.c_in ? a.x + c0 * hw : nullptr;
    const float* p1 = !a.f32 && c1 < a.c_in ? a.x + c1 * hw : nullptr;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      const int64_t iy0 = 2 * run.ty - a.row_phase - a.pad_top;
      for (int l = 0; l < run.len; ++l) {
        const int64_t ix0 = 2 * (run.tx0 + l) - a.pad_left;
        const int col = run.col + l;
        float d0[16], d1[16], v0[16], v1[16];
        load_patch(p0, a.h, a.w, iy0, ix0, d0);
        input_tile(d0, v0);
        if (!a.f32) {
          load_patch(p1, a.h, a.w, iy0, ix0, d1);
          input_tile(d1, v1);
        }
        uint32_t* dst = a.v + (col / a.nr) * a.k_rows * a.nr + q * a.nr + col % a.nr;
        for (int xi = 0; xi < 16; ++xi)
          dst[xi * a.xi_stride] = a.f32 ? std::bit_cast<uint32_t>(v0[xi])
                                        : bf16_bits_daz(v0[xi]) | (bf16_bits_daz(v1[xi]) << 16);
      }
    }
  }
}

void output_scalar(const detail::WinoOutput& a) {
  for (int64_t c = a.co0; c < a.co0 + a.nco; ++c) {
    const float* mc = a.m + (c - a.co0) * a.ldm;
    float* yc = a.y + c * a.plane;
    const float* rc = a.residual ? a.residual + c * a.plane : nullptr;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      for (int l = 0; l < run.len; ++l) {
        const int col = run.col + l;
        float m[16], t[8], y[4];
        for (int xi = 0; xi < 16; ++xi) m[xi] = mc[xi * a.xi_stride + col];
        for (int j = 0; j < 4; ++j) {
          t[0 * 4 + j] = (m[0 * 4 + j] + m[1 * 4 + j]) + m[2 * 4 + j];
          t[1 * 4 + j] = (m[1 * 4 + j] - m[2 * 4 + j]) - m[3 * 4 + j];
        }
        for (int i = 0; i < 2; ++i) {
          const float* ti = t + i * 4;
          y[i * 2 + 0] = (ti[0] + ti[1]) + ti[2];
          y[i * 2 + 1] = (ti[1] - ti[2]) - ti[3];
        }
        for (int i = 0; i < 2; ++i) {
          const int64_t oy = 2 * run.ty - a.row_phase + i;
          if (oy < 0 || oy >= a.oh) continue;
          for (int j = 0; j < 2; ++j) {
            const int64_t ox = 2 * (run.tx0 + l) + j;
            if (ox >= a.ow) continue;
            float v = y[i * 2 + j];
            if (a.bias) v += a.bias[c];
            if (rc) v += rc[oy * a.ow + ox];
            if (a.relu) v = v > 0.0f ? v : 0.0f;
            yc[oy * a.ow + ox] = v;
          }
        }
      }
    }
  }
}

// ---- chunk driver ------------------------------------------------------------------------------

// Tiles [t0, t0 + nt) of a TW-wide tile grid as runs (WinoRun's contract).
int make_runs(int64_t t0, int64_t nt, int64_t tw, detail::WinoRun* runs) {
  int n = 0;
  for (int64_t col = 0; col < nt;) {
    const int64_t t = t0 + col, ty = t / tw, tx = t % tw;
    const int64_t len = std::min({nt - col, tw - tx, 16 - col % 16});
    runs[n++] = detail::WinoRun{ty, tx, int(col), int(len)};
    col += len;
  }
  return n;
}

// Typed view of a per-thread scratch buffer (scratch.h): room for `cap` elements.
template <typename T>
struct Buffer {
  detail::AlignedScratch mem;
  size_t cap = 0;  // elements
  T* data = nullptr;
  void reserve(size_t n) {
    if (n <= cap) return;
    data = static_cast<T*>(mem.get(n * sizeof(T)));
    cap = n;
  }
};

struct Slot {
  Buffer<uint32_t> v;
  Buffer<float> m;
  Buffer<detail::WinoRun> runs;
};
thread_local std::vector<Slot> t_slots;  // one per pool worker, owned by the calling thread

}  // namespace

ConvWinograd conv2d_set_winograd(ConvWinograd mode) {
  const ConvWinograd old = mode_ref();
  mode_ref() = mode;
  return old;
}

ConvWinograd conv2d_winograd_mode() {
  return mode_ref();
}

size_t conv2d_set_winograd_chunk(size_t tiles) {
  const size_t old = g_chunk_tiles;
  g_chunk_tiles = tiles;
  return old;
}

namespace detail {

const WinogradTransforms& winograd_scalar_transforms() {
  static const WinogradTransforms t{input_scalar, output_scalar, "scalar"};
  return t;
}

bool winograd_vector_path(Isa isa) {
  return isa == Isa::kAvx2 || isa == Isa::kAvx512 || isa == Isa::kAvx512Bf16 || isa == Isa::kAmx;
}

const WinogradTransforms& winograd_transforms(Isa isa, bool f32) {
  switch (isa) {
    case Isa::kAvx2:
      return *winograd_avx2_transforms(f32);
    case Isa::kAvx512:
      return f32 ? *winograd_avx512_transforms() : *winograd_avx512_bf16_transforms();
    case Isa::kAvx512Bf16:
    case Isa::kAmx:
      return f32 ? *winograd_avx512_transforms() : *winograd_avx512bf16_transforms();
    default:
      return winograd_scalar_transforms();
  }
}

thread_local std::vector<float> t_pack_buffer;

std::vector<PackedWeights> winograd_pack(const float* w, int64_t c_out, int64_t c_in, Isa isa,
                                         WeightType type) {
  const int64_t cin2 = type == WeightType::kBf16 ? (c_in + 1) / 2 * 2 : c_in;
  // u [xi][Cout][Cin2], zero for the pad channel (bf16; fp32 has none). Kept per thread across
  // packs (a network packs dozens of convs in a row; a fresh buffer each time costs its page faults
  // again), freed by winograd_release_scratch().
  std::vector<float>& u = t_pack_buffer;
  u.assign(size_t(16 * c_out * cin2), 0.0f);
  for (int64_t co = 0; co < c_out; ++co)
    for (int64_t ci = 0; ci < c_in; ++ci) {
      const float* g = w + (co * c_in + ci) * 9;  // [3][3]
      double t[4][3];                             // G g
      for (int k = 0; k < 3; ++k) {
        const double g0 = g[0 * 3 + k], g1 = g[1 * 3 + k], g2 = g[2 * 3 + k];
        t[0][k] = g0;
        t[1][k] = 0.5 * (g0 + g1 + g2);
        t[2][k] = 0.5 * (g0 - g1 + g2);
        t[3][k] = g2;
      }
      for (int i = 0; i < 4; ++i) {  // (G g) G^T
        const double uu[4] = {t[i][0], 0.5 * (t[i][0] + t[i][1] + t[i][2]),
                              0.5 * (t[i][0] - t[i][1] + t[i][2]), t[i][2]};
        for (int j = 0; j < 4; ++j)
          u[size_t(((i * 4 + j) * c_out + co) * cin2 + ci)] = float(uu[j]);
      }
    }
  std::vector<PackedWeights> packs;
  packs.reserve(16);
  for (int xi = 0; xi < 16; ++xi)
    packs.push_back(PackedWeights::pack_as_a(u.data() + size_t(xi * c_out * cin2), c_out, cin2,
                                             cin2, type, isa));
  return packs;
}

bool winograd_pack_qualifies(int64_t c_out, int64_t c_in) {
  return c_out >= kAutoMinChannels && c_out <= kAutoMaxChannels && c_in >= kAutoMinChannels &&
         c_in <= kAutoMaxChannels;
}

bool winograd_applies(const Conv2dShape& s, const ConvWeights& w) {
  const ConvWinograd mode = mode_ref();
  if (mode == ConvWinograd::kOff || w.winograd().size() != 16) return false;
  if (s.kh != 3 || s.kw != 3 || s.stride != 1 || s.row_origin < 0) return false;
  if (mode == ConvWinograd::kAlways) return true;
  if (!winograd_vector_path(w.winograd()[0].isa())) return false;
  const int64_t tiles = (s.out_h() + 1) / 2 * ((s.out_w() + 1) / 2);
  return winograd_pack_qualifies(s.c_out, s.c_in) && tiles >= kAutoMinTiles;
}

void conv2d_winograd(const Conv2dShape& s, const float* x, const ConvWeights& w,
                     const float* residual, float* y, ConvAct act, ThreadPool* pool) {
  const std::vector<PackedWeights>& U = w.winograd();
  MACRO_CHECK(U.size() == 16 && s.kh == 3 && s.kw == 3 && s.stride == 1 && s.row_origin >= 0);
  const GemmKernel& kern = U[0].kernel();
  const bool f32 = U[0].type() == WeightType::kF32;
  const WinogradTransforms& tr = winograd_transforms(U[0].isa(), f32);
  const int nr = kern.nr, mr = kern.mr;
  MACRO_CHECK(nr % 16 == 0);
  const int64_t esz = packed_elem_bytes(kern.layout);
  // K of the GEMMs (Cin, or Cin2 for the pairs), the padded K and the words per panel row set.
  const int64_t kk = f32 ? s.c_in : (s.c_in + 1) / 2 * 2;
  const int64_t kp = U[0].k_padded(), k_rows = f32 ? kp : kp / 2, rows_valid = f32 ? kk : kk / 2;
  const int64_t oh = s.out_h(), ow = s.out_w();
  const int phase = int(s.row_origin & 1);
  const int64_t th = (oh + phase + 1) / 2, tw = (ow + 1) / 2, tiles = th * tw;
  // Chunk: T tiles (a multiple of NR), V about kVBytes in bf16 (the same tiles in fp32, twice the
  // bytes: measured faster than halving T, 2026-12-02); channel blocks: M about kMBytes.
  int64_t T = g_chunk_tiles > 0 ? int64_t(g_chunk_tiles)
                                : std::min(kMaxAutoTiles, budgets().v / (16 * kp * 2));
  T = std::clamp<int64_t>(T / nr * nr, nr, round_up(tiles, nr));
  const int64_t chunks = (tiles + T - 1) / T;
  const int64_t co_blk =
      std::min(round_up(s.c_out, mr), std::max<int64_t>(mr, budgets().m / (16 * 4 * T) / mr * mr));
  const int64_t co_blocks = (s.c_out + co_blk - 1) / co_blk;
  const int threads = pool ? pool->size() : 1;
  const int64_t items = s.n * chunks;
  int64_t blocks_per_part = co_blocks;
  if (threads > 1 && items < 4 * threads) {  // few chunks: split the channel blocks too
    const int64_t parts = std::min<int64_t>(co_blocks, (4 * threads + items - 1) / items);
    blocks_per_part = (co_blocks + parts - 1) / parts;
  }
  const int64_t parts = (co_blocks + blocks_per_part - 1) / blocks_per_part;
  const int64_t xs_v = T * k_rows, xs_m = co_blk * T;
  const size_t max_runs = size_t(T + T / 16 + 2);
  // The calling thread's slots (a thread_local named inside the job would be the worker's own).
  std::vector<Slot>& slots = t_slots;
  if (slots.size() < size_t(threads)) slots.resize(size_t(threads));
  for (int i = 0; i < threads; ++i) {
    slots[size_t(i)].v.reserve(size_t(16 * xs_v));
    slots[size_t(i)].m.reserve(size_t(16 * xs_m));
    slots[size_t(i)].runs.reserve(max_runs);
  }
  const int64_t hw = s.h * s.w, ohw = s.out_plane();

  auto item = [&](int64_t it, int worker) {
    const int64_t part = it % parts, chunk = (it / parts) % chunks, b = it / (parts * chunks);
    Slot& sl = slots[size_t(worker)];
    const int64_t t0 = chunk * T, nt = std::min(T, tiles - t0);
    WinoRun* runs = sl.runs.data;
    const int nruns = make_runs(t0, nt, tw, runs);
    uint32_t* v = sl.v.data;
    // Zero what the transform does not write and the kernel reads: pad pair rows (AMX pads K
    // to 32) and the last panel's columns past the chunk.
    const int64_t panels = (nt + nr - 1) / nr, tail = nt - (panels - 1) * nr;
    for (int xi = 0; xi < 16; ++xi)
      for (int64_t p = 0; p < panels; ++p) {
        uint32_t* vp = v + xi * xs_v + p * k_rows * nr;
        if (k_rows > rows_valid)
          std::memset(vp + rows_valid * nr, 0, size_t((k_rows - rows_valid) * nr) * 4);
        if (p == panels - 1 && tail < nr)
          for (int64_t q = 0; q < rows_valid; ++q)
            std::memset(vp + q * nr + tail, 0, size_t(nr - tail) * 4);
      }
    WinoInput in;
    in.x = x + b * s.c_in * hw;
    in.c_in = s.c_in, in.h = s.h, in.w = s.w;
    in.pad_top = s.pad_top, in.pad_left = s.pad_left, in.row_phase = phase;
    in.q0 = 0, in.q1 = rows_valid;
    in.runs = runs, in.nruns = nruns;
    in.nr = nr, in.k_rows = k_rows, in.xi_stride = xs_v;
    in.v = v;
    in.f32 = f32;
    tr.input(in);
    const int64_t cb1 = std::min(co_blocks, (part + 1) * blocks_per_part);
    for (int64_t cb = part * blocks_per_part; cb < cb1; ++cb) {
      const int64_t co0 = cb * co_blk, nco = std::min(co_blk, s.c_out - co0);
      for (int xi = 0; xi < 16; ++xi) {
        Operand oa{
            nullptr, nullptr,
            static_cast<const unsigned char*>(U[size_t(xi)].panels()) + (co0 / mr) * kp * mr * esz,
            kp};
        Operand ob{nullptr, nullptr, v + xi * xs_v, kp};
        DriverShape ds;
        ds.M = nco, ds.N = nt, ds.K = kk;
        ds.C = sl.m.data + xi * xs_m;
        ds.ldc = T;
        ds.mc = round_up(nco, mr);
        ds.nc = round_up(nt, nr);
        run_gemm(kern, ds, oa, ob, GemmParams{}, nullptr);
      }
      WinoOutput out;
      out.m = sl.m.data, out.ldm = T, out.xi_stride = xs_m;
      out.co0 = co0, out.nco = nco;
      out.bias = w.bias();
      out.residual = residual ? residual + b * s.c_out * ohw : nullptr;
      out.y = y + b * s.c_out * ohw;
      out.oh = oh, out.ow = ow, out.plane = ohw, out.row_phase = phase;
      out.relu = act == ConvAct::kRelu;
      out.runs = runs, out.nruns = nruns;
      tr.output(out);
    }
  };
  const int64_t total = items * parts;
  if (!pool || threads == 1 || total == 1) {
    for (int64_t it = 0; it < total; ++it) item(it, 0);
  } else {
    pool->parallel_for(
        size_t(total),
        [&](size_t b0, size_t b1, int worker) {
          for (size_t it = b0; it < b1; ++it) item(int64_t(it), worker);
        },
        1);
  }
}

void winograd_release_scratch() {
  std::vector<Slot>().swap(t_slots);
  std::vector<float>().swap(t_pack_buffer);
}

}  // namespace detail
}  // namespace macro
