// The arithmetic of the Winograd F(2x2, 3x3) transforms (conv_winograd.h), written once for
// every vector width: Ops is a traits type with V (the vector), add(a, b) and sub(a, b). The adds
// are those of the scalar twins in conv_winograd.cpp in the same order, so every width gives their
// bits. Included by the AVX2 and AVX-512 transform files (each instantiates it with its own
// flags; internal linkage).
#pragma once

namespace macro {
namespace {

// V = B^T d B for one lane per tile: d[4 i + j] the patch's rows i, columns j; v[xi], xi = 4 i + j.
template <typename Ops>
inline void winograd_btdb(const typename Ops::V* d, typename Ops::V* v) {
  typename Ops::V r[16];
#pragma GCC unroll 4
  for (int j = 0; j < 4; ++j) {
    r[0 * 4 + j] = Ops::sub(d[0 * 4 + j], d[2 * 4 + j]);
    r[1 * 4 + j] = Ops::add(d[1 * 4 + j], d[2 * 4 + j]);
    r[2 * 4 + j] = Ops::sub(d[2 * 4 + j], d[1 * 4 + j]);
    r[3 * 4 + j] = Ops::sub(d[1 * 4 + j], d[3 * 4 + j]);
  }
#pragma GCC unroll 4
  for (int i = 0; i < 4; ++i) {
    const typename Ops::V* ri = r + i * 4;
    v[i * 4 + 0] = Ops::sub(ri[0], ri[2]);
    v[i * 4 + 1] = Ops::add(ri[1], ri[2]);
    v[i * 4 + 2] = Ops::sub(ri[2], ri[1]);
    v[i * 4 + 3] = Ops::sub(ri[1], ri[3]);
  }
}

// The first half of Y = A^T M A: t[4 i + j] (i in [0, 2)) from the 16 M_xi.
template <typename Ops>
inline void winograd_atm(const typename Ops::V* m, typename Ops::V* t) {
#pragma GCC unroll 4
  for (int j = 0; j < 4; ++j) {
    t[0 * 4 + j] = Ops::add(Ops::add(m[0 * 4 + j], m[1 * 4 + j]), m[2 * 4 + j]);
    t[1 * 4 + j] = Ops::sub(Ops::sub(m[1 * 4 + j], m[2 * 4 + j]), m[3 * 4 + j]);
  }
}

// Output row i of the tiles from t (winograd_atm): its columns 0 (y0) and 1 (y1).
template <typename Ops>
inline void winograd_row(const typename Ops::V* ti, typename Ops::V* y0, typename Ops::V* y1) {
  *y0 = Ops::add(Ops::add(ti[0], ti[1]), ti[2]);
  *y1 = Ops::sub(Ops::sub(ti[1], ti[2]), ti[3]);
}

}  // namespace
}  // namespace macro
