"""An exact time-of-impact oracle for the tests: rational arithmetic, no rounding anywhere.

Every vertex moves on a straight line from x0 to x1 (its coordinates, doubles, are exact
rationals). A vertex-face pair touches at time t when the point lies in the closed triangle; an
edge-edge pair when the closed segments meet. Either happens only where the four points are
coplanar: at a root in [0, 1] of a cubic in t (a 3x3 determinant of differences of points that
are linear in t). The roots are isolated exactly (a Sturm sequence of the cubic's square-free
part over Python's Fractions) and taken in increasing order; at each, the inside conditions are
polynomials in t whose sign at the root is decided exactly:

- zero, when the condition and the cubic share the root (their gcd has a root in the isolating
  interval, counted by the gcd's own Sturm sequence);
- otherwise the sign over the isolating interval, bisected until interval arithmetic bounds the
  polynomial away from zero there (it must: the value at the root is not zero).

The earliest root where every condition holds is the exact TOI, returned as an interval
[lo, hi] of rationals that holds it (exact where the root is rational), as narrow as asked.
Pairs the method does not decide are reported as degenerate: a cubic that is zero for all t
(motion within one plane), a triangle or an edge pair with no normal at the root (collapsed, or
parallel edges), which a test then counts and skips.
"""

from __future__ import annotations

from fractions import Fraction
from typing import List, Optional, Sequence, Tuple

Poly = List[Fraction]  # coefficients, lowest degree first


def _trim(p: Poly) -> Poly:
    while p and p[-1] == 0:
        p = p[:-1]
    return p


def _add(p: Poly, q: Poly) -> Poly:
    n = max(len(p), len(q))
    return _trim([(p[i] if i < len(p) else 0) + (q[i] if i < len(q) else 0) for i in range(n)])


def _sub(p: Poly, q: Poly) -> Poly:
    return _add(p, [-c for c in q])


def _mul(p: Poly, q: Poly) -> Poly:
    if not p or not q:
        return []
    out = [Fraction(0)] * (len(p) + len(q) - 1)
    for i, a in enumerate(p):
        if a:
            for j, b in enumerate(q):
                out[i + j] += a * b
    return _trim(out)


def _eval(p: Poly, t: Fraction) -> Fraction:
    v = Fraction(0)
    for c in reversed(p):
        v = v * t + c
    return v


def _derivative(p: Poly) -> Poly:
    return _trim([c * i for i, c in enumerate(p)][1:])


def _divmod(p: Poly, q: Poly) -> Tuple[Poly, Poly]:
    p = list(p)
    quotient = [Fraction(0)] * max(len(p) - len(q) + 1, 1)
    while len(p) >= len(q) and p:
        shift = len(p) - len(q)
        factor = p[-1] / q[-1]
        quotient[shift] = factor
        for i, c in enumerate(q):
            p[i + shift] -= factor * c
        p = _trim(p[:-1])
    return _trim(quotient), p


def _gcd(p: Poly, q: Poly) -> Poly:
    p, q = _trim(p), _trim(q)
    while q:
        p, q = q, _divmod(p, q)[1]
    return [c / p[-1] for c in p] if p else []


def _sturm(p: Poly) -> List[Poly]:
    seq = [p, _derivative(p)]
    while seq[-1]:
        r = _divmod(seq[-2], seq[-1])[1]
        if not r:
            break
        seq.append([-c for c in r])
    return [s for s in seq if s]


def _sign_changes(seq: Sequence[Poly], t: Fraction) -> int:
    signs = [v for v in (_eval(s, t) for s in seq) if v != 0]
    return sum(1 for a, b in zip(signs, signs[1:]) if (a > 0) != (b > 0))


def _roots_in(seq: Sequence[Poly], lo: Fraction, hi: Fraction) -> int:
    """Distinct roots in (lo, hi] of the square-free polynomial seq[0]."""
    return _sign_changes(seq, lo) - _sign_changes(seq, hi)


def _interval_eval(p: Poly, lo: Fraction, hi: Fraction) -> Tuple[Fraction, Fraction]:
    """Bounds of p over [lo, hi] (Horner's scheme in interval arithmetic)."""
    a = b = Fraction(0)
    for c in reversed(p):
        products = (a * lo, a * hi, b * lo, b * hi)
        a, b = min(products) + c, max(products) + c
    return a, b


def _linear(x0, x1) -> List[Poly]:
    """A moving point's three coordinates as polynomials in t."""
    return [_trim([Fraction(a), Fraction(b) - Fraction(a)]) for a, b in zip(x0, x1)]


def _vsub(u, v):
    return [_sub(a, b) for a, b in zip(u, v)]


def _cross(u, v):
    return [_sub(_mul(u[1], v[2]), _mul(u[2], v[1])), _sub(_mul(u[2], v[0]), _mul(u[0], v[2])),
            _sub(_mul(u[0], v[1]), _mul(u[1], v[0]))]


def _dot(u, v):
    return _add(_add(_mul(u[0], v[0]), _mul(u[1], v[1])), _mul(u[2], v[2]))


class Degenerate(Exception):
    """The pair is outside what the oracle decides (see the module's docstring)."""


def _isolated_roots(cubic: Poly) -> Tuple[Poly, List[Poly], List[Tuple[Fraction, Fraction]]]:
    """The square-free part of `cubic`, its Sturm sequence and its roots in [0, 1], each as an
    interval (lo, hi] holding exactly one root (or lo == hi: an exact rational root), ascending."""
    square_free = _divmod(cubic, _gcd(cubic, _derivative(cubic)))[0]
    seq = _sturm(square_free)
    roots: List[Tuple[Fraction, Fraction]] = []
    zero, one = Fraction(0), Fraction(1)
    if _eval(square_free, zero) == 0:
        roots.append((zero, zero))
    stack = [(zero, one)]
    while stack:
        lo, hi = stack.pop()
        n = _roots_in(seq, lo, hi)
        if n == 0:
            continue
        if n == 1:
            roots.append((hi, hi) if _eval(square_free, hi) == 0 else (lo, hi))
            continue
        mid = (lo + hi) / 2
        stack += [(lo, mid), (mid, hi)]
    roots.sort()
    return square_free, seq, roots


