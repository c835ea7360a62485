// Block-sparse attention masks: builders and checks (see attention_mask.h).
#include "attention/runtime/attention_mask.h"

#include <algorithm>
#include <numeric>
#include <string>

namespace macro {
namespace {

constexpr int kBQ = kAttnBlockQ;
constexpr int kBK = kAttnBlockK;
constexpr size_t kTileElems = size_t(kBQ) * kBK;

int blocks(int n, int b) {
  return (n + b - 1) / b;
}

enum class TileKind { kEmpty, kFull, kPartial };

// Walk every (query block, key block) tile in mask order. classify(qb, kb) says whether the tile is
// empty, full or partial; fill(qb, kb, tile) writes a partial tile's [BQ, BK] elements (the buffer
// arrives zeroed, so entries beyond the Nq/Nk edges stay 0).
template <typename Classify, typename Fill>
void build_tiles(BlockSparseMask& m, Classify classify, Fill fill) {
  const int nqb = blocks(m.nq, kBQ), nkb = blocks(m.nk, kBK);
  m.block_begin.assign(1, 0);
  m.key_block.clear();
  m.tile.clear();
  m.tiles.clear();
  for (int qb = 0; qb < nqb; ++qb) {
    for (int kb = 0; kb < nkb; ++kb) {
      TileKind kind = classify(qb, kb);
      if (kind == TileKind::kEmpty) continue;
      m.key_block.push_back(kb);
      if (kind == TileKind::kFull) {
        m.tile.push_back(-1);
      } else {
        m.tile.push_back(static_cast<int32_t>(m.tiles.size() / kTileElems));
        m.tiles.resize(m.tiles.size() + kTileElems, 0);
        fill(qb, kb, m.tiles.data() + m.tiles.size() - kTileElems);
      }
    }
    m.block_begin.push_back(static_cast<int32_t>(m.key_block.size()));
  }
}

// Stable counting sort of tokens by label: index[r] = token placed at position r.
std::vector<int32_t> sort_by_group(const std::vector<int32_t>& group, int num_groups) {
  std::vector<int32_t> start(size_t(num_groups) + 1, 0);
  for (int32_t g : group) ++start[size_t(g) + 1];
  for (int g = 0; g < num_groups; ++g) start[size_t(g) + 1] += start[size_t(g)];
  std::vector<int32_t> index(group.size());
  for (size_t t = 0; t < group.size(); ++t) index[size_t(start[size_t(group[t])]++)] = int32_t(t);
  return index;
}

// Runs of equal labels inside each block of a sorted label sequence: (label, count) pairs.
struct Run {
  int32_t group;
  int32_t count;
};
std::vector<std::vector<Run>> block_runs(const std::vector<int32_t>& sorted_group, int block) {
  const int n = static_cast<int>(sorted_group.size());
  std::vector<std::vector<Run>> runs(size_t(blocks(n, block)));
  for (int b = 0; b < blocks(n, block); ++b) {
    for (int i = b * block; i < std::min(n, (b + 1) * block); ++i) {
      auto& r = runs[size_t(b)];
      if (!r.empty() && r.back().group == sorted_group[size_t(i)]) {
        ++r.back().count;
      } else {
        r.push_back({sorted_group[size_t(i)], 1});
      }
    }
  }
  return runs;
}

bool is_identity_or_permutation(const std::vector<int32_t>& index, int n) {
  if (index.empty()) return true;
  if (static_cast<int>(index.size()) != n) return false;
  std::vector<uint8_t> seen(size_t(n), 0);
  for (int32_t t : index) {
    if (t < 0 || t >= n || seen[size_t(t)]) return false;
    seen[size_t(t)] = 1;
  }
  return true;
}

}  // namespace

int64_t BlockSparseMask::allowed_pairs() const {
  int64_t total = 0;
  for (int qb = 0; qb < query_blocks(); ++qb) {
    const int rows = std::min(kBQ, nq - qb * kBQ);
    for (int e = block_begin[size_t(qb)]; e < block_begin[size_t(qb) + 1]; ++e) {
      const int cols = std::min(kBK, nk - key_block[size_t(e)] * kBK);
      const uint8_t* t = tile_data(tile[size_t(e)]);
      if (!t) {
        total += int64_t(rows) * cols;
        continue;
      }
      for (int r = 0; r < rows; ++r)
        for (int c = 0; c < cols; ++c) total += t[tile_offset(r, c)] != 0;
    }
  }
  return total;
}

int64_t BlockSparseMask::computed_pairs() const {
  int64_t total = 0;
  for (int qb = 0; qb < query_blocks(); ++qb) {
    const int rows = std::min(kBQ, nq - qb * kBQ);
    for (int e = block_begin[size_t(qb)]; e < block_begin[size_t(qb) + 1]; ++e)
      total += int64_t(rows) * std::min(kBK, nk - key_block[size_t(e)] * kBK);
  }
  return total;
}

std::vector<uint8_t> BlockSparseMask::to_dense() const {
  std::vector<uint8_t> dense(size_t(nq) * size_t(nk), 0);
  for (int qb = 0; qb < query_blocks(); ++qb) {
    const int rows = std::min(kBQ, nq - qb * kBQ);
    for (int e = block_begin[size_t(qb)]; e < block_begin[size_t(qb) + 1]; ++e) {
      const int kb = key_block[size_t(e)];
      const int cols = std::min(kBK, nk - kb * kBK);
      const uint8_t* t = tile_data(tile[size_t(e)]);
      for (int r = 0; r < rows; ++r) {
        const int mr = qb * kBQ + r;
        const size_t i = query_index.empty() ? size_t(mr) : size_t(query_index[size_t(mr)]);
        for (int c = 0; c < cols; ++c) {
          const int mc = kb * kBK + c;
          const size_t j = key_index.empty() ? size_t(mc) : size_t(key_index[size_t(mc)]);
          dense[i * size_t(nk) + j] = t ? (t[tile_offset(r, c)] != 0) : 1;
        }
      }
    }
  }
  return dense;
}

Status BlockSparseMask::validate() const {
  auto fail = [&](const std::string& what) {
    return Status::error("attention mask (" + std::to_string(nq) + " x " + std::to_string(nk) +
                         "): " + what);
  };
  if (nq < 0 || nk < 0) return fail("negative size");
  if (!is_identity_or_permutation(query_index, nq))
    return fail("query_index is not a permutation of " + std::to_string(nq) + " tokens");
  if (!is_identity_or_permutation(key_index, nk))
    return fail("key_index is not a permutation of " + std::to_string(nk) + " tokens");
  if (static_cast<int>(block_begin.size()) != blocks(nq, kBQ) + 1 || block_begin.front() != 0 ||
      size_t(block_begin.back()) != key_block.size() || tile.size() != key_block.size())
    return fail("block list sizes do not match " + std::to_string(blocks(nq, kBQ)) +
                " query blocks");
  if (tiles.size() % kTileElems) return fail("element tiles are not whole 64 x 64 tiles");
  const int nkb = blocks(nk, kBK);
  const int64_t ntiles = int64_t(partial_tiles());
  for (int qb = 0; qb < query_blocks(); ++qb) {
    if (block_begin[size_t(qb) + 1] < block_begin[size_t(qb)]) return fail("block_begin decreases");
    for (int e = block_begin[size_t(qb)]; e < block_begin[size_t(qb) + 1]; ++e) {
      const int kb = key_block[size_t(e)];
      if (kb < 0 || kb >= nkb) return fail("key block " + std::to_string(kb) + " out of range");
      if (e > block_begin[size_t(qb)] && key_block[size_t(e) - 1] >= kb)
        return fail("key blocks of query block " + std::to_string(qb) + " not ascending");
      if (tile[size_t(e)] < -1 || tile[size_t(e)] >= ntiles) return fail("tile index out of range");
    }
  }
  return Status::ok();
}

Result<BlockSparseMask> mask_from_dense(const uint8_t* dense, int nq, int nk, size_t stride,
                                        bool group_tokens) {
  if (nq < 0 || nk < 0)
    return Status::error("dense attention mask: negative size " + std::to_string(nq) + " x " +
                         std::to_string(nk));
  if (stride == 0) stride = size_t(nk);
  if (stride < size_t(nk))
    return Status::error("dense attention mask: row stride " + std::to_string(stride) +
                         " is smaller than the key count " + std::to_string(nk));
  if (!dense && nq > 0 && nk > 0) return Status::error("dense attention mask: null data");
  BlockSparseMask m;
  m.nq = nq;
  m.nk = nk;
  if (group_tokens) {
    // 64-bit pattern hashes per row and per column; tokens with the same hash end up adjacent.
    // A collision only costs efficiency: tiles are always filled from the dense data itself.
    std::vector<uint64_t> row_hash(size_t(nq), 1469598103934665603ull);
    std::vector<uint64_t> col_hash(size_t(nk), 1469598103934665603ull);
    for (int i = 0; i < nq; ++i) {
      const uint8_t* row = dense + size_t(i) * stride;
      uint64_t h = row_hash[size_t(i)];
      for (int j = 0; j < nk; ++j) {
        const uint64_t bit = row[j] != 0;
        h = (h ^ bit) * 1099511628211ull;
        col_hash[size_t(j)] = (col_hash[size_t(j)] ^ bit) * 1099511628211ull;
      }
      row_hash[size_t(i)] = h;
    }
    auto order = [](const std::vector<uint64_t>& hash) {
      std::vector<int32_t> index(hash.size());
      std::iota(index.begin(), index.end(), 0);
      std::stable_sort(index.begin(), index.end(),
                       [&](int32_t a, int32_t b) { return hash[size_t(a)] < hash[size_t(b)]; });
      return index;
    };
    m.query_index = order(row_hash);
    m.key_index = order(col_hash);
  }
  auto at = [&](int r, int c) {
    const size_t i = m.query_index.empty() ? size_t(r) : size_t(m.query_index[size_t(r)]);
    const size_t j = m.key_index.empty() ? size_t(c) : size_t(m.key_index[size_t(c)]);
    return dense[i * stride + j] != 0;
  };
  build_tiles(
      m,
      [&](int qb, int kb) {
        const int r1 = std::min(nq, (qb + 1) * kBQ), c1 = std::min(nk, (kb + 1) * kBK);
        int64_t ones = 0;
        for (int r = qb * kBQ; r < r1; ++r)
          for (int c = kb * kBK; c < c1; ++c) ones += at(r, c);
        if (ones == 0) return TileKind::kEmpty;
        return ones == int64_t(r1 - qb * kBQ) * (c1 - kb * kBK) ? TileKind::kFull
                                                                : TileKind::kPartial;
      },
      [&](int qb, int kb, uint8_t* t) {
        const int r1 = std::min(nq, (qb + 1) * kBQ), c1 = std::min(nk, (kb + 1) * kBK);
        for (int r = qb * kBQ; r < r1; ++r)
          for (int c = kb * kBK; c < c1; ++c) t[tile_offset(r - qb * kBQ, c - kb * kBK)] = at(r, c);
      });
  return m;
}

Result<BlockSparseMask> mask_from_groups(const std::vector<int32_t>& query_group,
                                         const std::vector<int32_t>& key_group,
                                         int num_query_groups, int num_key_groups,
                                         const std::vector<uint8_t>& allowed) {
  if (num_query_groups <= 0 || num_key_groups <= 0)
    return Status::error("grouped attention mask: group counts must be positive, found " +
                         std::to_string(num_query_groups) + " x " + std::to_string(num_key_groups));
  if (allowed.size() != size_t(num_query_groups) * size_t(num_key_groups))
    return Status::error("grouped attention mask: allowed table: expected " +
                         std::to_string(size_t(num_query_groups) * size_t(num_key_groups)) +
                         " entries [" + std::to_string(num_query_groups) + ", " +
                         std::to_string(num_key_groups) + "], found " +
                         std::to_string(allowed.size()));
  if (query_group.size() > size_t(INT32_MAX / 2) || key_group.size() > size_t(INT32_MAX / 2))
    return Status::error("grouped attention mask: too many tokens");
  auto check_labels = [](const std::vector<int32_t>& g, int n, const char* what) -> Status {
    for (size_t t = 0; t < g.size(); ++t)
      if (g[t] < 0 || g[t] >= n)
        return Status::error(std::string("grouped attention mask: ") + what + "[" +
                             std::to_string(t) + "]: expected a label in [0, " + std::to_string(n) +
                             "), found " + std::to_string(g[t]));
    return Status::ok();
  };
  MACRO_TRY(check_labels(query_group, num_query_groups, "query_group"));
  MACRO_TRY(check_labels(key_group, num_key_groups, "key_group"));

  BlockSparseMask m;
  m.nq = static_cast<int>(query_group.size());
  m.nk = static_cast<int>(key_group.size());
  m.query_index = sort_by_group(query_group, num_query_groups);
  m.key_index = sort_by_group(key_group, num_key_groups);
  std::vector<int32_t> qsorted(query_group.size()), ksorted(key_group.size());
  for (size_t r = 0; r < qsorted.size(); ++r) qsorted[r] = query_group[size_t(m.query_index[r])];
  for (size_t c = 0; c < ksorted.size(); ++c) ksorted[c] = key_group[size_t(m.key_index[c])];
  const auto qruns = block_runs(qsorted, kBQ), kruns = block_runs(ksorted, kBK);
  auto ok = [&](int32_t qg, int32_t kg) {
    return allowed[size_t(qg) * size_t(num_key_groups) + size_t(kg)] != 0;
  };
  build_tiles(
      m,
      [&](int qb, int kb) {
        bool any = false, all = true;
        for (const Run& a : qruns[size_t(qb)])
          for (const Run& b : kruns[size_t(kb)]) {
            const bool y = ok(a.group, b.group);
            any |= y;
            all &= y;
          }
        return !any ? TileKind::kEmpty : all ? TileKind::kFull : TileKind::kPartial;
      },
      [&](int qb, int kb, uint8_t* t) {
        int r = 0;
        for (const Run& a : qruns[size_t(qb)]) {
          for (int i = 0; i < a.count; ++i, ++r) {
            int c = 0;
            for (const Run& b : kruns[size_t(kb)]) {
              const uint8_t y = ok(a.group, b.group);
              for (int j = 0; j < b.count; ++j, ++c) t[tile_offset(r, c)] = y;
            }
          }
        }
      });
  return m;
}

Result<BlockSparseMask> macro_closeup_mask(int tokens_per_view, int planes,
                                           const std::vector<int32_t>& closeup_plane,
                                           const std::vector<int32_t>& crop_plane,
                                           const std::vector<uint8_t>& crop_valid) {
  const int n = tokens_per_view;
  const int crops = static_cast<int>(crop_plane.size());
  auto fail = [](const std::string& what) {
    return Status::error("MACRO attention mask: " + what);
  };
  if (n <= 0 || planes <= 0)
    return fail("tokens_per_view and planes must be positive, found " + std::to_string(n) +
                " and " + std::to_string(planes));
  if (int64_t(n) * (1 + crops) > INT32_MAX / 2) return fail("too many tokens");
  if (closeup_plane.size() != size_t(n))
    return fail("closeup_plane: expected " + std::to_string(n) + " labels, found " +
                std::to_string(closeup_plane.size()));
  if (crop_valid.size() != size_t(crops) * size_t(n))
    return fail("crop_valid: expected [" + std::to_string(crops) + ", " + std::to_string(n) +
                "], found " + std::to_string(crop_valid.size()) + " values");
  for (int c = 0; c < crops; ++c)
    if (crop_plane[size_t(c)] < 0 || crop_plane[size_t(c)] >= planes)
      return fail("crop_plane[" + std::to_string(c) + "]: expected a plane in [0, " +
                  std::to_string(planes) + "), found " + std::to_string(crop_plane[size_t(c)]));
  for (int t = 0; t < n; ++t)
    if (closeup_plane[size_t(t)] < 0 || closeup_plane[size_t(t)] >= planes)
      return fail("closeup_plane[" + std::to_string(t) + "]: expected a plane in [0, " +
                  std::to_string(planes) + "), found " + std::to_string(closeup_plane[size_t(t)]));

  // Query groups: close-up plane p -> p; crop c -> planes + c.
  // Key groups: close-up -> 0; crop c valid -> 1 + 2c; crop c invalid -> 2 + 2c.
  const int gq = planes + crops, gk = 1 + 2 * crops;
  std::vector<int32_t> qg(size_t(n) * size_t(1 + crops)), kg(qg.size());
  for (int t = 0; t < n; ++t) {
    qg[size_t(t)] = closeup_plane[size_t(t)];
    kg[size_t(t)] = 0;
  }
  for (int c = 0; c < crops; ++c)
    for (int t = 0; t < n; ++t) {
      const size_t i = size_t(1 + c) * size_t(n) + size_t(t);
      qg[i] = planes + c;
      kg[i] = crop_valid[size_t(c) * size_t(n) + size_t(t)] ? 1 + 2 * c : 2 + 2 * c;
    }
  std::vector<uint8_t> allowed(size_t(gq) * size_t(gk), 0);
  for (int p = 0; p < planes; ++p) {
    allowed[size_t(p) * gk + 0] = 1;  // close-up self-attention
    for (int c = 0; c < crops; ++c)
      if (crop_plane[size_t(c)] == p) allowed[size_t(p) * gk + size_t(1 + 2 * c)] = 1;
  }
  for (int c = 0; c < crops; ++c) {  // each crop sees all of itself
    allowed[size_t(planes + c) * gk + size_t(1 + 2 * c)] = 1;
    allowed[size_t(planes + c) * gk + size_t(2 + 2 * c)] = 1;
  }
  return mask_from_groups(qg, kg, gq, gk, allowed);
}

Result<BlockSparseMask> restrict_queries(const BlockSparseMask& mask, int limit) {
  if (limit < 0 || limit > mask.nq)
    return Status::error("restrict_queries: limit " + std::to_string(limit) + ", expected 0.." +
                         std::to_string(mask.nq) + " (the mask's query tokens)");
  // The kept mask rows, in mask order, and their tokens.
  std::vector<int32_t> rows;
  BlockSparseMask out;
  out.nq = limit;
  out.nk = mask.nk;
  out.key_index = mask.key_index;
  for (int r = 0; r < mask.nq; ++r) {
    const int32_t token = mask.query_index.empty() ? r : mask.query_index[size_t(r)];
    if (token < limit) {
      rows.push_back(r);
      out.query_index.push_back(token);
    }
  }
  bool identity = true;
  for (size_t i = 0; i < out.query_index.size(); ++i) identity &= out.query_index[i] == int32_t(i);
  if (identity) out.query_index.clear();
  // The old entry of (old row, key block): -2 none, -1 full, else its element tile.
  auto entry = [&](int row, int kb) -> int32_t {
    const int qb = row / kBQ;
    const auto first = mask.key_block.begin() + mask.block_begin[size_t(qb)];
    const auto last = mask.key_block.begin() + mask.block_begin[size_t(qb) + 1];
    const auto it = std::lower_bound(first, last, kb);
    if (it == last || *it != kb) return -2;
    return mask.tile[size_t(it - mask.key_block.begin())];
  };
  auto classify = [&](int qb, int kb) {
    const int r0 = qb * kBQ, r1 = std::min(limit, r0 + kBQ);
    bool any = false, all_full = true;
    for (int r = r0; r < r1; ++r) {
      const int32_t e = entry(rows[size_t(r)], kb);
      if (e == -2) {
        all_full = false;
        continue;
      }
      if (e >= 0) {  // a partial row may still allow nothing
        const uint8_t* t = mask.tile_data(e);
        const int row = rows[size_t(r)] % kBQ;
        bool row_any = false;
        for (int c = 0; c < std::min(kBK, mask.nk - kb * kBK); ++c)
          row_any |= t[tile_offset(row, c)] != 0;
        any |= row_any;
        all_full = false;  // kept partial: the kernel then runs the same masked path for it
        continue;
      }
      any = true;
    }
    return !any ? TileKind::kEmpty : all_full ? TileKind::kFull : TileKind::kPartial;
  };
  auto fill = [&](int qb, int kb, uint8_t* tile) {
    const int r0 = qb * kBQ, r1 = std::min(limit, r0 + kBQ);
    const int cols = std::min(kBK, mask.nk - kb * kBK);
    for (int r = r0; r < r1; ++r) {
      const int32_t e = entry(rows[size_t(r)], kb);
      if (e == -2) continue;
      const uint8_t* t = mask.tile_data(e);
      const int row = rows[size_t(r)] % kBQ;
      for (int c = 0; c < cols; ++c)
        tile[tile_offset(r - r0, c)] = t ? t[tile_offset(row, c)] : uint8_t(1);
    }
  };
  build_tiles(out, classify, fill);
  return out;
}

BlockSparseMask causal_mask(int nq, int nk) {
  BlockSparseMask m;
  m.nq = std::max(nq, 0);
  m.nk = std::max(nk, 0);
  build_tiles(
      m,
      [&](int qb, int kb) {
        const int last_row = std::min(m.nq, (qb + 1) * kBQ) - 1;
        if (kb * kBK > last_row) return TileKind::kEmpty;
        return (kb + 1) * kBK - 1 <= qb * kBQ ? TileKind::kFull : TileKind::kPartial;
      },
      [&](int qb, int kb, uint8_t* t) {
        for (int r = 0; r < kBQ && qb * kBQ + r < m.nq; ++r)
          for (int c = 0; c < kBK && kb * kBK + c < m.nk; ++c)
            t[tile_offset(r, c)] = kb * kBK + c <= qb * kBQ + r;
      });
  return m;
}

}  // namespace macro
