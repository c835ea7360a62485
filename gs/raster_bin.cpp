// Bin stage: group (Gaussian, tile) pairs by tile, front to back inside each tile.
//
// Legend: N Gaussians, V visible (tiles > 0), P pairs, T = TX*TY tiles, C = kBinChunks.
// The order produced is that of a stable sort of 64-bit keys (tile << 32 | float bits of depth),
// ties broken by Gaussian id, done as an LSD radix sort whose digits are split by where they are
// cheapest to sort:
//   1. the three depth digits (11, 11, 10 bits) on the V visible Gaussians (depth is per Gaussian,
//      so sorting the Gaussians sorts every pair's low 32 bits at once);
//   2. pairs emitted in that depth order (each Gaussian writes its own prefix-sum slot);
//   3. the tile digit as one stable counting pass over the pairs, in C fixed chunks.
// Positive floats order like their bit patterns, and depth > near > 0 here. Nothing depends on the
// number of threads or on timing, so the result is bit-identical for any pool.
#include <cstring>

#include "gs/raster_stages.h"

namespace macro::gs::raster {
namespace {

// One stable LSD pass: scatter (key, id) by the digit (key >> shift) & mask.
void radix_pass(const uint32_t* key_in, const uint32_t* id_in, uint32_t* key_out,
                uint32_t* id_out, size_t n, int shift, uint32_t mask, uint32_t* hist) {
  std::memset(hist, 0, sizeof(uint32_t) * (mask + 1));
  for (size_t i = 0; i < n; ++i) ++hist[(key_in[i] >> shift) & mask];
  uint32_t sum = 0;
  for (uint32_t d = 0; d <= mask; ++d) {
    uint32_t c = hist[d];
    hist[d] = sum;
    sum += c;
  }
  for (size_t i = 0; i < n; ++i) {
    uint32_t pos = hist[(key_in[i] >> shift) & mask]++;
    key_out[pos] = key_in[i];
    id_out[pos] = id_in[i];
  }
}

}  // namespace

size_t bin_scratch_bytes(size_t n, size_t pairs, int tiles) {
  return 4 * Arena::carve_size<uint32_t>(n)                        // keys, ids (x2)
         + Arena::carve_size<uint64_t>(n + 1)                      // pair offsets
         + 3 * Arena::carve_size<uint32_t>(pairs)                  // pair tile, pair id, output
         + Arena::carve_size<uint32_t>(size_t(kBinChunks) * tiles)  // chunk histograms
         + Arena::carve_size<uint32_t>(size_t(tiles) + 1)          // tile_start
         + Arena::carve_size<uint32_t>(2048);                      // radix histogram
}

void bin_stage(const Projected& proj, const CameraF& cam, TileRule rule, uint64_t pairs,
               Arena& scratch, Binned* out, ThreadPool& pool) {
  const size_t n = proj.n;
  const int tiles = cam.tiles_x * cam.tiles_y;
  scratch.reset(bin_scratch_bytes(n, pairs, tiles));
  uint32_t* key_a = scratch.carve<uint32_t>(n);
  uint32_t* id_a = scratch.carve<uint32_t>(n);
  uint32_t* key_b = scratch.carve<uint32_t>(n);
  uint32_t* id_b = scratch.carve<uint32_t>(n);
  uint64_t* offset = scratch.carve<uint64_t>(n + 1);
  uint32_t* pair_tile = scratch.carve<uint32_t>(pairs);
  uint32_t* pair_src = scratch.carve<uint32_t>(pairs);
  out->pair_gid = scratch.carve<uint32_t>(pairs);
  uint32_t* hist = scratch.carve<uint32_t>(size_t(kBinChunks) * tiles);
  out->tile_start = scratch.carve<uint32_t>(size_t(tiles) + 1);
  uint32_t* radix_hist = scratch.carve<uint32_t>(2048);

  // 1. Visible Gaussians in id order, keyed by depth bits; then three stable LSD passes.
  size_t v = 0;
  for (size_t g = 0; g < n; ++g) {
    if (proj.tiles[g] == 0) continue;
    std::memcpy(&key_a[v], &proj.splats[g].z, 4);
    id_a[v] = uint32_t(g);
    ++v;
  }
  struct Digit { int shift; uint32_t mask; };
  const Digit digits[3] = {{0, 0x7ff}, {11, 0x7ff}, {22, 0x3ff}};
  uint32_t *kin = key_a, *iin = id_a, *kout = key_b, *iout = id_b;
  for (const Digit& d : digits) {
    // Skip a digit every key shares (common for the top bits).
    const uint32_t first = v ? (kin[0] >> d.shift) & d.mask : 0;
    bool same = true;
    for (size_t i = 1; i < v && same; ++i) same = ((kin[i] >> d.shift) & d.mask) == first;
    if (same) continue;
    radix_pass(kin, iin, kout, iout, v, d.shift, d.mask, radix_hist);
    std::swap(kin, kout);
    std::swap(iin, iout);
  }
  const uint32_t* order = iin;  // [V] Gaussian ids front to back

  // 2. Pairs in depth order: Gaussian order[k] owns [offset[k], offset[k+1]).
  offset[0] = 0;
  for (size_t k = 0; k < v; ++k) offset[k + 1] = offset[k] + proj.tiles[order[k]];
  MACRO_CHECK(offset[v] == pairs);
  pool.parallel_for(v, [&](size_t begin, size_t end, int) {
    for (size_t k = begin; k < end; ++k) {
      const uint32_t g = order[k];
      uint64_t o = offset[k];
      for_each_tile(proj.splats[g], cam, rule, [&](int tx, int ty) {
        pair_tile[o] = uint32_t(ty * cam.tiles_x + tx);
        pair_src[o] = g;
        ++o;
      });
      MACRO_CHECK(o == offset[k + 1]);
    }
  }, 1024);

  // 3. Stable counting sort of the pairs by tile, over C fixed chunks.
  const size_t chunk = (pairs + kBinChunks - 1) / kBinChunks;
  pool.parallel_for(kBinChunks, [&](size_t begin, size_t end, int) {
    for (size_t ch = begin; ch < end; ++ch) {
      uint32_t* h = hist + ch * size_t(tiles);
      std::memset(h, 0, sizeof(uint32_t) * size_t(tiles));
      const size_t b = std::min<size_t>(pairs, ch * chunk), e = std::min<size_t>(pairs, b + chunk);
      for (size_t i = b; i < e; ++i) ++h[pair_tile[i]];
    }
  }, 1);
  uint32_t sum = 0;
  for (int t = 0; t < tiles; ++t) {
    out->tile_start[t] = sum;
    for (int ch = 0; ch < kBinChunks; ++ch) {
      uint32_t& h = hist[size_t(ch) * tiles + t];
      const uint32_t c = h;
      h = sum;
      sum += c;
    }
  }
  out->tile_start[tiles] = sum;
  pool.parallel_for(kBinChunks, [&](size_t begin, size_t end, int) {
    for (size_t ch = begin; ch < end; ++ch) {
      uint32_t* h = hist + ch * size_t(tiles);
      const size_t b = std::min<size_t>(pairs, ch * chunk), e = std::min<size_t>(pairs, b + chunk);
      for (size_t i = b; i < e; ++i) out->pair_gid[h[pair_tile[i]]++] = pair_src[i];
    }
  }, 1);
}

}  // namespace macro::gs::raster