def _refine(square_free: Poly, lo: Fraction, hi: Fraction) -> Tuple[Fraction, Fraction]:
    """Halves (lo, hi] around its one root (an exact one ends it)."""
    if lo == hi:
        return lo, hi
    mid = (lo + hi) / 2
    v_mid = _eval(square_free, mid)
    if v_mid == 0:
        return mid, mid
    v_hi = _eval(square_free, hi)
    if v_hi == 0:
        return hi, hi
    return (mid, hi) if (v_mid > 0) != (v_hi > 0) else (lo, mid)


def _sign_at_root(g: Poly, square_free: Poly, lo: Fraction, hi: Fraction) -> Tuple[int, Fraction, Fraction]:
    """The sign of g at the one root of square_free in (lo, hi] (or at lo == hi), and the interval
    refined so far."""
    if lo == hi:
        v = _eval(g, lo)
        return (v > 0) - (v < 0), lo, hi
    common = _gcd(square_free, g)
    if len(common) > 1 and _roots_in(_sturm(common), lo, hi) > 0:
        return 0, lo, hi
    while True:
        a, b = _interval_eval(g, lo, hi)
        if a > 0:
            return 1, lo, hi
        if b < 0:
            return -1, lo, hi
        lo, hi = _refine(square_free, lo, hi)
        if lo == hi:
            v = _eval(g, lo)
            return (v > 0) - (v < 0), lo, hi


def _earliest(cubic: Poly, conditions: Sequence[Tuple[Poly, str]], normal: Poly, width: Fraction):
    """The earliest root of `cubic` in [0, 1] where every condition holds ('>=0' or '<=0') and
    `normal` (a squared normal's length) is not zero: an interval (lo, hi) of width <= `width`
    holding it, or None."""
    if not _trim(cubic):
        raise Degenerate("coplanar for every t")
    square_free, _, roots = _isolated_roots(cubic)
    for lo, hi in roots:
        s, lo, hi = _sign_at_root(normal, square_free, lo, hi)
        if s == 0:
            raise Degenerate("no normal at a coplanar time")
        inside = True
        for g, rel in conditions:
            s, lo, hi = _sign_at_root(g, square_free, lo, hi)
            if (rel == ">=0" and s < 0) or (rel == "<=0" and s > 0):
                inside = False
                break
        if inside:
            while hi - lo > width:
                lo, hi = _refine(square_free, lo, hi)
            return lo, hi
    return None


def vertex_face_toi(p0, p1, a0, a1, b0, b1, c0, c1, width: Fraction = Fraction(1, 1 << 60)):
    """Exact earliest time in [0, 1] at which point p lies in triangle abc (closed), every point
    moving linearly from its *0 to its *1 position: (lo, hi) with lo <= TOI <= hi, hi - lo <= width
    (lo == hi when the TOI is rational), or None when they never touch. Raises Degenerate."""
    p, a, b, c = _linear(p0, p1), _linear(a0, a1), _linear(b0, b1), _linear(c0, c1)
    ab, ac, ap = _vsub(b, a), _vsub(c, a), _vsub(p, a)
    n = _cross(ab, ac)
    cubic = _dot(n, ap)
    bc, bp, ca, cp = _vsub(c, b), _vsub(p, b), _vsub(a, c), _vsub(p, c)
    conditions = [(_dot(_cross(ab, ap), n), ">=0"), (_dot(_cross(bc, bp), n), ">=0"), (_dot(_cross(ca, cp), n), ">=0")]
    return _earliest(cubic, conditions, _dot(n, n), width)


def edge_edge_toi(a0_0, a0_1, a1_0, a1_1, b0_0, b0_1, b1_0, b1_1, width: Fraction = Fraction(1, 1 << 60)):
    """Exact earliest time in [0, 1] at which segments a0a1 and b0b1 (closed) meet, every point
    moving linearly (arguments: each point's position at t = 0, then at t = 1): (lo, hi) as
    vertex_face_toi, or None. Raises Degenerate (parallel or collapsed edges at a coplanar time)."""
    a0, a1, b0, b1 = _linear(a0_0, a0_1), _linear(a1_0, a1_1), _linear(b0_0, b0_1), _linear(b1_0, b1_1)
    ea, eb = _vsub(a1, a0), _vsub(b1, b0)
    cubic = _dot(_cross(ea, _vsub(b0, a0)), _vsub(b1, a0))
    n = _cross(ea, eb)
    # Coplanar and not parallel: they meet iff each segment's ends lie on both sides (or on) of
    # the other's line, sides measured along n.
    conditions = [
        (_mul(_dot(_cross(ea, _vsub(b0, a0)), n), _dot(_cross(ea, _vsub(b1, a0)), n)), "<=0"),
        (_mul(_dot(_cross(eb, _vsub(a0, b0)), n), _dot(_cross(eb, _vsub(a1, b0)), n)), "<=0"),
    ]
    return _earliest(cubic, conditions, _dot(n, n), width)


def as_fraction(x: float) -> Fraction:
    return Fraction(x)


def optional_bounds(r: Optional[Tuple[Fraction, Fraction]]) -> Optional[Tuple[float, float]]:
    return None if r is None else (float(r[0]), float(r[1]))
