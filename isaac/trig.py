"""sin and cos from IEEE-754 basic operations only, the same bits on every machine.

libm's sin and cos differ in the last bit between implementations (glibc versions, macOS, musl,
Windows), so a step that calls them replays bit for bit only where it was recorded. These use
only + - * /, comparisons, float -> int conversion of an integral value and integer `&`: every
one of them is exactly rounded by IEEE 754, in CPython and in numba-compiled code alike, on any
CPU without fused multiply-add (docs/physics.md, "What could still differ").

The method is fdlibm's (Sun, 1993; FreeBSD msun ``e_rem_pio2.c``, ``k_sin.c``, ``k_cos.c``):

    n = nearest integer to x * 2/pi
    r = x - n * pi/2       as a head y0 and a tail y1, pi/2 split into three 33-bit pieces
                           (Cody-Waite): each n * piece is exact for |n| < 2^20
    sin(r), cos(r) on |r| <= pi/4 by fdlibm's minimax polynomials with the tail correction
    the quadrant n mod 4 picks +-sin(r) or +-cos(r)

Accuracy: within 1 ULP of the correctly rounded result for |x| <= 2^20 * pi/2 (about 1.6e6 rad;
tests/test_trig.py checks 10^6 angles in [-pi, pi] against math.sin/math.cos). Beyond that the
reduction loses accuracy gradually but stays deterministic. |x| >= 2^50, inf and NaN give NaN.
The engine keeps angles in [-pi, pi]; scene angles are bounded by 1e6 rad (isaac.scene.limits).

Written so that ``numba.njit(sin_cos)`` compiles it unchanged (isaac/engine/geometry.py): one
self-contained function, no ``**`` (numba and CPython may evaluate powers differently), every
product written out, no call into the math module. This module imports nothing, so the scene
layer uses it without loading numba.
"""

from __future__ import annotations

# nearest-integer rounding of |v| < 2^51: (v + 1.5 * 2^52) - 1.5 * 2^52 rounds v to an integer in
# the current (round-to-nearest-even) mode; without fast-math neither CPython nor LLVM folds it.
_ROUND = 6755399441055744.0  # 1.5 * 2^52
_PIO4 = 0.7853981633974483  # float(pi / 4): below it no reduction is needed
_LIMIT = 1125899906842624.0  # 2^50: n = x * 2/pi must convert to an int exactly
_NAN = float("nan")
_TINY = 7.450580596923828e-09  # 2^-27: below it x^2/2 < ulp(1)/4
_INVPIO2 = 6.36619772367581382433e-01  # 2/pi
# pi/2 = _PIO2_1 + _PIO2_2 + _PIO2_3 + _PIO2_3T, the first three with 33 significant bits each
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21
_PIO2_3T = 8.47842766036889956997e-32  # pi/2 - _PIO2_1 - _PIO2_2 - _PIO2_3
# sin(r) ~ r + S1 r^3 + ... + S6 r^13 on |r| <= pi/4 (error < 2^-58.6)
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
# cos(r) ~ 1 - r^2/2 + C1 r^4 + ... + C6 r^14 on |r| <= pi/4 (error < 2^-58)
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11


def sin_cos(x: float) -> tuple[float, float]:
    """(sin x, cos x) for an angle x (rad), each within 1 ULP, the same bits everywhere."""
    ax = abs(x)
    if not ax < _LIMIT:  # inf, NaN or too large to reduce: NaN, never an undefined conversion
        return _NAN, _NAN
    if ax < _TINY:  # sin x = x and cos x = 1 once rounded; keeps the sign of -0.0
        return x, 1.0
    # range reduction: x = n pi/2 + (y0 + y1), |y0 + y1| <= pi/4 (plus rounding)
    reduced = ax > _PIO4
    if reduced:
        fn = (x * _INVPIO2 + _ROUND) - _ROUND
        n = int(fn)
        # determinism: r1 = x - fn * P1 is exact (fn * P1 is exact for |fn| < 2^20 and a
        # multiple of 2^-32, x a multiple of 2^-53, the difference below 1); the next two
        # pieces are subtracted with their rounding errors kept (Fast2Sum: e = (t - r) - b),
        # and the errors and the last piece form the tail w. fdlibm takes the later rounds only
        # after a cancellation; always taking them costs a few operations and no accuracy.
        r1 = x - fn * _PIO2_1
        b2 = fn * _PIO2_2
        r2 = r1 - b2
        e2 = (r1 - r2) - b2
        b3 = fn * _PIO2_3
        r3 = r2 - b3
        e3 = (r2 - r3) - b3
        w = fn * _PIO2_3T - (e2 + e3)
        y0 = r3 - w
        y1 = (r3 - y0) - w
    else:
        n = 0
        y0 = x
        y1 = 0.0
    # kernels on the reduced angle (fdlibm __kernel_sin / __kernel_cos, FreeBSD form)
    z = y0 * y0
    zz = z * z
    v = z * y0
    rs = _S2 + z * (_S3 + z * _S4) + z * zz * (_S5 + z * _S6)
    if reduced:
        s = y0 - ((z * (0.5 * y1 - v * rs) - y1) - v * _S1)
    else:
        s = y0 + v * (_S1 + z * rs)
    rc = z * (_C1 + z * (_C2 + z * _C3)) + zz * zz * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    one_minus = 1.0 - hz
    c = one_minus + (((1.0 - one_minus) - hz) + (z * rc - y0 * y1))
    # quadrant: sin and cos of (y0 + y1) + n pi/2
    q = n & 3
    if q == 0:
        return s, c
    if q == 1:
        return c, -s
    if q == 2:
        return -s, -c
    return -c, s


def sin(x: float) -> float:
    """sin x (x in rad), within 1 ULP, the same bits everywhere (pure Python; the engine
    compiles sin_cos)."""
    return sin_cos(x)[0]


def cos(x: float) -> float:
    """cos x (x in rad), within 1 ULP, the same bits everywhere (pure Python; the engine
    compiles sin_cos)."""
    return sin_cos(x)[1]
