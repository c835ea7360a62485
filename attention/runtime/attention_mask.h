// Block-sparse attention masks: which (query, key) pairs may attend, stored so that the cost of
// attention scales with the allowed pairs rather than with Nq x Nk.
//
// Legend: Nq query tokens, Nk key tokens, BQ x BK = kAttnBlockQ x kAttnBlockK (64 x 64) tiles,
// nqb = ceil(Nq / BQ) query blocks, nkb = ceil(Nk / BK) key blocks.
//
// The mask lives in its own "mask order": mask row r is query token query_index[r] and mask
// column c is key token key_index[c] (both are permutations; empty = identity). Reordering tokens
// so that tokens with the same allow-list sit together is what turns a spatially interleaved mask
// (close-up tokens of several depth planes side by side) into mostly full or empty tiles. The
// attention kernel gathers Q/K/V rows through these indices and scatters the output rows back,
// so callers never see the permutation: results are in the original token order.
//
// For each query block the mask lists the key blocks it may see, each either full (every pair in
// the tile allowed, up to the Nq/Nk edges) or partial (a BQ x BK uint8 element tile, 1 = may
// attend, consulted only for that tile). Key blocks not listed are skipped entirely.
// Element tiles are stored key-major (byte of query r, key c at tile_offset(r, c) = c * BQ + r),
// because the SIMD kernels hold scores transposed: one vector = one key, 16 queries.
//
// Builders:
//  - from_dense(): a dense uint8 [Nq, Nk] mask (as the goldens store `mask.levelL`), in token
//    order. Optionally groups rows and columns with identical patterns first (group_tokens).
//  - from_groups(): tokens carry group labels and an allowed-pairs table says which query group
//    may see which key group; never materialises the dense mask.
//  - macro_closeup_mask(): the MACRO rule of the goldens (see the function) built on from_groups().
#pragma once

#include <cstdint>
#include <vector>

#include "attention/runtime/status.h"

namespace macro {

// Tile sizes of the attention kernels: 64 queries x 64 keys. 64 keys fill four AVX-512 vectors
// (eight AVX2 vectors) per score row; a 64 x 64 fp32 score tile (16 KiB) plus the packed K^T tile
// (D x 64 floats, 16 KiB at D = 64) and the output accumulator (64 x D) stay in L1/L2.
inline constexpr int kAttnBlockQ = 64;
inline constexpr int kAttnBlockK = 64;

// Position of (query r, key c) inside an element tile (key-major).
inline constexpr int tile_offset(int r, int c) {
  return c * kAttnBlockQ + r;
}

struct BlockSparseMask {
  int nq = 0;                        // query tokens (mask rows)
  int nk = 0;                        // key tokens (mask columns)
  std::vector<int32_t> query_index;  // [nq] mask row -> query token; empty = identity
  std::vector<int32_t> key_index;    // [nk] mask column -> key token; empty = identity
  std::vector<int32_t> block_begin;  // [nqb + 1] query block b lists entries block_begin[b]..[b+1]
  std::vector<int32_t> key_block;    // [entries] key block seen by the query block (ascending)
  std::vector<int32_t> tile;         // [entries] -1 = full, else index of its element tile
  std::vector<uint8_t> tiles;  // [partial, BK, BQ] element tiles, 1 = may attend (0 beyond edges)

  int query_blocks() const { return static_cast<int>(block_begin.size()) - 1; }
  size_t entries() const { return key_block.size(); }
  size_t partial_tiles() const { return tiles.size() / (size_t(kAttnBlockQ) * kAttnBlockK); }
  const uint8_t* tile_data(int32_t t) const {
    return t < 0 ? nullptr : tiles.data() + size_t(t) * kAttnBlockQ * kAttnBlockK;
  }

  // Exact number of allowed (query, key) pairs (full tiles clipped to the Nq/Nk edges).
  int64_t allowed_pairs() const;
  // Pairs inside listed tiles (what the kernel computes): sum over entries of the clipped tile
  // area.
  int64_t computed_pairs() const;
  // The dense uint8 [nq, nk] mask in token order (for tests; materialises the full square).
  std::vector<uint8_t> to_dense() const;
  // Structural invariants (sizes, ascending key blocks, permutations); for tests and checks.
  Status validate() const;
};

// dense: uint8 [nq, nk] with row stride `stride` elements (0 = nk), non-zero = may attend.
// group_tokens: first sort rows (and columns) by their pattern so that identical rows/columns are
// adjacent; this recovers the block structure of masks whose groups are spatially interleaved.
Result<BlockSparseMask> mask_from_dense(const uint8_t* dense, int nq, int nk, size_t stride = 0,
                                        bool group_tokens = false);

// Group-structured mask. query_group [nq] in [0, num_query_groups), key_group [nk] in
// [0, num_key_groups), allowed [num_query_groups, num_key_groups] row-major (non-zero = may see).
// Tokens are stably sorted by group (query_index / key_index), so each group is a contiguous run
// and a tile is full, empty or partial only where runs meet a tile edge. Cost O(nq + nk + tiles *
// groups meeting in a tile); the dense mask is never formed.
Result<BlockSparseMask> mask_from_groups(const std::vector<int32_t>& query_group,
                                         const std::vector<int32_t>& key_group,
                                         int num_query_groups, int num_key_groups,
                                         const std::vector<uint8_t>& allowed);

// The MACRO close-up mask over the joint sequence [close-up, crop_0 .. crop_{n-1}], N tokens per
// view (view-major), as stored by the goldens (`mask.levelL`):
//  - every view attends to all of its own tokens;
//  - close-up token t (plane closeup_plane[t]) also attends to the valid tokens of every crop c
//    whose crop_plane[c] equals its plane (crop_valid[c * N + t'] != 0).
// closeup_plane [N] in [0, planes); crop_plane [n] in [0, planes); crop_valid [n, N].
// Labels out of range or wrong sizes are errors naming the argument.
Result<BlockSparseMask> macro_closeup_mask(int tokens_per_view, int planes,
                                           const std::vector<int32_t>& closeup_plane,
                                           const std::vector<int32_t>& crop_plane,
                                           const std::vector<uint8_t>& crop_valid);

// The mask of the query tokens 0..limit-1 alone (same keys): row t of the result allows what row t
// of `mask` allows, for every token t < limit; nq = limit. What a caller needs that keeps only the
// first views' outputs of a joint attention (the later views still serve as keys). The rows keep
// their mask order and are re-blocked, so a tile may turn from full to partial or disappear.
// 0 <= limit <= mask.nq, else an error naming both.
Result<BlockSparseMask> restrict_queries(const BlockSparseMask& mask, int limit);

// Causal mask (key j allowed iff j <= i), nq x nk; the kernel's `causal` flag does the same
// without a mask object. Provided for tests and for combining with other structure.
BlockSparseMask causal_mask(int nq, int nk);

}  // namespace macro
