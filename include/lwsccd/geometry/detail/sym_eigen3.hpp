// lwsccd — eigen decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations.
//
// Jacobi is used (rather than the closed-form cubic) because it stays accurate for repeated and
// nearly repeated eigenvalues, which OBB fitting meets all the time (flat triangles, symmetric
// point sets), and because it cannot produce NaN from a well-formed input.
#pragma once

#include <cmath>
#include <limits>

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd::detail {

/// Symmetric 3x3 matrix stored as its upper triangle: xx, yy, zz, xy, xz, yz.
template <class T>
struct SymMat3 {
  T xx, yy, zz, xy, xz, yz;
  LWSCCD_HD T at(int r, int c) const {
    if (r == c) return r == 0 ? xx : (r == 1 ? yy : zz);
    const int s = r + c;  // (0,1) -> 1, (0,2) -> 2, (1,2) -> 3
    return s == 1 ? xy : (s == 2 ? xz : yz);
  }
};

/// Eigenvalues (descending) and orthonormal eigenvectors (rows of `vectors`, right-handed).
template <class T>
struct SymEigen3 {
  T values[3];
  Vec3<T> vectors[3];
};

/// Cyclic Jacobi: at most `max_sweeps` sweeps of the three off-diagonal rotations; converges
/// quadratically, so 3x3 matrices finish in a handful of sweeps in float and double.
template <class T>
LWSCCD_HD SymEigen3<T> symmetric_eigen3(const SymMat3<T>& m, int max_sweeps = 16) {
  // Work on a copy scaled to unit magnitude so that huge or tiny coordinates cannot overflow or
  // underflow in the rotation formulas.
  T a[3][3] = {{m.xx, m.xy, m.xz}, {m.xy, m.yy, m.yz}, {m.xz, m.yz, m.zz}};
  T scale = T(0);
  LWSCCD_UNROLL for (int r = 0; r < 3; ++r)
    LWSCCD_UNROLL for (int c = 0; c < 3; ++c) scale = std::fmax(scale, std::fabs(a[r][c]));
  T v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // columns are eigenvectors
  if (scale > T(0) && std::isfinite(scale)) {
    LWSCCD_UNROLL for (int r = 0; r < 3; ++r)
      LWSCCD_UNROLL for (int c = 0; c < 3; ++c) a[r][c] /= scale;
    for (int sweep = 0; sweep < max_sweeps; ++sweep) {
      const T off = std::fabs(a[0][1]) + std::fabs(a[0][2]) + std::fabs(a[1][2]);
      if (off == T(0)) break;
      LWSCCD_UNROLL for (int p = 0; p < 2; ++p) {
        LWSCCD_UNROLL for (int q = p + 1; q < 3; ++q) {
          const T apq = a[p][q];
          // Negligible next to the diagonal (or to the unit scale): zero it and skip the rotation,
          // so that the sweeps end as soon as the matrix is diagonal to working precision.
          const T eps = std::numeric_limits<T>::epsilon();
          if (std::fabs(apq) <= fadd(fmul(eps, fadd(std::fabs(a[p][p]), std::fabs(a[q][q]))), fmul(eps, eps))) {
            a[p][q] = a[q][p] = T(0);
            continue;
          }
          // Rotation angle that zeroes a[p][q] (Golub & Van Loan, symmetric Schur decomposition).
          // fmul/fadd/fsub (fp.hpp): the same rounding on host and device.
          const T theta = fsub(a[q][q], a[p][p]) / fmul(T(2), apq);
          const T t = (theta >= T(0) ? T(1) : T(-1)) / fadd(std::fabs(theta), std::sqrt(fadd(fmul(theta, theta), T(1))));
          const T c = T(1) / std::sqrt(fadd(fmul(t, t), T(1)));
          const T s = fmul(t, c);
          LWSCCD_UNROLL for (int k = 0; k < 3; ++k) {  // a = a * J
            const T akp = a[k][p], akq = a[k][q];
            a[k][p] = fsub(fmul(c, akp), fmul(s, akq));
            a[k][q] = fadd(fmul(s, akp), fmul(c, akq));
          }
          LWSCCD_UNROLL for (int k = 0; k < 3; ++k) {  // a = J^T * a
            const T apk = a[p][k], aqk = a[q][k];
            a[p][k] = fsub(fmul(c, apk), fmul(s, aqk));
            a[q][k] = fadd(fmul(s, apk), fmul(c, aqk));
          }
          LWSCCD_UNROLL for (int k = 0; k < 3; ++k) {  // v = v * J
            const T vkp = v[k][p], vkq = v[k][q];
            v[k][p] = fsub(fmul(c, vkp), fmul(s, vkq));
            v[k][q] = fadd(fmul(s, vkp), fmul(c, vkq));
          }
          a[p][q] = a[q][p] = T(0);  // what the rotation makes it, without the rounding residue
        }
      }
    }
  } else {
    scale = T(0);
  }
  // Sort by eigenvalue, descending: a three-element network with constant indices (registers).
  SymEigen3<T> out;
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
    out.values[i] = fmul(a[i][i], scale);
    out.vectors[i] = {v[0][i], v[1][i], v[2][i]};
  }
  auto order_pair = [&out](int i, int j) {
    if (out.values[j] > out.values[i]) {
      const T tv = out.values[i];
      out.values[i] = out.values[j];
      out.values[j] = tv;
      const Vec3<T> tw = out.vectors[i];
      out.vectors[i] = out.vectors[j];
      out.vectors[j] = tw;
    }
  };
  order_pair(0, 1);
  order_pair(1, 2);
  order_pair(0, 1);
  // Right-handed frame; rotations keep det = +1, the sort may flip it.
  if (vdot(vcross(out.vectors[0], out.vectors[1]), out.vectors[2]) < T(0)) out.vectors[2] = -out.vectors[2];
  return out;
}

}  // namespace lwsccd::detail
