// Bin stage: group (Gaussian, tile) pairs by tile, front to back inside each tile.
//
// Legend: N Gaussians, V visible (tiles > 0), P pairs, T = TX*TY tiles, C = kBinChunks.
// The order produced is that of a stable sort of 64-bit keys (tile << 32 | float bits of depth),
// ties broken by Gaussian id, done as an LSD radix sort whose digits are split by where they are
// cheapest to sort:
//   1. the three depth digits (11, 11, 10 bits) on the V visible Gaussians (depth is per Gaussian,
//      so sorting the Gaussians sorts every pair's low 32 bits at once);
//   2. the visible records gathered into depth order (one random read each, prefetched), then
//      pairs emitted from that sequential copy (each Gaussian writes its own prefix-sum slot);
//   3. the tile digit as one stable counting pass over the pairs, in C fixed chunks.
// Positive floats order like their bit patterns, and depth > near > 0 here. Nothing depends on the
// number of threads or on timing, so the result is bit-identical for any pool.
#include <cstring>

#include "gs/raster/raster_stages.h"

namespace macro::gs::raster {
namespace {

constexpr uint32_t kRadixBuckets = 2048;  // 11-bit digits

// Deterministic parallel split of [0, n) into kBinChunks fixed chunks.
struct Chunks {
  size_t n, size;
  explicit Chunks(size_t count) : n(count), size((count + kBinChunks - 1) / kBinChunks) {}
  size_t begin(size_t ch) const { return std::min(n, ch * size); }
  size_t end(size_t ch) const { return std::min(n, (ch + 1) * size); }
};

// One stable LSD pass: scatter (key, id) by the digit (key >> shift) & mask. Per-chunk histograms
// (hist: [kBinChunks, kRadixBuckets]) make it parallel and still stable: chunk ch's keys of digit
// d land after those of every earlier chunk.
void radix_pass(const uint32_t* key_in, const uint32_t* id_in, uint32_t* key_out, uint32_t* id_out,
                size_t n, int shift, uint32_t mask, uint32_t* hist, ThreadPool& pool) {
  const Chunks chunks(n);
  pool.parallel_for(
      kBinChunks,
      [&](size_t cb, size_t ce, int) {
        for (size_t ch = cb; ch < ce; ++ch) {
          uint32_t* h = hist + ch * kRadixBuckets;
          std::memset(h, 0, sizeof(uint32_t) * kRadixBuckets);
          for (size_t i = chunks.begin(ch); i < chunks.end(ch); ++i)
            ++h[(key_in[i] >> shift) & mask];
        }
      },
      1);
  uint32_t sum = 0;
  for (uint32_t d = 0; d <= mask; ++d)
    for (size_t ch = 0; ch < size_t(kBinChunks); ++ch) {
      uint32_t& h = hist[ch * kRadixBuckets + d];
      const uint32_t c = h;
      h = sum;
      sum += c;
    }
  pool.parallel_for(
      kBinChunks,
      [&](size_t cb, size_t ce, int) {
        for (size_t ch = cb; ch < ce; ++ch) {
          uint32_t* h = hist + ch * kRadixBuckets;
          for (size_t i = chunks.begin(ch); i < chunks.end(ch); ++i) {
            const uint32_t pos = h[(key_in[i] >> shift) & mask]++;
            key_out[pos] = key_in[i];
            id_out[pos] = id_in[i];
          }
        }
      },
      1);
}

}  // namespace

size_t bin_scratch_bytes(size_t n, size_t pairs, int tiles) {
  return Arena::carve_size<TileSplat>(n)                            // depth-sorted records
         + 4 * Arena::carve_size<uint32_t>(n)                       // keys, ids (x2)
         + Arena::carve_size<uint64_t>(n + 1)                       // pair offsets
         + 3 * Arena::carve_size<uint32_t>(pairs)                   // pair tile, pair id, output
         + Arena::carve_size<uint32_t>(size_t(kBinChunks) * tiles)  // chunk histograms
         + Arena::carve_size<uint32_t>(size_t(tiles) + 1)           // tile_start
         + Arena::carve_size<uint32_t>(n)                           // tiles in depth order
         + Arena::carve_size<uint32_t>(size_t(kBinChunks) * kRadixBuckets);  // radix hist
}

void bin_stage(const Projected& proj, const CameraF& cam, TileRule rule, uint64_t pairs,
               Arena& scratch, Binned* out, ThreadPool& pool, Progress* progress) {
  const auto step = [progress] {
    if (progress) progress->advance();
  };
  const size_t n = proj.n;
  const int tiles = cam.tiles_x * cam.tiles_y;
  scratch.reset(bin_scratch_bytes(n, pairs, tiles));
  out->splats = scratch.carve<TileSplat>(n);
  uint32_t* key_a = scratch.carve<uint32_t>(n);
  uint32_t* id_a = scratch.carve<uint32_t>(n);
  uint32_t* key_b = scratch.carve<uint32_t>(n);
  uint32_t* id_b = scratch.carve<uint32_t>(n);
  uint64_t* offset = scratch.carve<uint64_t>(n + 1);
  uint32_t* pair_tile = scratch.carve<uint32_t>(pairs);
  uint32_t* pair_src = scratch.carve<uint32_t>(pairs);
  out->pair = scratch.carve<uint32_t>(pairs);
  uint32_t* hist = scratch.carve<uint32_t>(size_t(kBinChunks) * tiles);
  out->tile_start = scratch.carve<uint32_t>(size_t(tiles) + 1);
  uint32_t* sorted_tiles = scratch.carve<uint32_t>(n);
  uint32_t* radix_hist = scratch.carve<uint32_t>(size_t(kBinChunks) * kRadixBuckets);

  // 1. Visible Gaussians in id order, keyed by depth bits (compaction by fixed chunks); then
  //    three stable LSD passes.
  const Chunks gchunks(n);
  uint32_t* chunk_visible = radix_hist;  // [kBinChunks + 1], before the radix passes use it
  pool.parallel_for(
      kBinChunks,
      [&](size_t cb, size_t ce, int) {
        for (size_t ch = cb; ch < ce; ++ch) {
          uint32_t c = 0;
          for (size_t g = gchunks.begin(ch); g < gchunks.end(ch); ++g) c += proj.tiles[g] != 0;
          chunk_visible[ch + 1] = c;
        }
      },
      1);
  chunk_visible[0] = 0;
  for (int ch = 0; ch < kBinChunks; ++ch) chunk_visible[ch + 1] += chunk_visible[ch];
  const size_t v = chunk_visible[kBinChunks];
  pool.parallel_for(
      kBinChunks,
      [&](size_t cb, size_t ce, int) {
        for (size_t ch = cb; ch < ce; ++ch) {
          size_t o = chunk_visible[ch];
          for (size_t g = gchunks.begin(ch); g < gchunks.end(ch); ++g) {
            if (proj.tiles[g] == 0) continue;
            key_a[o] = proj.depth_key[g];
            id_a[o] = uint32_t(g);
            ++o;
          }
        }
      },
      1);
  struct Digit {
    int shift;
    uint32_t mask;
  };
  const Digit digits[3] = {{0, 0x7ff}, {11, 0x7ff}, {22, 0x3ff}};
  uint32_t *kin = key_a, *iin = id_a, *kout = key_b, *iout = id_b;
  for (const Digit& d : digits) {
    // Skip a digit every key shares (common for the top bits).
    const uint32_t first = v ? (kin[0] >> d.shift) & d.mask : 0;
    bool same = true;
    for (size_t i = 1; i < v && same; ++i) same = ((kin[i] >> d.shift) & d.mask) == first;
    if (same) continue;
    radix_pass(kin, iin, kout, iout, v, d.shift, d.mask, radix_hist, pool);
    std::swap(kin, kout);
    std::swap(iin, iout);
  }
  const uint32_t* order = iin;  // [V] Gaussian ids front to back
  step();

  // 2. Records in depth order; the record at rank k owns pairs [offset[k], offset[k+1]).
  TileSplat* sorted = out->splats;
  pool.parallel_for(
      v,
      [&](size_t begin, size_t end, int) {
        constexpr size_t kAhead = 16;
        for (size_t k = begin; k < end; ++k) {
          if (k + kAhead < end) __builtin_prefetch(&proj.splats[order[k + kAhead]]);
          sorted[k] = proj.splats[order[k]];
          sorted_tiles[k] = proj.tiles[order[k]];
        }
      },
      4096);
  offset[0] = 0;
  for (size_t k = 0; k < v; ++k) offset[k + 1] = offset[k] + sorted_tiles[k];
  MACRO_CHECK(offset[v] == pairs);
  step();
  pool.parallel_for(
      v,
      [&](size_t begin, size_t end, int) {
        for (size_t k = begin; k < end; ++k) {
          uint64_t o = offset[k];
          for_each_tile(sorted[k], cam, rule, [&](int tx, int ty) {
            pair_tile[o] = uint32_t(ty * cam.tiles_x + tx);
            pair_src[o] = uint32_t(k);
            ++o;
          });
          MACRO_CHECK(o == offset[k + 1]);
        }
      },
      1024);

  step();
  // 3. Stable counting sort of the pairs by tile, over C fixed chunks.
  const size_t chunk = (pairs + kBinChunks - 1) / kBinChunks;
  pool.parallel_for(
      kBinChunks,
      [&](size_t begin, size_t end, int) {
        for (size_t ch = begin; ch < end; ++ch) {
          uint32_t* h = hist + ch * size_t(tiles);
          std::memset(h, 0, sizeof(uint32_t) * size_t(tiles));
          const size_t b = std::min<size_t>(pairs, ch * chunk),
                       e = std::min<size_t>(pairs, b + chunk);
          for (size_t i = b; i < e; ++i) ++h[pair_tile[i]];
        }
      },
      1);
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
  pool.parallel_for(
      kBinChunks,
      [&](size_t begin, size_t end, int) {
        for (size_t ch = begin; ch < end; ++ch) {
          uint32_t* h = hist + ch * size_t(tiles);
          const size_t b = std::min<size_t>(pairs, ch * chunk),
                       e = std::min<size_t>(pairs, b + chunk);
          for (size_t i = b; i < e; ++i) out->pair[h[pair_tile[i]]++] = pair_src[i];
        }
      },
      1);
  step();
}

}  // namespace macro::gs::raster
