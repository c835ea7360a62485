// MACRO attention masks per token grid (see plane_masks.h).
#include "enhance/macro/plane_masks.h"

#include <algorithm>

namespace macro::enhance {

const char* mask_mode_name(MaskMode mode) {
  switch (mode) {
    case MaskMode::kReleased:
      return "released";
    case MaskMode::kPaper:
      return "paper";
    case MaskMode::kNone:
      return "none";
  }
  return "?";
}

Result<MaskMode> parse_mask_mode(const std::string& text) {
  if (text == "released") return MaskMode::kReleased;
  if (text == "paper") return MaskMode::kPaper;
  if (text == "none") return MaskMode::kNone;
  return Status::error("--mask: expected released, paper or none, found '" + text + "'");
}

std::vector<TokenGrid> unet_token_grids(int latent_h, int latent_w, int levels) {
  std::vector<TokenGrid> g;
  TokenGrid t{latent_h, latent_w};
  for (int l = 0; l < levels; ++l) {
    g.push_back(t);
    t = TokenGrid{(t.h + 1) / 2, (t.w + 1) / 2};
  }
  return g;
}

std::vector<int32_t> latent_plane_map(const std::vector<int32_t>& labels, int width, int height,
                                      int planes) {
  const int lh = height / kLatentPatch, lw = width / kLatentPatch;
  std::vector<int32_t> out(size_t(lh) * size_t(lw), 0);
  std::vector<int> votes(size_t(std::max(planes, 1)));
  for (int ci = 0; ci < lh; ++ci)
    for (int cj = 0; cj < lw; ++cj) {
      std::fill(votes.begin(), votes.end(), 0);
      for (int di = 0; di < kLatentPatch; ++di)
        for (int dj = 0; dj < kLatentPatch; ++dj) {
          const int32_t l =
              labels[size_t(ci * kLatentPatch + di) * width + size_t(cj * kLatentPatch + dj)];
          if (l >= 0 && l < planes) ++votes[size_t(l)];
        }
      int best = 0;
      for (int p = 1; p < planes; ++p)
        if (votes[size_t(p)] > votes[size_t(best)]) best = p;
      out[size_t(ci) * lw + cj] = best;  // all invalid: every count 0 -> bin 0 (farthest)
    }
  return out;
}

namespace {

Status check_inputs(int n_tok, int planes, const std::vector<int32_t>& closeup_plane,
                    const std::vector<int32_t>& crop_plane,
                    const std::vector<uint8_t>& crop_valid) {
  auto fail = [](const std::string& w) { return Status::error("plane mask: " + w); };
  if (n_tok <= 0 || planes <= 0) return fail("tokens per view and planes must be positive");
  if (closeup_plane.size() != size_t(n_tok))
    return fail("closeup_plane: expected " + std::to_string(n_tok) + " labels, found " +
                std::to_string(closeup_plane.size()));
  if (crop_valid.size() != crop_plane.size() * size_t(n_tok))
    return fail("crop_valid: expected " + std::to_string(crop_plane.size() * size_t(n_tok)) +
                " values, found " + std::to_string(crop_valid.size()));
  for (size_t i = 0; i < closeup_plane.size(); ++i)
    if (closeup_plane[i] < 0 || closeup_plane[i] >= planes)
      return fail("closeup_plane[" + std::to_string(i) + "] = " + std::to_string(closeup_plane[i]) +
                  ": expected a plane in [0, " + std::to_string(planes) + ")");
  for (size_t c = 0; c < crop_plane.size(); ++c)
    if (crop_plane[c] < 0 || crop_plane[c] >= planes)
      return fail("crop_plane[" + std::to_string(c) + "] = " + std::to_string(crop_plane[c]) +
                  ": expected a plane in [0, " + std::to_string(planes) + ")");
  if (int64_t(n_tok) * int64_t(1 + crop_plane.size()) > (int64_t(1) << 30))
    return fail("too many tokens");
  return Status::ok();
}

}  // namespace

Result<BlockSparseMask> build_level_mask(MaskMode mode, int n_tok, int planes,
                                         const std::vector<int32_t>& closeup_plane,
                                         const std::vector<int32_t>& crop_plane,
                                         const std::vector<uint8_t>& crop_valid) {
  MACRO_TRY(check_inputs(n_tok, planes, closeup_plane, crop_plane, crop_valid));
  const int n = int(crop_plane.size());
  // Query groups: close-up plane p -> p; crop c -> planes + c (paper) or planes + its plane;
  // canvas -> gq - 1 (sees nothing). Key groups: close-up -> 0; crop c valid -> 1 + 2c,
  // padding -> 2 + 2c; canvas -> gk - 1 (seen by nobody).
  const int gq = planes + std::max(n, planes) + 1, gk = 2 + 2 * n;
  std::vector<int32_t> qg(size_t(n_tok) * size_t(1 + n)), kg(qg.size());
  for (int t = 0; t < n_tok; ++t) {
    qg[size_t(t)] = closeup_plane[size_t(t)];
    kg[size_t(t)] = 0;
  }
  auto crop_row_group = [&](int c) {
    return planes + (mode == MaskMode::kPaper ? c : crop_plane[size_t(c)]);
  };
  for (int c = 0; c < n; ++c)
    for (int t = 0; t < n_tok; ++t) {
      const size_t i = size_t(1 + c) * size_t(n_tok) + size_t(t);
      const uint8_t v = crop_valid[size_t(c) * n_tok + size_t(t)];
      qg[i] = v == kCanvasPad ? gq - 1 : crop_row_group(c);
      kg[i] = v == kCanvasPad ? gk - 1 : v ? 1 + 2 * c : 2 + 2 * c;
    }
  std::vector<uint8_t> allowed(size_t(gq) * size_t(gk), 0);
  auto allow = [&](int q, int k) { allowed[size_t(q) * gk + size_t(k)] = 1; };
  for (int p = 0; p < planes; ++p) {
    allow(p, 0);
    for (int c = 0; c < n; ++c) {
      if (mode == MaskMode::kNone) {
        allow(p, 1 + 2 * c);
        allow(p, 2 + 2 * c);
      } else if (crop_plane[size_t(c)] == p) {
        allow(p, 1 + 2 * c);
      }
    }
  }
  for (int c = 0; c < n; ++c)
    for (int d = 0; d < n; ++d) {
      const bool sees =
          mode == MaskMode::kPaper ? c == d : crop_plane[size_t(c)] == crop_plane[size_t(d)];
      if (!sees) continue;
      allow(crop_row_group(c), 1 + 2 * d);
      allow(crop_row_group(c), 2 + 2 * d);
    }
  return mask_from_groups(qg, kg, gq, gk, allowed);
}

std::vector<uint8_t> build_level_mask_dense(MaskMode mode, int n_tok,
                                            const std::vector<int32_t>& closeup_plane,
                                            const std::vector<int32_t>& crop_plane,
                                            const std::vector<uint8_t>& crop_valid) {
  const int n = int(crop_plane.size());
  const size_t total = size_t(n_tok) * size_t(1 + n);
  std::vector<uint8_t> m(total * total, 0);
  for (int qv = 0; qv <= n; ++qv)
    for (int qt = 0; qt < n_tok; ++qt) {
      uint8_t* row = &m[(size_t(qv) * n_tok + size_t(qt)) * total];
      for (int kv = 0; kv <= n; ++kv)
        for (int kt = 0; kt < n_tok; ++kt) {
          bool a;
          const bool q_canvas =
              qv > 0 && crop_valid[size_t(qv - 1) * n_tok + size_t(qt)] == kCanvasPad;
          const bool k_canvas =
              kv > 0 && crop_valid[size_t(kv - 1) * n_tok + size_t(kt)] == kCanvasPad;
          if (q_canvas || k_canvas) {
            a = false;
          } else if (qv == 0 && kv == 0) {
            a = true;
          } else if (qv == 0) {
            const int c = kv - 1;
            a = mode == MaskMode::kNone || (crop_plane[size_t(c)] == closeup_plane[size_t(qt)] &&
                                            crop_valid[size_t(c) * n_tok + size_t(kt)] != 0);
          } else if (kv == 0) {
            a = false;
          } else {
            a = mode == MaskMode::kPaper ? qv == kv
                                         : crop_plane[size_t(qv - 1)] == crop_plane[size_t(kv - 1)];
          }
          row[size_t(kv) * n_tok + size_t(kt)] = a;
        }
    }
  return m;
}

double PlaneMaskSet::density() const {
  double allowed = 0, total = 0;
  for (const BlockSparseMask& m : masks) {
    allowed += double(m.allowed_pairs());
    total += double(m.nq) * double(m.nk);
  }
  return total > 0 ? allowed / total : 0;
}

std::vector<int64_t> PlaneMaskSet::view_pair_counts(int level) const {
  const int n = int(crop_plane.size()), V = 1 + n;
  const int64_t N = grids[size_t(level)].tokens();
  const auto& cp = closeup_plane[size_t(level)];
  const auto& valid = crop_valid[size_t(level)];
  std::vector<int64_t> per_plane(size_t(planes), 0);
  for (int32_t l : cp) ++per_plane[size_t(l)];
  std::vector<int64_t> out(size_t(V) * V, 0);
  out[0] = N * N;
  if (composite) {
    // tokens [c][p] and valid tokens [c][p] of each composite view.
    const auto& vp = view_plane[size_t(level)];
    std::vector<int64_t> cnt(size_t(n) * size_t(planes), 0), vcnt(cnt.size(), 0);
    for (int c = 0; c < n; ++c)
      for (int64_t t = 0; t < N; ++t) {
        const size_t i = size_t(c) * size_t(N) + size_t(t);
        ++cnt[size_t(c) * planes + size_t(vp[i])];
        vcnt[size_t(c) * planes + size_t(vp[i])] += valid[i] != 0;
      }
    for (int c = 0; c < n; ++c) {
      int64_t a = 0;
      for (int p = 0; p < planes; ++p) a += per_plane[size_t(p)] * vcnt[size_t(c) * planes + p];
      out[size_t(1 + c)] = mode == MaskMode::kNone ? N * N : a;
      for (int d = 0; d < n; ++d) {
        if (mode == MaskMode::kPaper && c != d) continue;
        int64_t b = 0;
        for (int p = 0; p < planes; ++p)
          b += cnt[size_t(c) * planes + p] * cnt[size_t(d) * planes + p];
        out[size_t(1 + c) * V + size_t(1 + d)] = b;
      }
    }
    return out;
  }
  std::vector<int64_t> nv(size_t(n), 0), nin(size_t(n), 0);  // valid, in-view tokens per crop
  for (int c = 0; c < n; ++c)
    for (int64_t t = 0; t < N; ++t) {
      const uint8_t v = valid[size_t(c) * size_t(N) + size_t(t)];
      nv[size_t(c)] += v != 0 && v != kCanvasPad;
      nin[size_t(c)] += v != kCanvasPad;
    }
  for (int c = 0; c < n; ++c) {
    out[size_t(1 + c)] = mode == MaskMode::kNone
                             ? N * nin[size_t(c)]
                             : per_plane[size_t(crop_plane[size_t(c)])] * nv[size_t(c)];
    for (int d = 0; d < n; ++d) {
      const bool sees =
          mode == MaskMode::kPaper ? c == d : crop_plane[size_t(c)] == crop_plane[size_t(d)];
      out[size_t(1 + c) * V + size_t(1 + d)] = sees ? nin[size_t(c)] * nin[size_t(d)] : 0;
    }
  }
  return out;
}

Result<PlaneMaskSet> build_plane_masks(MaskMode mode, int planes,
                                       const std::vector<int32_t>& crop_plane,
                                       const std::vector<int32_t>& plane_src, int src_h, int src_w,
                                       const std::vector<std::vector<uint8_t>>& valid_src,
                                       int valid_h, int valid_w,
                                       const std::vector<TokenGrid>& grids) {
  if (src_h <= 0 || src_w <= 0 || plane_src.size() != size_t(src_h) * size_t(src_w))
    return Status::error("plane mask: plane map has " + std::to_string(plane_src.size()) +
                         " values, expected " + std::to_string(src_h) + "x" +
                         std::to_string(src_w));
  if (valid_src.size() != crop_plane.size())
    return Status::error("plane mask: " + std::to_string(valid_src.size()) +
                         " crop validity maps for " + std::to_string(crop_plane.size()) + " crops");
  for (size_t c = 0; c < valid_src.size(); ++c)
    if (valid_h <= 0 || valid_w <= 0 || valid_src[c].size() != size_t(valid_h) * size_t(valid_w))
      return Status::error("plane mask: crop " + std::to_string(c) + " validity has " +
                           std::to_string(valid_src[c].size()) + " values, expected " +
                           std::to_string(valid_h) + "x" + std::to_string(valid_w));
  PlaneMaskSet s;
  s.mode = mode;
  s.planes = planes;
  s.crop_plane = crop_plane;
  s.grids = grids;
  for (const TokenGrid& g : grids) {
    if (g.h <= 0 || g.w <= 0) return Status::error("plane mask: empty token grid");
    s.closeup_plane.push_back(resize_nearest(plane_src, src_h, src_w, g.h, g.w));
    std::vector<uint8_t> valid;
    valid.reserve(crop_plane.size() * size_t(g.tokens()));
    for (const auto& v : valid_src) {
      const std::vector<uint8_t> r = resize_nearest(v, valid_h, valid_w, g.h, g.w);
      valid.insert(valid.end(), r.begin(), r.end());
    }
    MACRO_ASSIGN_OR_RETURN(
        BlockSparseMask m,
        build_level_mask(mode, g.tokens(), planes, s.closeup_plane.back(), crop_plane, valid));
    s.crop_valid.push_back(std::move(valid));
    s.masks.push_back(std::move(m));
  }
  return s;
}

namespace {

Status check_composite_inputs(int n_tok, int planes, const std::vector<int32_t>& closeup_plane,
                              const std::vector<int32_t>& view_plane,
                              const std::vector<uint8_t>& view_valid) {
  auto fail = [](const std::string& w) { return Status::error("composite mask: " + w); };
  if (n_tok <= 0 || planes <= 0) return fail("tokens per view and planes must be positive");
  if (closeup_plane.size() != size_t(n_tok))
    return fail("closeup_plane: expected " + std::to_string(n_tok) + " labels, found " +
                std::to_string(closeup_plane.size()));
  if (view_plane.size() % size_t(n_tok) != 0)
    return fail("view_plane: " + std::to_string(view_plane.size()) +
                " labels, expected a multiple of " + std::to_string(n_tok));
  if (view_valid.size() != view_plane.size())
    return fail("view_valid: expected " + std::to_string(view_plane.size()) + " values, found " +
                std::to_string(view_valid.size()));
  for (size_t i = 0; i < closeup_plane.size(); ++i)
    if (closeup_plane[i] < 0 || closeup_plane[i] >= planes)
      return fail("closeup_plane[" + std::to_string(i) + "] = " + std::to_string(closeup_plane[i]) +
                  ": expected a plane in [0, " + std::to_string(planes) + ")");
  for (size_t i = 0; i < view_plane.size(); ++i)
    if (view_plane[i] < 0 || view_plane[i] >= planes)
      return fail("view_plane[" + std::to_string(i) + "] = " + std::to_string(view_plane[i]) +
                  ": expected a plane in [0, " + std::to_string(planes) + ")");
  if (int64_t(n_tok) + int64_t(view_plane.size()) > (int64_t(1) << 30))
    return fail("too many tokens");
  return Status::ok();
}

}  // namespace

Result<BlockSparseMask> build_composite_level_mask(MaskMode mode, int n_tok, int planes,
                                                   const std::vector<int32_t>& closeup_plane,
                                                   const std::vector<int32_t>& view_plane,
                                                   const std::vector<uint8_t>& view_valid) {
  MACRO_TRY(check_composite_inputs(n_tok, planes, closeup_plane, view_plane, view_valid));
  const int n = int(view_plane.size() / size_t(n_tok)), P = planes;
  // Query groups: close-up plane p -> p; composite (view c, label p) -> P + p (paper: P + c P + p).
  // Key groups, plane-major so that a plane's keys of every view are adjacent: close-up -> 0;
  // composite (c, p, valid) -> 1 + 2 (p n + c) + (valid ? 0 : 1).
  const bool paper = mode == MaskMode::kPaper;
  const int gq = P + (paper ? n * P : P), gk = 1 + 2 * n * P;
  auto key = [&](int c, int p, bool valid) { return 1 + 2 * (p * n + c) + (valid ? 0 : 1); };
  auto row = [&](int c, int p) { return P + (paper ? c * P + p : p); };
  std::vector<int32_t> qg(size_t(n_tok) * size_t(1 + n)), kg(qg.size());
  for (int t = 0; t < n_tok; ++t) {
    qg[size_t(t)] = closeup_plane[size_t(t)];
    kg[size_t(t)] = 0;
  }
  for (int c = 0; c < n; ++c)
    for (int t = 0; t < n_tok; ++t) {
      const size_t i = size_t(c) * size_t(n_tok) + size_t(t);
      const int p = view_plane[i];
      qg[size_t(n_tok) + i] = row(c, p);
      kg[size_t(n_tok) + i] = key(c, p, view_valid[i] != 0);
    }
  std::vector<uint8_t> allowed(size_t(gq) * size_t(gk), 0);
  auto allow = [&](int q, int k) { allowed[size_t(q) * gk + size_t(k)] = 1; };
  for (int p = 0; p < P; ++p) {
    allow(p, 0);
    for (int c = 0; c < n; ++c)
      for (int l = 0; l < P; ++l) {
        if (mode == MaskMode::kNone) {
          allow(p, key(c, l, true));
          allow(p, key(c, l, false));
        } else if (l == p) {
          allow(p, key(c, l, true));
        }
      }
  }
  for (int c = 0; c < n; ++c)
    for (int p = 0; p < P; ++p)
      for (int d = 0; d < n; ++d) {
        if (paper && d != c) continue;
        allow(row(c, p), key(d, p, true));
        allow(row(c, p), key(d, p, false));
      }
  return mask_from_groups(qg, kg, gq, gk, allowed);
}

std::vector<uint8_t> build_composite_level_mask_dense(MaskMode mode, int n_tok,
                                                      const std::vector<int32_t>& closeup_plane,
                                                      const std::vector<int32_t>& view_plane,
                                                      const std::vector<uint8_t>& view_valid) {
  const int n = int(view_plane.size() / size_t(n_tok));
  const size_t total = size_t(n_tok) * size_t(1 + n);
  std::vector<uint8_t> m(total * total, 0);
  auto label = [&](int v, int t) {
    return v == 0 ? closeup_plane[size_t(t)] : view_plane[size_t(v - 1) * n_tok + size_t(t)];
  };
  for (int qv = 0; qv <= n; ++qv)
    for (int qt = 0; qt < n_tok; ++qt) {
      uint8_t* r = &m[(size_t(qv) * n_tok + size_t(qt)) * total];
      for (int kv = 0; kv <= n; ++kv)
        for (int kt = 0; kt < n_tok; ++kt) {
          bool a;
          const bool same = label(qv, qt) == label(kv, kt);
          if (qv == 0 && kv == 0) {
            a = true;
          } else if (qv == 0) {
            a = mode == MaskMode::kNone ||
                (same && view_valid[size_t(kv - 1) * n_tok + size_t(kt)] != 0);
          } else if (kv == 0) {
            a = false;
          } else {
            a = same && (mode != MaskMode::kPaper || qv == kv);
          }
          r[size_t(kv) * n_tok + size_t(kt)] = a;
        }
    }
  return m;
}

Result<PlaneMaskSet> build_composite_masks(
    MaskMode mode, int planes, const std::vector<int32_t>& plane_src, int src_h, int src_w,
    const std::vector<std::vector<int32_t>>& view_plane_src, int vp_h, int vp_w,
    const std::vector<std::vector<uint8_t>>& valid_src, int valid_h, int valid_w,
    const std::vector<TokenGrid>& grids) {
  if (src_h <= 0 || src_w <= 0 || plane_src.size() != size_t(src_h) * size_t(src_w))
    return Status::error("composite mask: plane map has " + std::to_string(plane_src.size()) +
                         " values, expected " + std::to_string(src_h) + "x" +
                         std::to_string(src_w));
  if (valid_src.size() != view_plane_src.size())
    return Status::error("composite mask: " + std::to_string(valid_src.size()) +
                         " validity maps for " + std::to_string(view_plane_src.size()) + " views");
  for (size_t c = 0; c < view_plane_src.size(); ++c) {
    if (vp_h <= 0 || vp_w <= 0 || view_plane_src[c].size() != size_t(vp_h) * size_t(vp_w))
      return Status::error("composite mask: view " + std::to_string(c) + " plane map has " +
                           std::to_string(view_plane_src[c].size()) + " values, expected " +
                           std::to_string(vp_h) + "x" + std::to_string(vp_w));
    if (valid_h <= 0 || valid_w <= 0 || valid_src[c].size() != size_t(valid_h) * size_t(valid_w))
      return Status::error("composite mask: view " + std::to_string(c) + " validity has " +
                           std::to_string(valid_src[c].size()) + " values, expected " +
                           std::to_string(valid_h) + "x" + std::to_string(valid_w));
  }
  PlaneMaskSet s;
  s.mode = mode;
  s.planes = planes;
  s.composite = true;
  s.crop_plane.assign(view_plane_src.size(), -1);
  s.grids = grids;
  for (const TokenGrid& g : grids) {
    if (g.h <= 0 || g.w <= 0) return Status::error("composite mask: empty token grid");
    s.closeup_plane.push_back(resize_nearest(plane_src, src_h, src_w, g.h, g.w));
    std::vector<int32_t> labels;
    std::vector<uint8_t> valid;
    labels.reserve(view_plane_src.size() * size_t(g.tokens()));
    valid.reserve(labels.capacity());
    for (size_t c = 0; c < view_plane_src.size(); ++c) {
      const std::vector<int32_t> l = resize_nearest(view_plane_src[c], vp_h, vp_w, g.h, g.w);
      labels.insert(labels.end(), l.begin(), l.end());
      const std::vector<uint8_t> v = resize_nearest(valid_src[c], valid_h, valid_w, g.h, g.w);
      for (uint8_t x : v) valid.push_back(x != 0);
    }
    MACRO_ASSIGN_OR_RETURN(BlockSparseMask m,
                           build_composite_level_mask(mode, g.tokens(), planes,
                                                      s.closeup_plane.back(), labels, valid));
    s.view_plane.push_back(std::move(labels));
    s.crop_valid.push_back(std::move(valid));
    s.masks.push_back(std::move(m));
  }
  return s;
}

}  // namespace macro::enhance
