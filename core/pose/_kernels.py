"""Compiled kernels of core.pose: the one P3L solver and the one refinement, on plain arrays.

``p3l``, ``p3l_batch`` (``core.pose.p3l``), the automatic matcher (``app.vision.matching``),
``refine``, ``refine_many`` and ``estimate_pose`` call these; the maths is the modules' own (their
docstrings explain it), written here once on scalars and small arrays and compiled by numba
(``cache=True``: compiled once per machine into ``__pycache__``, loaded from there afterwards;
``warm_up`` loads or compiles every kernel, e.g. in a background thread at start-up).

Why compiled: one P3L call is a few hundred floating-point operations and an 8 × 8 eigenproblem,
one refinement a few dozen 6 × 6 systems; in the interpreter (or as NumPy calls on tiny arrays)
each operation costs ~50× its arithmetic, so ~80 % of a call was interpreter time.

P3L roots: the eigenvalues of the (balanced) companion matrix of the degree-8 eliminant, by the
Francis double-shift QR iteration on the Hessenberg matrix (EISPACK's balanc/hqr, as LAPACK's
dgeev does for a companion matrix), without NumPy's or SciPy's per-call wrappers.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import robust

_jit = njit(cache=True, nogil=True)
# core.robust's Huber weight and cost of one residual, compiled: the refinement down-weights as every fit does
_huber_weight = _jit(robust.huber_weight)
_huber_rho = _jit(robust.huber_rho)

IMAG_TOL_RAD = 1e-4  # eigenvalues with |imaginary part| mapped to α below this are real roots
CONSTRAINT_TOL = 3e-6  # a rotation is kept when Σ_i |N_i · R V_i| is below this
PARALLEL_TOL = 1e-9  # two unit directions are parallel when the sine of their angle is below this
DEPENDENT_TOL = 1e-7  # the β-equations are dependent at a root when |nd| is below this
EPS = 2.220446049250313e-16

# status codes of ``p3l_solve``
OK, SEGS_01, SEGS_02, SEGS_12, ALL_PARALLEL, CONCURRENT = 0, 1, 2, 3, 4, 5
MAX_SOLUTIONS = 16


# ------------------------------------------------------------------------------------ roots
@_jit
def _balance(a, n):
    """EISPACK balanc on the leading n × n block (diagonal similarity, powers of 2)."""
    done = False
    while not done:
        done = True
        for i in range(n):
            c = 0.0
            r = 0.0
            for j in range(n):
                if j != i:
                    c += abs(a[j, i])
                    r += abs(a[i, j])
            if c != 0.0 and r != 0.0:
                g = r / 2.0
                f = 1.0
                s = c + r
                while c < g:
                    f *= 2.0
                    c *= 4.0
                g = r * 2.0
                while c > g:
                    f /= 2.0
                    c /= 4.0
                if (c + r) / f < 0.95 * s:
                    done = False
                    g = 1.0 / f
                    for j in range(n):
                        a[i, j] *= g
                    for j in range(n):
                        a[j, i] *= f


@_jit
def _hqr(a, n, wr, wi):
    """Eigenvalues (wr + i wi) of the upper Hessenberg leading n × n block of a (destroyed):
    the Francis double-shift QR iteration (EISPACK hqr). Returns False if it did not converge."""
    anorm = 0.0
    for i in range(n):
        for j in range(max(i - 1, 0), n):
            anorm += abs(a[i, j])
    nn = n - 1
    t = 0.0
    x = y = z = w = p = q = r = s = 0.0
    while nn >= 0:
        its = 0
        while True:
            ll = 0
            for l in range(nn, 0, -1):
                s = abs(a[l - 1, l - 1]) + abs(a[l, l])
                if s == 0.0:
                    s = anorm
                if abs(a[l, l - 1]) <= EPS * s:
                    a[l, l - 1] = 0.0
                    ll = l
                    break
            l = ll
            x = a[nn, nn]
            if l == nn:
                wr[nn] = x + t
                wi[nn] = 0.0
                nn -= 1
                break
            y = a[nn - 1, nn - 1]
            w = a[nn, nn - 1] * a[nn - 1, nn]
            if l == nn - 1:
                p = 0.5 * (y - x)
                q = p * p + w
                z = math.sqrt(abs(q))
                x += t
                if q >= 0.0:
                    z = p + (z if p >= 0.0 else -z)
                    wr[nn - 1] = wr[nn] = x + z
                    if z != 0.0:
                        wr[nn] = x - w / z
                    wi[nn - 1] = wi[nn] = 0.0
                else:
                    wr[nn - 1] = wr[nn] = x + p
                    wi[nn - 1] = -z
                    wi[nn] = z
                nn -= 2
                break
            if its == 60:
                return False
            if its == 10 or its == 20:  # exceptional shift
                t += x
                for i in range(nn + 1):
                    a[i, i] -= x
                s = abs(a[nn, nn - 1]) + abs(a[nn - 1, nn - 2])
                x = y = 0.75 * s
                w = -0.4375 * s * s
            its += 1
            m = nn - 2
            while m >= l:
                z = a[m, m]
                r = x - z
                s = y - z
                p = (r * s - w) / a[m + 1, m] + a[m, m + 1]
                q = a[m + 1, m + 1] - z - r - s
                r = a[m + 2, m + 1]
                s = abs(p) + abs(q) + abs(r)
                p /= s
                q /= s
                r /= s
                if m == l:
                    break
                u = abs(a[m, m - 1]) * (abs(q) + abs(r))
                v = abs(p) * (abs(a[m - 1, m - 1]) + abs(z) + abs(a[m + 1, m + 1]))
                if u <= EPS * v:
                    break
                m -= 1
            for i in range(m + 2, nn + 1):
                a[i, i - 2] = 0.0
                if i != m + 2:
                    a[i, i - 3] = 0.0
            for k in range(m, nn):
                if k != m:
                    p = a[k, k - 1]
                    q = a[k + 1, k - 1]
                    r = 0.0
                    if k != nn - 1:
                        r = a[k + 2, k - 1]
                    x = abs(p) + abs(q) + abs(r)
                    if x != 0.0:
                        p /= x
                        q /= x
                        r /= x
                s = math.sqrt(p * p + q * q + r * r)
                if p < 0.0:
                    s = -s
                if s != 0.0:
                    if k == m:
                        if l != m:
                            a[k, k - 1] = -a[k, k - 1]
                    else:
                        a[k, k - 1] = -s * x
                    p += s
                    x = p / s
                    y = q / s
                    z = r / s
                    q /= p
                    r /= p
                    for j in range(k, nn + 1):
                        p = a[k, j] + q * a[k + 1, j]
                        if k != nn - 1:
                            p += r * a[k + 2, j]
                            a[k + 2, j] -= p * z
                        a[k + 1, j] -= p * y
                        a[k, j] -= p * x
                    mmin = nn if nn < k + 3 else k + 3
                    for i in range(l, mmin + 1):
                        p = x * a[i, k] + y * a[i, k + 1]
                        if k != nn - 1:
                            p += z * a[i, k + 2]
                            a[i, k + 2] -= p * r
                        a[i, k + 1] -= p * q
                        a[i, k] -= p
            if l >= nn - 1:
                break
    return True


@_jit
def _poly_roots(c, d, wr, wi, work):
    """Roots (wr + i wi, d of them) of the polynomial c[0] + c[1] x + ... + c[d] x^d: the
    eigenvalues of its balanced companion matrix (last column −c_k / c_d, ones below the diagonal)."""
    for i in range(d):
        for j in range(d):
            work[i, j] = 0.0
    for i in range(1, d):
        work[i, i - 1] = 1.0
    for i in range(d):
        work[i, d - 1] = -c[i] / c[d]
    _balance(work, d)
    return _hqr(work, d, wr, wi)


@_jit
def real_roots(coef, hc, hs):
    """Real roots of one degree-8 eliminant (9 coefficients, ascending in t = tan(α/2)) as half
    angles (hc, hs) ∝ (cos α/2, sin α/2); returns their count (≤ 8).

    Coefficients below 1e-14 of the largest are zero. When the constant and leading ones both
    vanish, t = 0 and α = π are roots: they are deflated, and the polynomial between the first and
    last non-zero coefficients is solved. Otherwise, when the leading coefficient is the smaller
    end, the reversed polynomial in u = cot(α/2) is solved, so α = π is found like any other root.
    Eigenvalues whose imaginary part, mapped to α, is below 1e-4 rad are kept (a near-double real
    root split into a complex pair by rounding is not lost)."""
    amax = 0.0
    for k in range(9):
        amax = max(amax, abs(coef[k]))
    tol = 1e-14 * amax
    c = np.empty(9)
    wr = np.empty(8)
    wi = np.empty(8)
    work = np.empty((8, 8))
    count = 0
    if abs(coef[0]) <= tol and abs(coef[8]) <= tol:
        lo, hi = -1, -1
        for k in range(9):
            if abs(coef[k]) > tol:
                if lo < 0:
                    lo = k
                hi = k
        if lo < 0:
            return 0
        hc[0], hs[0] = 1.0, 0.0
        hc[1], hs[1] = 0.0, 1.0
        count = 2
        d = hi - lo
        if d > 0:
            for k in range(d + 1):
                c[k] = coef[lo + k]
            if _poly_roots(c, d, wr, wi, work):
                for k in range(d):
                    re, im = wr[k], wi[k]
                    if 2.0 * abs(im) < IMAG_TOL_RAD * (1.0 + re * re + im * im):
                        hc[count], hs[count] = 1.0, re
                        count += 1
        return count
    reverse = abs(coef[8]) < abs(coef[0])
    for k in range(9):
        c[k] = coef[8 - k] if reverse else coef[k]
    # the degree as a variable: a literal 8 would have numba compile _poly_roots and _hqr a second time (3 s)
    if not _poly_roots(c, wr.shape[0], wr, wi, work):
        return 0
    for k in range(8):
        re, im = wr[k], wi[k]
        if 2.0 * abs(im) < IMAG_TOL_RAD * (1.0 + re * re + im * im):
            if reverse:
                hc[count], hs[count] = re, 1.0
            else:
                hc[count], hs[count] = 1.0, re
            count += 1
    return count


# ------------------------------------------------------------------------------------ set-up
@_jit
def _quad_det(a, d, b, c, out):
    """a d − b c for four quadratics (ascending coefficient triples): a quartic (5 coefficients)."""
    out[0] = a[0] * d[0] - b[0] * c[0]
    out[1] = a[0] * d[1] + a[1] * d[0] - b[0] * c[1] - b[1] * c[0]
    out[2] = a[0] * d[2] + a[1] * d[1] + a[2] * d[0] - b[0] * c[2] - b[1] * c[1] - b[2] * c[0]
    out[3] = a[1] * d[2] + a[2] * d[1] - b[1] * c[2] - b[2] * c[1]
    out[4] = a[2] * d[2] - b[2] * c[2]


@_jit
def setup(n, ray, V, X, Mo, E, minors, coef):
    """The α-independent part of one triple (``core.pose.p3l``'s module docstring).

    n (3, 3) unit plane normals (world), ray (3,) the ray of l1's first clicked pixel, V (3, 3)
    unit edge directions (object), in the solver's order. Fills X (3, 3): rows are the columns
    x, y, z of R_world_c1; Mo (3, 3): rows are the columns of R_obj_m1; E (2, 3, 3): for edges 2,
    3 the half-angle quadratics of (s_c, s_s, s_rhs); minors (3, 5): nc, ns, nd times (1 + t²)²;
    coef (9,): the eliminant nc² + ns² − nd², ascending in t."""
    y0, y1, y2 = n[0, 0], n[0, 1], n[0, 2]
    k = ray[0] * y0 + ray[1] * y1 + ray[2] * y2
    x0, x1, x2 = ray[0] - k * y0, ray[1] - k * y1, ray[2] - k * y2
    k = (x0 * x0 + x1 * x1 + x2 * x2) ** -0.5
    x0, x1, x2 = x0 * k, x1 * k, x2 * k
    X[0, 0], X[0, 1], X[0, 2] = x0, x1, x2
    X[1, 0], X[1, 1], X[1, 2] = y0, y1, y2
    X[2, 0], X[2, 1], X[2, 2] = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    v0, v1, v2 = V[0, 0], V[0, 1], V[0, 2]
    w0, w1, w2 = V[1, 0], V[1, 1], V[1, 2]
    z0, z1, z2 = v1 * w2 - v2 * w1, v2 * w0 - v0 * w2, v0 * w1 - v1 * w0
    k = (z0 * z0 + z1 * z1 + z2 * z2) ** -0.5
    z0, z1, z2 = z0 * k, z1 * k, z2 * k
    Mo[0, 0], Mo[0, 1], Mo[0, 2] = v0, v1, v2
    Mo[1, 0], Mo[1, 1], Mo[1, 2] = z1 * v2 - z2 * v1, z2 * v0 - z0 * v2, z0 * v1 - z1 * v0
    Mo[2, 0], Mo[2, 1], Mo[2, 2] = z0, z1, z2
    for i in range(1, 3):
        ax = X[0, 0] * n[i, 0] + X[0, 1] * n[i, 1] + X[0, 2] * n[i, 2]
        ay = X[1, 0] * n[i, 0] + X[1, 1] * n[i, 1] + X[1, 2] * n[i, 2]
        az = X[2, 0] * n[i, 0] + X[2, 1] * n[i, 1] + X[2, 2] * n[i, 2]
        bx = Mo[0, 0] * V[i, 0] + Mo[0, 1] * V[i, 1] + Mo[0, 2] * V[i, 2]
        by = Mo[1, 0] * V[i, 0] + Mo[1, 1] * V[i, 1] + Mo[1, 2] * V[i, 2]
        bz = Mo[2, 0] * V[i, 0] + Mo[2, 1] * V[i, 1] + Mo[2, 2] * V[i, 2]
        # N·R_y(β) R_x(α) V = s_c cos β + s_s sin β − s_rhs, each s = p cos α + q sin α + r;
        # as half-angle quadratics s (1 + t²) = (p + r) + 2q t + (r − p) t².
        for j in range(3):
            if j == 0:
                p, q, r = az * bz, az * by, ax * bx
            elif j == 1:
                p, q, r = ax * bz, ax * by, -az * bx
            else:
                p, q, r = -ay * by, ay * bz, 0.0
            E[i - 1, j, 0] = p + r
            E[i - 1, j, 1] = 2.0 * q
            E[i - 1, j, 2] = r - p
    # Cramer on the two β-equations (eq. A3): cos β = nc/nd, sin β = ns/nd.
    _quad_det(E[0, 2], E[1, 1], E[0, 1], E[1, 2], minors[0])
    _quad_det(E[0, 0], E[1, 2], E[0, 2], E[1, 0], minors[1])
    _quad_det(E[0, 0], E[1, 1], E[0, 1], E[1, 0], minors[2])
    for kk in range(9):
        coef[kk] = 0.0
    for i in range(5):
        for j in range(5):
            coef[i + j] += minors[0, i] * minors[0, j] + minors[1, i] * minors[1, j] - minors[2, i] * minors[2, j]


@_jit
def _half(e, ca, sa):
    """s from its half-angle quadratic e: (e0 (1 + cos α) + e1 sin α + e2 (1 − cos α)) / 2."""
    return 0.5 * (e[0] * (1.0 + ca) + e[1] * sa + e[2] * (1.0 - ca))


@_jit
def constraint_error(E, ca, sa, cb, sb):
    """|G_2| + |G_3| at (α, β) (edge 1's constraint holds by construction of the frames)."""
    g2 = _half(E[0, 0], ca, sa) * cb + _half(E[0, 1], ca, sa) * sb - _half(E[0, 2], ca, sa)
    g3 = _half(E[1, 0], ca, sa) * cb + _half(E[1, 1], ca, sa) * sb - _half(E[1, 2], ca, sa)
    return abs(g2) + abs(g3)


@_jit
def _rotate(c, s, d):
    cd, sd = 1.0 - 0.5 * d * d, d - d * d * d / 6.0
    c2, s2 = c * cd + s * sd, s * cd - c * sd
    k = (c2 * c2 + s2 * s2) ** -0.5
    return c2 * k, s2 * k


@_jit
def polish(E, ca, sa, cb, sb):
    """One Newton step on G_2 = G_3 = 0 in (α, β), kept where it lowers |G_2| + |G_3| by a step
    below 0.1 rad (a large step means no root nearby)."""
    G = np.empty(2)
    dGa = np.empty(2)
    dGb = np.empty(2)
    for i in range(2):
        c, s, h = E[i, 0], E[i, 1], E[i, 2]
        vc, vs, vh = _half(c, ca, sa), _half(s, ca, sa), _half(h, ca, sa)
        dc = 0.5 * ((c[2] - c[0]) * sa + c[1] * ca)
        ds = 0.5 * ((s[2] - s[0]) * sa + s[1] * ca)
        dh = 0.5 * ((h[2] - h[0]) * sa + h[1] * ca)
        G[i] = vc * cb + vs * sb - vh
        dGa[i] = dc * cb + ds * sb - dh
        dGb[i] = vs * cb - vc * sb
    det = dGa[0] * dGb[1] - dGa[1] * dGb[0]
    if det == 0.0:
        det = 1e-300
    da = (G[0] * dGb[1] - G[1] * dGb[0]) / det
    db = (dGa[0] * G[1] - dGa[1] * G[0]) / det
    ca2, sa2 = _rotate(ca, sa, da)
    cb2, sb2 = _rotate(cb, sb, db)
    if constraint_error(E, ca2, sa2, cb2, sb2) < abs(G[0]) + abs(G[1]) and abs(da) < 0.1 and abs(db) < 0.1:
        return ca2, sa2, cb2, sb2
    return ca, sa, cb, sb


@_jit
def angles_at_root(minors, hc, hs):
    """(cos α, sin α, cos β, sin β, nd) at a root given by its half angle (hc, hs); nd is the
    normalised Cramer denominator (the β-equations are dependent where ~0)."""
    hc2, hs2, hcs = hc * hc, hs * hs, hc * hs
    w = hc2 + hs2
    p0, p1, p2, p3, p4 = hc2 * hc2, hc2 * hcs, hc2 * hs2, hcs * hs2, hs2 * hs2
    nc = minors[0, 0] * p0 + minors[0, 1] * p1 + minors[0, 2] * p2 + minors[0, 3] * p3 + minors[0, 4] * p4
    ns = minors[1, 0] * p0 + minors[1, 1] * p1 + minors[1, 2] * p2 + minors[1, 3] * p3 + minors[1, 4] * p4
    nd = (minors[2, 0] * p0 + minors[2, 1] * p1 + minors[2, 2] * p2 + minors[2, 3] * p3 + minors[2, 4] * p4) / (w * w)
    cb, sb = nc * nd, ns * nd
    k = 1.0 / (math.sqrt(cb * cb + sb * sb) + 1e-300)
    return (hc2 - hs2) / w, 2.0 * hcs / w, cb * k, sb * k, nd


@_jit
def beta_dependent(E, ca, sa, out):
    """Both (cos β, sin β) at a root where the two β-equations are dependent: the better
    conditioned one, s_c cos β + s_s sin β = s_rhs, intersected with the unit circle, each
    intersection kept if it satisfies the other. Fills out (2, 2) and returns how many (0-2)."""
    a0, a1, a2 = _half(E[0, 0], ca, sa), _half(E[0, 1], ca, sa), _half(E[0, 2], ca, sa)
    b0, b1, b2 = _half(E[1, 0], ca, sa), _half(E[1, 1], ca, sa), _half(E[1, 2], ca, sa)
    na, nb = math.hypot(a0, a1), math.hypot(b0, b1)
    if na >= nb:
        e0, e1, e2, nk, o0, o1, o2 = a0, a1, a2, na, b0, b1, b2
    else:
        e0, e1, e2, nk, o0, o1, o2 = b0, b1, b2, nb, a0, a1, a2
    if not (nk >= 1e-12 and abs(e2) <= nk * (1.0 + 1e-9)):
        return 0
    phi = math.atan2(e1, e0)
    delta = math.acos(min(max(e2 / nk, -1.0), 1.0))
    count = 0
    for j in range(2):
        if j == 1 and delta < 1e-12:
            break  # a tangent: the second intersection is the first
        beta = phi + delta if j == 0 else phi - delta
        cb, sb = math.cos(beta), math.sin(beta)
        if abs(o0 * cb + o1 * sb - o2) < 1e-6 and constraint_error(E, ca, sa, cb, sb) < CONSTRAINT_TOL:
            out[count, 0], out[count, 1] = cb, sb
            count += 1
    return count


@_jit
def _rotation(X, Mo, ca, sa, cb, sb, R):
    """R_world_obj = R_world_c1 · R_y(β) R_x(α) · R_obj_m1ᵀ into R (3, 3)."""
    sbsa, sbca, cbsa, cbca = sb * sa, sb * ca, cb * sa, cb * ca
    for j in range(3):
        g0 = cb * Mo[0, j] + sbsa * Mo[1, j] + sbca * Mo[2, j]
        g1 = ca * Mo[1, j] - sa * Mo[2, j]
        g2 = -sb * Mo[0, j] + cbsa * Mo[1, j] + cbca * Mo[2, j]
        for i in range(3):
            R[i, j] = X[0, i] * g0 + X[1, i] * g1 + X[2, i] * g2


@_jit
def rotations(n, ray, V, Rs):
    """Every rotation with N_i · R V_i = 0 for one triple in the solver's order (first edge
    parallel to neither other) into Rs (≥ 16, 3, 3); returns their count, before de-duplication."""
    X = np.empty((3, 3))
    Mo = np.empty((3, 3))
    E = np.empty((2, 3, 3))
    minors = np.empty((3, 5))
    coef = np.empty(9)
    setup(n, ray, V, X, Mo, E, minors, coef)
    hc = np.empty(8)
    hs = np.empty(8)
    nroots = real_roots(coef, hc, hs)
    two = np.empty((2, 2))
    count = 0
    for k in range(nroots):
        ca, sa, cb, sb, nd = angles_at_root(minors, hc[k], hs[k])
        if abs(nd) >= DEPENDENT_TOL:
            err = constraint_error(E, ca, sa, cb, sb)
            if err > 1e-12:  # polish an inaccurate root (near-double, or a near-real complex pair)
                ca, sa, cb, sb = polish(E, ca, sa, cb, sb)
                err = constraint_error(E, ca, sa, cb, sb)
            if err < CONSTRAINT_TOL:
                _rotation(X, Mo, ca, sa, cb, sb, Rs[count])
                count += 1
        else:
            m = beta_dependent(E, ca, sa, two)
            for j in range(m):
                _rotation(X, Mo, ca, sa, two[j, 0], two[j, 1], Rs[count])
                count += 1
    return count


@_jit
def _distinct(Rs, count, tol=1e-6):
    """Keep the rotations not equal to an earlier one within tol in every entry (in place)."""
    out = 0
    for k in range(count):
        dup = False
        for f in range(out):
            same = True
            for i in range(3):
                for j in range(3):
                    if abs(Rs[k, i, j] - Rs[f, i, j]) > tol:
                        same = False
            if same:
                dup = True
                break
        if not dup:
            if out != k:
                Rs[out] = Rs[k]
            out += 1
    return out


# ------------------------------------------------------------------------------------ P3L
@_jit
def planes(C, segs, n, d):
    """Interpretation planes Cᵀ l of clicked segments (S, 2, 2): unit normals n (S, 3), offsets d (S,)."""
    for i in range(segs.shape[0]):
        u1, v1, u2, v2 = segs[i, 0, 0], segs[i, 0, 1], segs[i, 1, 0], segs[i, 1, 1]
        l0, l1, l2 = v1 - v2, u2 - u1, u1 * v2 - u2 * v1
        p0 = l0 * C[0, 0] + l1 * C[1, 0] + l2 * C[2, 0]
        p1 = l0 * C[0, 1] + l1 * C[1, 1] + l2 * C[2, 1]
        p2 = l0 * C[0, 2] + l1 * C[1, 2] + l2 * C[2, 2]
        k = (p0 * p0 + p1 * p1 + p2 * p2) ** -0.5
        n[i, 0], n[i, 1], n[i, 2] = p0 * k, p1 * k, p2 * k
        d[i] = (l0 * C[0, 3] + l1 * C[1, 3] + l2 * C[2, 3]) * k


@_jit
def _cross2(a, b):
    c0 = a[1] * b[2] - a[2] * b[1]
    c1 = a[2] * b[0] - a[0] * b[2]
    c2 = a[0] * b[1] - a[1] * b[0]
    return c0 * c0 + c1 * c1 + c2 * c2


@_jit
def _concurrent(A, V, scale):
    """True when the three model lines A_i + s V_i (V_0 ∦ V_1) meet in one point."""
    w0, w1, w2 = A[1, 0] - A[0, 0], A[1, 1] - A[0, 1], A[1, 2] - A[0, 2]
    c0 = V[0, 1] * V[1, 2] - V[0, 2] * V[1, 1]
    c1 = V[0, 2] * V[1, 0] - V[0, 0] * V[1, 2]
    c2 = V[0, 0] * V[1, 1] - V[0, 1] * V[1, 0]
    cc = c0 * c0 + c1 * c1 + c2 * c2
    wc = w0 * c0 + w1 * c1 + w2 * c2
    if wc * wc > (1e-9 * scale) ** 2 * cc:
        return False
    x0 = w1 * V[1, 2] - w2 * V[1, 1]
    x1 = w2 * V[1, 0] - w0 * V[1, 2]
    x2 = w0 * V[1, 1] - w1 * V[1, 0]
    s = (x0 * c0 + x1 * c1 + x2 * c2) / cc
    D0 = A[0, 0] + s * V[0, 0] - A[2, 0]
    D1 = A[0, 1] + s * V[0, 1] - A[2, 1]
    D2 = A[0, 2] + s * V[0, 2] - A[2, 2]
    dv = D0 * V[2, 0] + D1 * V[2, 1] + D2 * V[2, 2]
    return D0 * D0 + D1 * D1 + D2 * D2 - dv * dv <= (1e-9 * scale) ** 2


@_jit
def distance_cost(C, R, t, edges, segs, pts_obj, pts_uv):
    """``residuals.distance_cost`` (its docstring): Σ of squared pixel distances of the clicks to
    the projected finite model segments and points, or −1 when a clicked model edge (both
    endpoints) or point is behind the camera."""
    a = np.empty((3, 4))
    for i in range(3):
        for j in range(3):
            a[i, j] = C[i, 0] * R[0, j] + C[i, 1] * R[1, j] + C[i, 2] * R[2, j]
        a[i, 3] = C[i, 0] * t[0] + C[i, 1] * t[1] + C[i, 2] * t[2] + C[i, 3]
    cost = 0.0
    for e in range(edges.shape[0]):
        x0, x1, x2 = edges[e, 0, 0], edges[e, 0, 1], edges[e, 0, 2]
        y0, y1, y2 = edges[e, 1, 0], edges[e, 1, 1], edges[e, 1, 2]
        sa = a[2, 0] * x0 + a[2, 1] * x1 + a[2, 2] * x2 + a[2, 3]
        sb = a[2, 0] * y0 + a[2, 1] * y1 + a[2, 2] * y2 + a[2, 3]
        if sa <= 0.0 and sb <= 0.0:
            return -1.0
        ha0 = a[0, 0] * x0 + a[0, 1] * x1 + a[0, 2] * x2 + a[0, 3]
        ha1 = a[1, 0] * x0 + a[1, 1] * x1 + a[1, 2] * x2 + a[1, 3]
        hb0 = a[0, 0] * y0 + a[0, 1] * y1 + a[0, 2] * y2 + a[0, 3]
        hb1 = a[1, 0] * y0 + a[1, 1] * y1 + a[1, 2] * y2 + a[1, 3]
        if sa > 0.0 and sb > 0.0:
            au, av = ha0 / sa, ha1 / sa
            du, dv = hb0 / sb - au, hb1 / sb - av
            dd = du * du + dv * dv + 1e-300
            for k in range(2):
                qu, qv = segs[e, k, 0], segs[e, k, 1]
                lam = min(max(((qu - au) * du + (qv - av) * dv) / dd, 0.0), 1.0)
                eu, ev = qu - au - lam * du, qv - av - lam * dv
                cost += eu * eu + ev * ev
        else:
            l0 = ha1 * sb - sa * hb1
            l1 = sa * hb0 - ha0 * sb
            l2 = ha0 * hb1 - ha1 * hb0
            g2 = l0 * l0 + l1 * l1 + 1e-300
            r1 = l0 * segs[e, 0, 0] + l1 * segs[e, 0, 1] + l2
            r2 = l0 * segs[e, 1, 0] + l1 * segs[e, 1, 1] + l2
            cost += (r1 * r1 + r2 * r2) / g2
    for p in range(pts_obj.shape[0]):
        x0, x1, x2 = pts_obj[p, 0], pts_obj[p, 1], pts_obj[p, 2]
        s = a[2, 0] * x0 + a[2, 1] * x1 + a[2, 2] * x2 + a[2, 3]
        if s <= 0.0:
            return -1.0
        du = (a[0, 0] * x0 + a[0, 1] * x1 + a[0, 2] * x2 + a[0, 3]) / s - pts_uv[p, 0]
        dv = (a[1, 0] * x0 + a[1, 1] * x1 + a[1, 2] * x2 + a[1, 3]) / s - pts_uv[p, 1]
        cost += du * du + dv * dv
    return cost


@_jit
def distance_cost_views(Cs, seg_view, pt_view, R, t, edges, segs, pts_obj, pts_uv):
    """``distance_cost`` summed over the views of ``residuals`` (Cs, seg_view, pt_view: each view's clicks
    one after the other); −1 when a clicked feature is behind its camera."""
    if Cs.shape[0] == 1:
        return distance_cost(Cs[0], R, t, edges, segs, pts_obj, pts_uv)
    cost = 0.0
    for v in range(Cs.shape[0]):
        s0, s1 = np.searchsorted(seg_view, v), np.searchsorted(seg_view, v + 1)
        p0, p1 = np.searchsorted(pt_view, v), np.searchsorted(pt_view, v + 1)
        c = distance_cost(Cs[v], R, t, edges[s0:s1], segs[s0:s1], pts_obj[p0:p1], pts_uv[p0:p1])
        if c < 0.0:
            return -1.0
        cost += c
    return cost


@_jit
def p3l_solve(C, segs, edges, pts_uv, pts_obj, T, cost, concurrent_ok=False):
    """Every pose putting three model edges (3, 2, 3) on three clicked segments (3, 2, 2).

    Fills T (≥ 16, 4, 4) with the distinct solutions whose clicked model edges and points are in
    front of the camera and cost with their ``distance_cost``, unsorted; returns (count, status).
    status OK; SEGS_ij: clicked segments i and j on one image line; ALL_PARALLEL; CONCURRENT: the
    three lines meet in one point (or their planes share a line of sight), so lines alone do not
    fix the depth: T holds the count rotations only (translations from clicked points: the caller).
    concurrent_ok: solve such triples from the three planes all the same, unless the planes are
    singular (the matcher: noisy clicks on three edges through one vertex, refined with more clicks).
    """
    n = np.empty((3, 3))
    d = np.empty(3)
    planes(C, segs, n, d)
    tol2 = PARALLEL_TOL * PARALLEL_TOL
    if _cross2(n[0], n[1]) < tol2:
        return 0, SEGS_01
    if _cross2(n[0], n[2]) < tol2:
        return 0, SEGS_02
    if _cross2(n[1], n[2]) < tol2:
        return 0, SEGS_12
    A = np.empty((3, 3))
    V = np.empty((3, 3))
    for i in range(3):
        v0 = edges[i, 1, 0] - edges[i, 0, 0]
        v1 = edges[i, 1, 1] - edges[i, 0, 1]
        v2 = edges[i, 1, 2] - edges[i, 0, 2]
        k = (v0 * v0 + v1 * v1 + v2 * v2) ** -0.5
        V[i, 0], V[i, 1], V[i, 2] = v0 * k, v1 * k, v2 * k
        A[i, 0], A[i, 1], A[i, 2] = edges[i, 0, 0], edges[i, 0, 1], edges[i, 0, 2]
    p01, p02, p12 = _cross2(V[0], V[1]) > tol2, _cross2(V[0], V[2]) > tol2, _cross2(V[1], V[2]) > tol2
    if p01 and p02:
        i0, i1, i2 = 0, 1, 2
    elif p01 and p12:
        i0, i1, i2 = 1, 2, 0
    elif p02 and p12:
        i0, i1, i2 = 2, 0, 1
    else:
        return 0, ALL_PARALLEL
    no = np.empty((3, 3))
    Vo = np.empty((3, 3))
    Ao = np.empty((3, 3))
    for r, i in enumerate((i0, i1, i2)):
        for j in range(3):
            no[r, j], Vo[r, j], Ao[r, j] = n[i, j], V[i, j], A[i, j]
    # The paper's x axis of R_c1: the ray of l1's first clicked pixel, m_u × m_v (eq. 4).
    u, v = segs[i0, 0, 0], segs[i0, 0, 1]
    mu = np.array([C[0, 0] - u * C[2, 0], C[0, 1] - u * C[2, 1], C[0, 2] - u * C[2, 2]])
    mv = np.array([C[1, 0] - v * C[2, 0], C[1, 1] - v * C[2, 1], C[1, 2] - v * C[2, 2]])
    ray = np.array([mu[1] * mv[2] - mu[2] * mv[1], mu[2] * mv[0] - mu[0] * mv[2], mu[0] * mv[1] - mu[1] * mv[0]])
    Rs = np.empty((MAX_SOLUTIONS, 3, 3))
    count = _distinct(Rs, rotations(no, ray, Vo, Rs))
    if count == 0:
        return 0, OK
    scale = 1.0
    for i in range(3):
        for j in range(3):
            scale = max(scale, abs(A[i, j]))
    det = (
        n[0, 0] * (n[1, 1] * n[2, 2] - n[1, 2] * n[2, 1])
        - n[0, 1] * (n[1, 0] * n[2, 2] - n[1, 2] * n[2, 0])
        + n[0, 2] * (n[1, 0] * n[2, 1] - n[1, 1] * n[2, 0])
    )
    if (not concurrent_ok and _concurrent(Ao, Vo, scale)) or abs(det) <= 1e-9:
        for k in range(count):
            T[k, :3, :3] = Rs[k]
        return count, CONCURRENT
    # N_i·T = −d_i − N_i·(R A_i)  (eq. 5), by Cramer's rule: T = adj(N) rhs / det(N).
    adj = np.empty((3, 3))
    for r, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):
        adj[0, r] = (n[a, 1] * n[b, 2] - n[a, 2] * n[b, 1]) / det
        adj[1, r] = (n[a, 2] * n[b, 0] - n[a, 0] * n[b, 2]) / det
        adj[2, r] = (n[a, 0] * n[b, 1] - n[a, 1] * n[b, 0]) / det
    h = np.empty(3)
    t = np.empty(3)
    out = 0
    for k in range(count):
        R = Rs[k]
        for i in range(3):
            RA0 = R[0, 0] * A[i, 0] + R[0, 1] * A[i, 1] + R[0, 2] * A[i, 2]
            RA1 = R[1, 0] * A[i, 0] + R[1, 1] * A[i, 1] + R[1, 2] * A[i, 2]
            RA2 = R[2, 0] * A[i, 0] + R[2, 1] * A[i, 1] + R[2, 2] * A[i, 2]
            h[i] = -d[i] - n[i, 0] * RA0 - n[i, 1] * RA1 - n[i, 2] * RA2
        for i in range(3):
            t[i] = adj[i, 0] * h[0] + adj[i, 1] * h[1] + adj[i, 2] * h[2]
        c = distance_cost(C, R, t, edges, segs, pts_obj, pts_uv)  # −1: a clicked feature behind
        if c >= 0.0:
            for i in range(3):
                for j in range(3):
                    T[out, i, j] = R[i, j]
                T[out, i, 3] = t[i]
                T[out, 3, i] = 0.0
            T[out, 3, 3] = 1.0
            cost[out] = c
            out += 1
    return out, OK


@_jit
def p3l_many(C, segs, edges, T, valid, concurrent_ok=False):
    """``p3l_solve`` for every triple b: segs (B, 3, 2, 2), edges (B, 3, 2, 3) → T (B, 16, 4, 4),
    valid (B, 16); a triple p3l would reject (or that needs clicked points, unless concurrent_ok)
    has no valid slot."""
    no_uv = np.zeros((0, 2))
    no_X = np.zeros((0, 3))
    cost = np.empty(MAX_SOLUTIONS)
    for b in range(segs.shape[0]):
        count, status = p3l_solve(C, segs[b], edges[b], no_uv, no_X, T[b], cost, concurrent_ok)
        for k in range(MAX_SOLUTIONS):
            valid[b, k] = status == OK and k < count


@_jit
def rotations_many(n, ray, V, R, valid):
    """``rotations`` for every triple b: n (B, 3, 3), ray (B, 3), V (B, 3, 3) → R (B, 16, 3, 3),
    valid (B, 16) (distinct rotations first)."""
    Rs = np.empty((MAX_SOLUTIONS, 3, 3))
    for b in range(n.shape[0]):
        count = _distinct(Rs, rotations(n[b], ray[b], V[b], Rs))
        for k in range(MAX_SOLUTIONS):
            valid[b, k] = k < count
            if k < count:
                R[b, k] = Rs[k]


# ------------------------------------------------------------------------------------ refinement
@_jit
def residuals(Cs, seg_view, pt_view, R, t, edges, segs, pts_obj, pts_uv, want_J, r, J):
    """``core.pose.residuals.residuals`` (its docstring) into r (m,) and, when want_J, J (m, 6), for
    clicks in V views: Cs (V, 3, 4), seg_view (S,) and pt_view (P,) the view of each clicked segment
    and point; returns feasible."""
    V = Cs.shape[0]
    MRs = np.empty((V, 3, 3))
    bs = np.empty((V, 3))
    for vw in range(V):
        for i in range(3):
            for j in range(3):
                MRs[vw, i, j] = Cs[vw, i, 0] * R[0, j] + Cs[vw, i, 1] * R[1, j] + Cs[vw, i, 2] * R[2, j]
            bs[vw, i] = Cs[vw, i, 0] * t[0] + Cs[vw, i, 1] * t[1] + Cs[vw, i, 2] * t[2] + Cs[vw, i, 3]
    S = edges.shape[0]
    P = pts_obj.shape[0]
    feasible = True
    if S:
        H = np.empty((S, 2, 3))
        L = np.empty((S, 3))
        g = np.empty(S)
        lmax = 0.0
        gmin = np.inf
        zmin = np.inf
        for s in range(S):
            vw = seg_view[s]
            for e in range(2):
                for i in range(3):
                    H[s, e, i] = (
                        MRs[vw, i, 0] * edges[s, e, 0]
                        + MRs[vw, i, 1] * edges[s, e, 1]
                        + MRs[vw, i, 2] * edges[s, e, 2]
                        + bs[vw, i]
                    )
            hA, hB = H[s, 0], H[s, 1]
            L[s, 0] = hA[1] * hB[2] - hA[2] * hB[1]
            L[s, 1] = hA[2] * hB[0] - hA[0] * hB[2]
            L[s, 2] = hA[0] * hB[1] - hA[1] * hB[0]
            g[s] = math.hypot(L[s, 0], L[s, 1])
            gmin = min(gmin, g[s])
            zmin = min(zmin, max(hA[2], hB[2]))
            for i in range(3):
                lmax = max(lmax, abs(L[s, i]))
        if not (zmin > 0 and gmin > 1e-12 * lmax):
            feasible = False
            for s in range(S):
                lrow = max(abs(L[s, 0]), max(abs(L[s, 1]), abs(L[s, 2])))
                if not (g[s] > 1e-12 * lrow and (H[s, 0, 2] > 0 or H[s, 1, 2] > 0)):
                    g[s] = np.nan
        for s in range(S):
            vw = seg_view[s]
            l0, l1, l2 = L[s, 0] / g[s], L[s, 1] / g[s], L[s, 2] / g[s]
            for k in range(2):
                q0, q1 = segs[s, k, 0], segs[s, k, 1]
                rk = l0 * q0 + l1 * q1 + l2
                r[2 * s + k] = rk
                if want_J:
                    # r = (hA × hB)·q / g: dr/dhA = hB × p, dr/dhB = p × hA, p = (q − r l̂_xy) / g;
                    # dh/dδ = [M, −M [X − t]×]: dr/dδt = Σ a_X, dr/dδr = Σ (X − t) × a_X, a_X = Mᵀ dr/dh_X.
                    p0, p1, p2 = (q0 - rk * l0) / g[s], (q1 - rk * l1) / g[s], 1.0 / g[s]
                    row = 2 * s + k
                    for i in range(6):
                        J[row, i] = 0.0
                    for e in range(2):
                        o = H[s, 1] if e == 0 else H[s, 0]
                        sg = 1.0 if e == 0 else -1.0
                        c0 = sg * (o[1] * p2 - o[2] * p1)
                        c1 = sg * (o[2] * p0 - o[0] * p2)
                        c2 = sg * (o[0] * p1 - o[1] * p0)
                        a0 = c0 * Cs[vw, 0, 0] + c1 * Cs[vw, 1, 0] + c2 * Cs[vw, 2, 0]
                        a1 = c0 * Cs[vw, 0, 1] + c1 * Cs[vw, 1, 1] + c2 * Cs[vw, 2, 1]
                        a2 = c0 * Cs[vw, 0, 2] + c1 * Cs[vw, 1, 2] + c2 * Cs[vw, 2, 2]
                        x0 = R[0, 0] * edges[s, e, 0] + R[0, 1] * edges[s, e, 1] + R[0, 2] * edges[s, e, 2]
                        x1 = R[1, 0] * edges[s, e, 0] + R[1, 1] * edges[s, e, 1] + R[1, 2] * edges[s, e, 2]
                        x2 = R[2, 0] * edges[s, e, 0] + R[2, 1] * edges[s, e, 1] + R[2, 2] * edges[s, e, 2]
                        J[row, 0] += a0
                        J[row, 1] += a1
                        J[row, 2] += a2
                        J[row, 3] += x1 * a2 - x2 * a1
                        J[row, 4] += x2 * a0 - x0 * a2
                        J[row, 5] += x0 * a1 - x1 * a0
    for p in range(P):
        vw = pt_view[p]
        h0 = MRs[vw, 0, 0] * pts_obj[p, 0] + MRs[vw, 0, 1] * pts_obj[p, 1] + MRs[vw, 0, 2] * pts_obj[p, 2] + bs[vw, 0]
        h1 = MRs[vw, 1, 0] * pts_obj[p, 0] + MRs[vw, 1, 1] * pts_obj[p, 1] + MRs[vw, 1, 2] * pts_obj[p, 2] + bs[vw, 1]
        s_ = MRs[vw, 2, 0] * pts_obj[p, 0] + MRs[vw, 2, 1] * pts_obj[p, 1] + MRs[vw, 2, 2] * pts_obj[p, 2] + bs[vw, 2]
        if not s_ > 0:
            feasible = False
            s_ = np.nan
        u, v = h0 / s_, h1 / s_
        row = 2 * S + 2 * p
        r[row] = u - pts_uv[p, 0]
        r[row + 1] = v - pts_uv[p, 1]
        if want_J:
            x0 = R[0, 0] * pts_obj[p, 0] + R[0, 1] * pts_obj[p, 1] + R[0, 2] * pts_obj[p, 2]
            x1 = R[1, 0] * pts_obj[p, 0] + R[1, 1] * pts_obj[p, 1] + R[1, 2] * pts_obj[p, 2]
            x2 = R[2, 0] * pts_obj[p, 0] + R[2, 1] * pts_obj[p, 1] + R[2, 2] * pts_obj[p, 2]
            for k in range(2):
                uk = u if k == 0 else v
                a0 = (Cs[vw, k, 0] - uk * Cs[vw, 2, 0]) / s_
                a1 = (Cs[vw, k, 1] - uk * Cs[vw, 2, 1]) / s_
                a2 = (Cs[vw, k, 2] - uk * Cs[vw, 2, 2]) / s_
                J[row + k, 0], J[row + k, 1], J[row + k, 2] = a0, a1, a2
                J[row + k, 3] = x1 * a2 - x2 * a1
                J[row + k, 4] = x2 * a0 - x0 * a2
                J[row + k, 5] = x0 * a1 - x1 * a0
    return feasible


@_jit
def robust(r, S, huber, huber_px, b, w, w_unit):
    """Cost of residuals r (m,) and their weights w (m,) (1/σ² b times the robust weights), the
    per-pixel robust weights w_unit (2 S + P,): each clicked pixel's (a point's by its 2D distance)
    Huber weight and cost, ``core.robust.huber_weight`` / ``huber_rho``."""
    m = r.shape[0]
    P = (m - 2 * S) // 2
    if not huber:
        cost = 0.0
        for i in range(m):
            cost += b[i] * r[i] * r[i]
            w[i] = b[i]
        for i in range(2 * S + P):
            w_unit[i] = 1.0
        return 0.5 * cost
    cost = 0.0
    for i in range(2 * S + P):
        if i < 2 * S:
            e = abs(r[i])
            bu = b[i]
        else:
            j = 2 * S + 2 * (i - 2 * S)
            e = math.sqrt(r[j] * r[j] + r[j + 1] * r[j + 1])
            bu = b[j]
        wu = _huber_weight(e, huber_px)
        w_unit[i] = wu
        cost += bu * _huber_rho(e, huber_px)
        if i < 2 * S:
            w[i] = wu * b[i]
        else:
            w[j] = wu * b[j]
            w[j + 1] = wu * b[j + 1]
    return cost


@_jit
def _normal_equations(J, w, r, H, g):
    m = r.shape[0]
    for i in range(6):
        g[i] = 0.0
        for j in range(6):
            H[i, j] = 0.0
    for k in range(m):
        wk = w[k]
        for i in range(6):
            wi = wk * J[k, i]
            g[i] += wi * r[k]
            for j in range(i, 6):
                H[i, j] += wi * J[k, j]
    for i in range(6):
        for j in range(i):
            H[i, j] = H[j, i]


@_jit
def _solve_spd(A, rhs, x):
    """x with A x = rhs for a symmetric 6 × 6 A: Cholesky, or least squares if A is not SPD."""
    n = 6
    Lc = np.zeros((n, n))
    ok = True
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= Lc[j, k] * Lc[j, k]
        if not s > 0.0:
            ok = False
            break
        Lc[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= Lc[i, k] * Lc[j, k]
            Lc[i, j] = s / Lc[j, j]
    if ok:
        y = np.empty(n)
        for i in range(n):
            s = rhs[i]
            for k in range(i):
                s -= Lc[i, k] * y[k]
            y[i] = s / Lc[i, i]
        for i in range(n - 1, -1, -1):
            s = y[i]
            for k in range(i + 1, n):
                s -= Lc[k, i] * x[k]
            x[i] = s / Lc[i, i]
        return
    sol = np.linalg.lstsq(A, rhs)[0]
    for i in range(n):
        x[i] = sol[i]


@_jit
def _perturb(R, t, delta, R_new, t_new):
    """R ← exp([δr]×) R, t ← t + δt (``residuals.perturb``)."""
    x, y, z = delta[3], delta[4], delta[5]
    th2 = x * x + y * y + z * z
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    xx, yy, zz, xy, xz, yz = x * x, y * y, z * z, x * y, x * z, y * z
    E = np.empty((3, 3))
    E[0, 0], E[0, 1], E[0, 2] = 1.0 - b * (yy + zz), b * xy - a * z, b * xz + a * y
    E[1, 0], E[1, 1], E[1, 2] = b * xy + a * z, 1.0 - b * (xx + zz), b * yz - a * x
    E[2, 0], E[2, 1], E[2, 2] = b * xz - a * y, b * yz + a * x, 1.0 - b * (xx + yy)
    for i in range(3):
        for j in range(3):
            R_new[i, j] = E[i, 0] * R[0, j] + E[i, 1] * R[1, j] + E[i, 2] * R[2, j]
        t_new[i] = t[i] + delta[i]


@_jit
def _norm3(v, o):
    return math.sqrt(v[o] * v[o] + v[o + 1] * v[o + 1] + v[o + 2] * v[o + 2])


@_jit
def _log3(E, phi):
    """phi (3,) = log(E), the rotation vector of a rotation matrix E (``core.transforms.log_so3``)."""
    w0, w1, w2 = E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]  # 2 sin θ · axis
    c = min(1.0, max(-1.0, 0.5 * (E[0, 0] + E[1, 1] + E[2, 2] - 1.0)))
    th = math.atan2(0.5 * math.sqrt(w0 * w0 + w1 * w1 + w2 * w2), c)
    if th < 1e-6:
        f = 0.5
    elif math.pi - th > 1e-3:
        f = th / (2.0 * math.sin(th))
    else:  # near π: the axis from the symmetric part, its sign from the antisymmetric one
        k, best = 0, -1.0
        for i in range(3):
            a = (E[i, i] - c) / (1.0 - c)
            if a > best:
                k, best = i, a
        n = 0.0
        for i in range(3):
            phi[i] = (0.5 * (E[i, k] + E[k, i]) - (c if i == k else 0.0)) / (1.0 - c)
            n += phi[i] * phi[i]
        n = math.sqrt(n)
        sgn = 1.0 if phi[0] * w0 + phi[1] * w1 + phi[2] * w2 >= 0.0 else -1.0
        for i in range(3):
            phi[i] *= sgn * th / n
        return
    phi[0], phi[1], phi[2] = f * w0, f * w1, f * w2


@_jit
def _prior_terms(R, t, prior_T, Lam, H, g):
    """Add a pose prior to the normal equations H (6, 6), g (6,) at (R, t) and return its cost
    ½ eᵀ Λ e, e = (t − t₀, log(R R₀ᵀ)) (``refine.PosePrior``); e's Jacobian in δ is diag(I, J_l⁻¹(e_r))."""
    e = np.empty(6)
    E = np.empty((3, 3))
    for i in range(3):
        e[i] = t[i] - prior_T[i, 3]
        for j in range(3):
            E[i, j] = R[i, 0] * prior_T[j, 0] + R[i, 1] * prior_T[j, 1] + R[i, 2] * prior_T[j, 2]
    phi = np.empty(3)
    _log3(E, phi)
    e[3], e[4], e[5] = phi[0], phi[1], phi[2]
    # J_l⁻¹(φ) = I − ½ [φ]× + (1/θ² − (1 + cos θ) / (2 θ sin θ)) [φ]×²
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    th = math.sqrt(th2)
    q = 1.0 / 12.0 if th < 1e-4 else 1.0 / th2 - (1.0 + math.cos(th)) / (2.0 * th * math.sin(th))
    K = np.zeros((3, 3))
    K[0, 1], K[0, 2], K[1, 2] = -phi[2], phi[1], -phi[0]
    K[1, 0], K[2, 0], K[2, 1] = phi[2], -phi[1], phi[0]
    Je = np.zeros((6, 6))
    for i in range(3):
        Je[i, i] = 1.0
        for j in range(3):
            Je[3 + i, 3 + j] = (
                (1.0 if i == j else 0.0)
                - 0.5 * K[i, j]
                + q * (K[i, 0] * K[0, j] + K[i, 1] * K[1, j] + K[i, 2] * K[2, j])
            )
    LJ = Lam @ Je
    Le = Lam @ e
    cost = 0.0
    for i in range(6):
        cost += 0.5 * e[i] * Le[i]
        for j in range(6):
            g[i] += Je[j, i] * Le[j]
            h = 0.0
            for k in range(6):
                h += Je[k, i] * LJ[k, j]
            H[i, j] += h
    return cost


# refine statuses
REFINED, BEHIND, UNOBSERVABLE, SINGULAR = 0, 1, 2, 3


@_jit
def _inverse6(H, out):
    """out = H⁻¹ (6 × 6) by Gauss–Jordan with partial pivoting; False when H is singular (a zero or
    non-finite pivot), as LAPACK's getrf reports it."""
    n = 6
    A = np.empty((n, 2 * n))
    for i in range(n):
        for j in range(n):
            A[i, j] = H[i, j]
            A[i, n + j] = 1.0 if i == j else 0.0
    for c in range(n):
        p = c
        for i in range(c + 1, n):
            if abs(A[i, c]) > abs(A[p, c]):
                p = i
        piv = A[p, c]
        if piv == 0.0 or not np.isfinite(piv):
            return False
        if p != c:
            for j in range(2 * n):
                A[c, j], A[p, j] = A[p, j], A[c, j]
        for j in range(2 * n):
            A[c, j] /= piv
        for i in range(n):
            if i != c:
                f = A[i, c]
                if f != 0.0:
                    for j in range(2 * n):
                        A[i, j] -= f * A[c, j]
    for i in range(n):
        for j in range(n):
            out[i, j] = A[i, n + j]
    return True


@_jit
def refine_one(
    Cs,
    seg_view,
    pt_view,
    T0,
    edges,
    segs,
    pts_obj,
    pts_uv,
    b,
    huber,
    huber_px,
    has_prior,
    prior_T,
    Lam,
    max_iterations,
    extent,
    T,
    r,
    J,
    w,
    w_unit,
    H,
    free,
):
    """Levenberg–Marquardt on the pixel residuals from T0 (``refine``'s module docstring), the clicks
    in the views of ``residuals`` (Cs, seg_view, pt_view); with ``has_prior``, plus the pose prior
    ½ eᵀ Λ e about prior_T (4, 4) with information Lam (6, 6) (``_prior_terms``).

    Fills T (4, 4), r (m,), J (m, 6), w (m,), w_unit (2 S + P,) at the solution and H (6, 6) =
    Jᵀ W J (+ the prior's Λ) there; returns (status, iterations, converged). status BEHIND: the start
    puts a clicked feature behind the camera; UNOBSERVABLE: the clicks (and the prior) leave a motion
    free (free (6,): it, δt in m, δr in rad)."""
    m = r.shape[0]
    S = edges.shape[0]
    R = T0[:3, :3].copy()
    t = T0[:3, 3].copy()
    if not residuals(Cs, seg_view, pt_view, R, t, edges, segs, pts_obj, pts_uv, True, r, J):
        return BEHIND, 0, False
    # Observability: JᵀJ scaled to unit diagonal, smallest eigenvalue below 1e-16 of the largest
    # (with a prior: Jᵀ B J + Λ, the information of clicks and prior together).
    if has_prior:
        _normal_equations(J, b, r, H, free)
        _prior_terms(R, t, prior_T, Lam, H, free)
    else:
        ones = np.ones(m)
        _normal_equations(J, ones, r, H, free)
    sc = np.empty(6)
    for i in range(6):
        sc[i] = math.sqrt(H[i, i]) if H[i, i] > 0.0 else 1.0
    Hs = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            Hs[i, j] = H[i, j] / (sc[i] * sc[j])
    ev, vec = np.linalg.eigh(Hs)
    if not ev[0] > 1e-16 * ev[5]:
        for i in range(6):
            free[i] = vec[i, 0] / sc[i]
        return UNOBSERVABLE, 0, False
    cost = robust(r, S, huber, huber_px, b, w, w_unit)
    n_scratch = 6 if has_prior else 0
    H_scratch, g_scratch = np.zeros((n_scratch, 6)), np.zeros(n_scratch)  # _prior_terms' sums for its cost alone
    if has_prior:
        cost += _prior_terms(R, t, prior_T, Lam, H_scratch, g_scratch)
    r_new = np.empty(m)
    J_new = np.empty((m, 6))
    w_new = np.empty(m)
    wu_new = np.empty(w_unit.shape[0])
    R_new = np.empty((3, 3))
    t_new = np.empty(3)
    g = np.empty(6)
    A = np.empty((6, 6))
    neg = np.empty(6)
    delta = np.empty(6)
    lam = 1e-4
    iterations = 0
    converged = False
    cost_new = cost
    while iterations < max_iterations:
        if cost <= 1e-20 * m:  # residuals at round-off: exact data, done
            converged = True
            break
        _normal_equations(J, w, r, H, g)
        if has_prior:
            _prior_terms(R, t, prior_T, Lam, H, g)
        for i in range(6):
            neg[i] = -g[i]
        while True:
            for i in range(6):
                for j in range(6):
                    A[i, j] = H[i, j]
                A[i, i] = H[i, i] + lam * H[i, i]
            _solve_spd(A, neg, delta)
            if _norm3(delta, 3) + _norm3(delta, 0) / extent < 1e-12:
                lam = np.inf  # the Gauss–Newton step itself is negligible: at the minimum
                break
            _perturb(R, t, delta, R_new, t_new)
            if residuals(Cs, seg_view, pt_view, R_new, t_new, edges, segs, pts_obj, pts_uv, True, r_new, J_new):
                cost_new = robust(r_new, S, huber, huber_px, b, w_new, wu_new)
                if has_prior:
                    cost_new += _prior_terms(R_new, t_new, prior_T, Lam, H_scratch, g_scratch)
                if cost_new <= cost:
                    break
            lam *= 10.0
            if lam > 1e12:
                break
        if lam > 1e12:
            converged = True  # no step lowers the cost: a minimum to machine precision
            break
        iterations += 1
        decrease = cost - cost_new
        R[:, :] = R_new
        t[:] = t_new
        r[:] = r_new
        J[:, :] = J_new
        w[:] = w_new
        cost = cost_new
        lam = max(lam * 0.1, 1e-12)
        step = _norm3(delta, 3) + _norm3(delta, 0) / extent
        if step < 1e-9 or decrease <= 1e-10 * cost:
            converged = True
            break
    robust(r, S, huber, huber_px, b, w, w_unit)
    _normal_equations(J, w, r, H, g)
    if has_prior:
        _prior_terms(R, t, prior_T, Lam, H, g)
    for i in range(4):
        for j in range(4):
            T[i, j] = 0.0
    T[:3, :3] = R
    T[:3, 3] = t
    T[3, 3] = 1.0
    return REFINED, iterations, converged


@_jit
def refine_many(
    Cs,
    seg_view,
    pt_view,
    T0,
    edges,
    segs,
    pts_obj,
    pts_uv,
    b,
    huber,
    huber_px,
    has_prior,
    prior_T,
    Lam,
    max_iterations,
    extent,
    T,
    r,
    w_unit,
    cov,
    free,
    status,
    iterations,
    converged,
    score,
    summary,
):
    """``refine_one`` from each start T0 (K, 4, 4) with the model edges edges (K, S, 2, 3) (one
    assignment per start) and the clicked features' extent (K,); outputs gain a leading axis K:
    T, r, w_unit, cov = (Jᵀ W J + Λ)⁻¹ (Λ = 0 without a prior), free, status, iterations,
    converged; score (K,): the RMS pixel distance of the clicks to the projected finite model features at the result
    (``distance_cost``), inf when a clicked feature is behind the camera or the refinement failed;
    summary (K, 2 (S + P) + 2): per click its residual (a segment's larger |distance|, a point's
    distance), then per click its smallest robust weight, then the RMS of r and the a-posteriori σ
    (NaN without redundancy)."""
    K, S = edges.shape[0], edges.shape[1]
    P = pts_obj.shape[0]
    m = 2 * (S + P)
    n = 2 * S + P
    J = np.empty((m, 6))
    w = np.empty(m)
    H = np.empty((6, 6))
    for k in range(K):
        st, it, cv = refine_one(
            Cs,
            seg_view,
            pt_view,
            T0[k],
            edges[k],
            segs,
            pts_obj,
            pts_uv,
            b,
            huber,
            huber_px,
            has_prior,
            prior_T,
            Lam,
            max_iterations,
            extent[k],
            T[k],
            r[k],
            J,
            w,
            w_unit[k],
            H,
            free[k],
        )
        status[k], iterations[k], converged[k] = st, it, cv
        score[k] = np.inf
        if st != REFINED:
            continue
        if not _inverse6(H, cov[k]):
            status[k] = SINGULAR
            continue
        c = distance_cost_views(Cs, seg_view, pt_view, T[k, :3, :3], T[k, :3, 3], edges[k], segs, pts_obj, pts_uv)
        if c >= 0.0:
            score[k] = math.sqrt(c / max(n, 1))
        rk, wu = r[k], w_unit[k]
        for i in range(S + P):
            if i < S:
                summary[k, i] = max(abs(rk[2 * i]), abs(rk[2 * i + 1]))
                summary[k, S + P + i] = min(wu[2 * i], wu[2 * i + 1])
            else:
                j = 2 * i
                summary[k, i] = math.sqrt(rk[j] * rk[j] + rk[j + 1] * rk[j + 1])
                summary[k, S + P + i] = wu[2 * S + (i - S)]
        ss = 0.0
        wss = 0.0
        for i in range(m):
            ss += rk[i] * rk[i]
            wss += w[i] / b[i] * rk[i] * rk[i]
        summary[k, 2 * (S + P)] = math.sqrt(ss / m) if m > 0 else 0.0
        summary[k, 2 * (S + P) + 1] = math.sqrt(wss / (m - 6)) if m > 6 else np.nan


@_jit
def clicks_ok(segs, edges, pts_uv, pts_obj, max_px, max_m):
    """True when ``residuals.as_clicks`` would accept these arrays as they are (right shapes
    assumed): every pixel within max_px, every coordinate within max_m (so finite), and no
    segment or edge with coinciding points; False: let as_clicks say what is wrong."""
    mp = 0.0
    for v in segs.ravel():
        if not abs(v) <= max_px:
            return False
        mp = max(mp, abs(v))
    for v in pts_uv.ravel():
        if not abs(v) <= max_px:
            return False
    mm = 0.0
    for v in edges.ravel():
        if not abs(v) <= max_m:
            return False
        mm = max(mm, abs(v))
    for v in pts_obj.ravel():
        if not abs(v) <= max_m:
            return False
    tp = (1e-9 * max(1.0, mp)) ** 2
    for s in range(segs.shape[0]):
        du, dv = segs[s, 1, 0] - segs[s, 0, 0], segs[s, 1, 1] - segs[s, 0, 1]
        if du * du + dv * dv < tp:
            return False
    tm = (1e-12 * max(1.0, mm)) ** 2
    for s in range(edges.shape[0]):
        dx, dy, dz = edges[s, 1, 0] - edges[s, 0, 0], edges[s, 1, 1] - edges[s, 0, 1], edges[s, 1, 2] - edges[s, 0, 2]
        if dx * dx + dy * dy + dz * dz < tm:
            return False
    return True


@_jit
def pose_ok(T, max_m):
    """True when T (4, 4) is plainly a rigid transform: finite, last row (0, 0, 0, 1), R orthonormal
    to 1e-9 with det > 0, |t| within max_m (``refine._as_pose``'s fast test)."""
    if not (T[3, 0] == 0.0 and T[3, 1] == 0.0 and T[3, 2] == 0.0 and T[3, 3] == 1.0):
        return False
    for i in range(3):
        if not abs(T[i, 3]) <= max_m:
            return False
        for j in range(3):
            if not abs(T[i, j]) <= 2.0:
                return False
    for i in range(3):
        for j in range(3):
            d = T[0, i] * T[0, j] + T[1, i] * T[1, j] + T[2, i] * T[2, j] - (1.0 if i == j else 0.0)
            if not abs(d) < 1e-9:
                return False
    det = (
        T[0, 0] * (T[1, 1] * T[2, 2] - T[1, 2] * T[2, 1])
        - T[0, 1] * (T[1, 0] * T[2, 2] - T[1, 2] * T[2, 0])
        + T[0, 2] * (T[1, 0] * T[2, 1] - T[1, 1] * T[2, 0])
    )
    return det > 0.0


def _readonly(a: np.ndarray) -> np.ndarray:
    a = a.view()
    a.flags.writeable = False
    return a


WARM_UP_PARTS = ("solvers", "refinement")  # two halves of about equal compile time (18-20 s each on first use)


def warm_up(parts: tuple[str, ...] = WARM_UP_PARTS) -> None:
    """Load (or, the first time on a machine, compile: ~45 s) every kernel, with the argument types
    core.pose passes: call it in a background thread at start-up so that no click waits for it.
    ``parts``: the P3L solvers, the refinement, or both (two processes can compile one each)."""
    unknown = set(parts) - set(WARM_UP_PARTS)
    if unknown:
        raise ValueError(f"unknown kernel parts {sorted(unknown)}: choose among {WARM_UP_PARTS}")
    C = _readonly(np.array([[500.0, 0.0, 320.0, 0.0], [0.0, 500.0, 240.0, 0.0], [0.0, 0.0, 1.0, 0.0]]))  # a Camera's
    segs = np.array(
        [[[100.0, 100.0], [200.0, 110.0]], [[300.0, 120.0], [310.0, 300.0]], [[120.0, 300.0], [400.0, 250.0]]]
    )
    edges = np.array(
        [[[0.0, 0.0, 2.0], [0.3, 0.0, 2.0]], [[0.3, 0.0, 2.0], [0.3, 0.2, 2.1]], [[0.0, 0.2, 2.0], [0.0, 0.2, 2.3]]]
    )
    no_uv, no_X = np.zeros((0, 2)), np.zeros((0, 3))
    # read-only as core.pose passes them (core.pose._lazy.frozen): clicks_ok, distance_cost, refine_many's clicks
    ro_segs, ro_edges, ro_uv, ro_X = (_readonly(a) for a in (segs, edges, no_uv, no_X))
    if "solvers" in parts:
        T, cost = np.empty((MAX_SOLUTIONS, 4, 4)), np.empty(MAX_SOLUTIONS)
        p3l_solve(C, segs, edges, no_uv, no_X, T, cost)
        n, d = np.empty((3, 3)), np.empty(3)
        planes(C, segs, n, d)
        valid = np.empty((1, MAX_SOLUTIONS), dtype=np.bool_)
        p3l_many(C, segs[None].copy(), edges[None].copy(), T[None].copy(), valid, False)
        p3l_many(C, segs[None].copy(), edges[None].copy(), T[None].copy(), valid, True)
        M = np.empty((1, MAX_SOLUTIONS, 3, 3))
        rotations_many(n[None].copy(), np.ones((1, 3)), np.eye(3)[None].copy(), M, valid)
        clicks_ok(ro_segs, ro_edges, ro_uv, ro_X, 1e7, 1e6)
    if "refinement" not in parts:
        return
    distance_cost(C, _readonly(np.eye(3)), _readonly(np.zeros(3)), ro_edges, ro_segs, ro_X, ro_uv)
    T0 = np.eye(4)
    T0[2, 3] = 0.0
    pose_ok(T0, 1e6)
    m, S, P = 6, 3, 0
    Cs = C[None].copy()
    Cs.setflags(write=False)  # as core.pose.residuals.view_matrices passes it
    refine_many(
        Cs,
        np.zeros(S, np.int64),
        np.zeros(P, np.int64),
        T0[None].copy(),
        _readonly(edges[None].copy()),
        ro_segs,
        ro_X,
        ro_uv,
        np.ones(m),
        False,
        3.0,
        False,
        np.eye(4),
        np.zeros((6, 6)),
        100,
        np.ones(1),
        np.empty((1, 4, 4)),
        np.empty((1, m)),
        np.empty((1, 2 * S + P)),
        np.empty((1, 6, 6)),
        np.empty((1, 6)),
        np.empty(1, np.int64),
        np.empty(1, np.int64),
        np.empty(1, np.bool_),
        np.empty(1),
        np.empty((1, 2 * (S + P) + 2)),
    )
