"""P3L: the pose of a known object from three clicked image edges (source paper §IV.1 and appendix).

Finds R, T with ``N_i·(R V_i) = 0`` and ``N_i·(T + R M_i − c) = 0`` (paper eqs. 1, 5) for three
model edges L_i (point M_i, direction V_i, object frame) and the interpretation planes (N_i, world)
of their clicked images, written on the global camera model C (after Dhome et al. 1989, as the
paper does, without splitting C into intrinsics and extrinsics).

Rotation. Two intermediate frames reduce R to two angles:

* R_c1 (world): x along the back-projected ray of l1's first clicked pixel (the intersection of
  the pixel's two planes of eq. 4), y = N_1, z = x × y;
* R_m1 (object): x along V_1, z along V_1 × V_2, y = z × x;

so that ``R_world_obj = R_world_c1 · R_y(β) R_x(α) · R_obj_m1ᵀ`` satisfies the first edge's
constraint for every (α, β). The two other edges give ``s1 cos β + s2 sin β = s3`` and
``s4 cos β + s5 sin β = s6`` with s_k linear in (cos α, sin α, 1) (eq. A3); eliminating β with
cos²β + sin²β = 1 and substituting t = tan(α/2) gives a polynomial of degree 8 in t, whose roots
are the eigenvalues of its companion matrix. When its leading coefficient is smaller than its
constant one (α = π is a root, or nearly) the reversed polynomial in u = cot(α/2) = 1/t is solved
instead, so α = π is found like any other root. cos β, sin β follow from Cramer's rule, evaluated
homogeneously in the half angle so that no root is near a pole. Eigenvalues whose imaginary part
is below 1e-4 rad (in α) are kept, so a near-double real root that the eigen-solver splits into a
complex pair is not lost; every root is then checked against the constraints (|G_2| + |G_3|), one
whose error exceeds 1e-12 gets a Newton step on (α, β), and only those below 3e-6 are returned.

Structured triples (a box's, say: every triple automatic matching solves) change the polynomial:
when edges 2 and 3 are orthogonal to edge 1 and parallel or orthogonal to each other it is even in
t (the solutions come in pairs α, −α); when also parallel, its constant and leading coefficients
vanish (t = 0 and α = π are roots, where the two β-equations are dependent: β then comes from the
unit circle). Both are deflated: the known roots are taken out, and the batched solver
(``p3l_rotations``) solves an even polynomial in s = t², with companion matrices of half the size,
all rows of one kind and size in one eigen-solve; the dependent roots are handled with array code.
``p3l`` (one triple) solves the same polynomial in t, so its solutions stay what they were to the bit.

Translation. With R known, ``N_i·T = −d_i − N_i·(R M_i)`` (three planes). When the three model
edges meet in one vertex, their interpretation planes share that vertex's line of sight and the
depth along it is unobservable from lines: clicked points matched to model points (any vertex
other than the common one) are then added to the system; without them a ValueError says what to
click.

Each candidate keeps the clicked model edges in front of the camera; candidates are ranked by the
RMS pixel distance of the clicked pixels to the projected finite model segments
(``residuals.distance_cost``: the paper's "test of distances between 2D points").
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgeev

from ..camera import Camera
from ..checks import MAX_M, MAX_PX
from .residuals import Clicks, as_clicks, distance_cost, interpretation_planes

__all__ = ["p3l", "p3l_batch", "p3l_rotations", "ConcurrentEdgesError"]

# Eigenvalues whose imaginary part, mapped to α, is below this are taken as real roots (radians).
_IMAG_TOL_RAD = 1e-4
# A candidate rotation is kept when Σ_i |N_i · R V_i| is below this (sines).
_CONSTRAINT_TOL = 3e-6
# Two unit directions (or plane normals) are parallel when the sine of their angle is below this.
_PARALLEL_TOL = 1e-9
_MAX_PX2, _MAX_M2 = MAX_PX**2, MAX_M**2
# The β-equations are dependent at a root when |s1 s5 − s2 s4| is below this.
_DEPENDENT_TOL = 1e-7
# Companion matrices of degree d: ones on the sub-diagonal.
_SUBDIAGS = {d: np.eye(d, k=-1) for d in range(1, 9)}


class ConcurrentEdgesError(ValueError):
    """The three edges' interpretation planes share a line of sight: the depth along it is unknown."""


# ---------------------------------------------------------------------------------------------
# Component algebra. A vector is a 3-tuple of components, a matrix a 3-tuple of rows; a component
# is a float (one triple, the fast path of ``p3l``: plain Python arithmetic is ~30× cheaper than a
# NumPy call on tiny arrays) or an array (many triples at once, ``p3l_batch``). The solver's
# maths below is written once on components and runs unchanged on both.


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _unit(a):
    k = _dot(a, a) ** -0.5
    return (a[0] * k, a[1] * k, a[2] * k)


def _quad_det(a, d, b, c):
    """a d − b c for four quadratics (ascending coefficient triples): a quartic (5 coefficients)."""
    return [
        a[0] * d[0] - b[0] * c[0],
        a[0] * d[1] + a[1] * d[0] - b[0] * c[1] - b[1] * c[0],
        a[0] * d[2] + a[1] * d[1] + a[2] * d[0] - b[0] * c[2] - b[1] * c[1] - b[2] * c[0],
        a[1] * d[2] + a[2] * d[1] - b[1] * c[2] - b[2] * c[1],
        a[2] * d[2] - b[2] * c[2],
    ]


def _eliminant(nc, ns, nd):
    """nc² + ns² − nd² for three quartics: the degree-8 polynomial (9 coefficients, ascending).

    The product Σ_{i+j=k} (nc_i nc_j + ns_i ns_j − nd_i nd_j), unrolled (summed in the order of
    the convolution loop i < j it replaces)."""
    c0, c1, c2, c3, c4 = nc
    s0, s1, s2, s3, s4 = ns
    d0, d1, d2, d3, d4 = nd
    return [
        c0 * c0 + s0 * s0 - d0 * d0,
        2.0 * (c0 * c1 + s0 * s1 - d0 * d1),
        2.0 * (c0 * c2 + s0 * s2 - d0 * d2) + (c1 * c1 + s1 * s1 - d1 * d1),
        2.0 * (c0 * c3 + s0 * s3 - d0 * d3) + 2.0 * (c1 * c2 + s1 * s2 - d1 * d2),
        2.0 * (c0 * c4 + s0 * s4 - d0 * d4) + 2.0 * (c1 * c3 + s1 * s3 - d1 * d3) + (c2 * c2 + s2 * s2 - d2 * d2),
        2.0 * (c1 * c4 + s1 * s4 - d1 * d4) + 2.0 * (c2 * c3 + s2 * s3 - d2 * d3),
        2.0 * (c2 * c4 + s2 * s4 - d2 * d4) + (c3 * c3 + s3 * s3 - d3 * d3),
        2.0 * (c3 * c4 + s3 * s4 - d3 * d4),
        c4 * c4 + s4 * s4 - d4 * d4,
    ]


class _Setup:
    """Everything of one triple (or a batch of triples) that does not depend on α.

    cols_c1 : the columns x, y, z of R_world_c1 (vectors, world).
    cols_m1 : the columns of R_obj_m1 (vectors, object frame).
    coef : the 9 coefficients (ascending in t = tan(α/2)) of the degree-8 eliminant.
    minors : nc, ns, nd times (1 + t²)², quartics (5 coefficients each).
    E : per edge 2, 3 the half-angle quadratics of (s_c, s_s, s_rhs).
    """

    __slots__ = ("cols_c1", "cols_m1", "coef", "minors", "E")

    def __init__(self, n, ray, V):
        # R_c1: x along the ray of l1's first clicked pixel, y = N_1, z = x × y.
        y = n[0]
        k = _dot(ray, y)
        x = _unit((ray[0] - k * y[0], ray[1] - k * y[1], ray[2] - k * y[2]))
        z = _cross(x, y)
        self.cols_c1 = (x, y, z)
        # R_m1: x along L1, z along L1 × L2, y = z × x.
        v1 = V[0]
        z_m = _unit(_cross(v1, V[1]))
        y_m = _cross(z_m, v1)
        self.cols_m1 = (v1, y_m, z_m)
        E = []
        for i in (1, 2):
            ax, ay, az = _dot(x, n[i]), _dot(y, n[i]), _dot(z, n[i])  # N_i in R_c1
            bx, by, bz = _dot(v1, V[i]), _dot(y_m, V[i]), _dot(z_m, V[i])  # V_i in R_m1
            # N·R_y(β) R_x(α) V = s_c cos β + s_s sin β − s_rhs, each s = p cos α + q sin α + r;
            # as half-angle quadratics s (1 + t²) = (p + r) + 2q t + (r − p) t².
            pqr = ((az * bz, az * by, ax * bx), (ax * bz, ax * by, -az * bx), (-ay * by, ay * bz, 0.0 * ax))
            E.append([(p + r, 2.0 * q, r - p) for p, q, r in pqr])
        (c2, s2, h2), (c3, s3, h3) = E
        # Cramer on the two β-equations (eq. A3): cos β = nc/nd, sin β = ns/nd.
        nc = _quad_det(h2, s3, s2, h3)
        ns = _quad_det(c2, h3, h2, c3)
        nd = _quad_det(c2, s3, s2, c3)
        # cos²β + sin²β = 1 (eq. A4): nc² + ns² − nd², degree 8 in t.
        self.coef = _eliminant(nc, ns, nd)
        self.minors = (nc, ns, nd)
        self.E = E

    def rows(self, b: np.ndarray) -> "_Setup":
        """The setup of the triples b (M,) of a batch (components (B, 1) or (B,) → (M,)),
        without the polynomial: what ``_rotation``, ``_constraint_error`` and ``_polish`` read."""
        sub = object.__new__(_Setup)
        sub.cols_c1, sub.cols_m1, sub.E = _take((self.cols_c1, self.cols_m1, self.E), b)
        return sub


def _take(x, b):
    """Rows b of every array component, (B, 1) or (B,), in a nested tuple/list structure: (M,)."""
    if isinstance(x, (tuple, list)):
        return type(x)(_take(y, b) for y in x)
    return x[b, 0] if x.ndim == 2 else x[b]


def _angles_at_root(st: _Setup, hc, hs):
    """(cos α, sin α, cos β, sin β, nd) at a root given by its half angle (hc, hs) ∝ (cos α/2,
    sin α/2); nd is the normalised Cramer denominator (the β-equations are dependent where ~0)."""
    hc2, hs2, hcs = hc * hc, hs * hs, hc * hs
    w = hc2 + hs2
    # t^k (1 + t²)^-2 = hs^k hc^(4-k) / w²: homogeneous, no pole at α = π.
    p0, p1, p2, p3, p4 = hc2 * hc2, hc2 * hcs, hc2 * hs2, hcs * hs2, hs2 * hs2
    (c0, c1, c2, c3, c4), (s0, s1, s2, s3, s4), (d0, d1, d2, d3, d4) = st.minors
    nc = c0 * p0 + c1 * p1 + c2 * p2 + c3 * p3 + c4 * p4
    ns = s0 * p0 + s1 * p1 + s2 * p2 + s3 * p3 + s4 * p4
    nd = (d0 * p0 + d1 * p1 + d2 * p2 + d3 * p3 + d4 * p4) / (w * w)
    # (cos β, sin β) = (nc, ns) sign(nd) / |(nc, ns)|, written without a branch.
    cb, sb = nc * nd, ns * nd
    k = 1.0 / ((cb * cb + sb * sb) ** 0.5 + 1e-300)
    return (hc2 - hs2) / w, 2.0 * hcs / w, cb * k, sb * k, nd


def _polish(st: _Setup, ca, sa, cb, sb):
    """One Newton step on the two β-equations G_2 = G_3 = 0 in (α, β), kept where it lowers
    |G_2| + |G_3|. The companion eigenvalues are accurate to ~1e-10 rad for simple roots but only
    to ~1e-6 near a double root; this brings the constraint residuals back to ~1e-15."""
    G, dGa, dGb = [], [], []
    for c, s, h in st.E:  # half-angle quadratics of s_c, s_s, s_rhs for edges 2, 3
        # s (1 + t²) = e0 + e1 t + e2 t²  ⇒  s = (e0 (1 + cos α) + e1 sin α + e2 (1 − cos α)) / 2
        vc = 0.5 * (c[0] * (1 + ca) + c[1] * sa + c[2] * (1 - ca))
        vs = 0.5 * (s[0] * (1 + ca) + s[1] * sa + s[2] * (1 - ca))
        vh = 0.5 * (h[0] * (1 + ca) + h[1] * sa + h[2] * (1 - ca))
        dc = 0.5 * ((c[2] - c[0]) * sa + c[1] * ca)
        ds = 0.5 * ((s[2] - s[0]) * sa + s[1] * ca)
        dh = 0.5 * ((h[2] - h[0]) * sa + h[1] * ca)
        G.append(vc * cb + vs * sb - vh)
        dGa.append(dc * cb + ds * sb - dh)
        dGb.append(vs * cb - vc * sb)
    det = dGa[0] * dGb[1] - dGa[1] * dGb[0]
    det = det + (det == 0) * 1e-300
    da = (G[0] * dGb[1] - G[1] * dGb[0]) / det
    db = (dGa[0] * G[1] - dGa[1] * G[0]) / det
    # Rotate (cos, sin) by −da, −db (second-order, renormalised: the steps are tiny).
    def rotate(c, s, d):
        cd, sd = 1.0 - 0.5 * d * d, d - d * d * d / 6.0
        c2, s2 = c * cd + s * sd, s * cd - c * sd
        k = (c2 * c2 + s2 * s2) ** -0.5
        return c2 * k, s2 * k

    ca2, sa2 = rotate(ca, sa, da)
    cb2, sb2 = rotate(cb, sb, db)
    # A polish moves a root by a tiny step: a large one means no root nearby (keep the old angles).
    keep = (_constraint_error(st, ca2, sa2, cb2, sb2) < abs(G[0]) + abs(G[1])) & (abs(da) < 0.1) & (abs(db) < 0.1)  # a bool or a boolean array: blend without a branch
    return (
        ca2 * keep + ca * (1 - keep),
        sa2 * keep + sa * (1 - keep),
        cb2 * keep + cb * (1 - keep),
        sb2 * keep + sb * (1 - keep),
    )


def _rotation(st: _Setup, ca, sa, cb, sb):
    """R_world_obj = R_world_c1 · R_y(β) R_x(α) · R_obj_m1ᵀ (rows)."""
    # G = R_y(β) R_x(α) R_obj_m1ᵀ: row j of R_y R_x is (cb, sb sa, sb ca), (0, ca, −sa),
    # (−sb, cb sa, cb ca); R_obj_m1ᵀ has rows m0, m1, m2 (the columns of R_obj_m1).
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = st.cols_m1
    sbsa, sbca, cbsa, cbca = sb * sa, sb * ca, cb * sa, cb * ca
    g00, g01, g02 = cb * m00 + sbsa * m10 + sbca * m20, cb * m01 + sbsa * m11 + sbca * m21, cb * m02 + sbsa * m12 + sbca * m22
    g10, g11, g12 = ca * m10 - sa * m20, ca * m11 - sa * m21, ca * m12 - sa * m22
    g20, g21, g22 = -sb * m00 + cbsa * m10 + cbca * m20, -sb * m01 + cbsa * m11 + cbca * m21, -sb * m02 + cbsa * m12 + cbca * m22
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = st.cols_c1  # R = [x y z] G
    return (
        (x0 * g00 + y0 * g10 + z0 * g20, x0 * g01 + y0 * g11 + z0 * g21, x0 * g02 + y0 * g12 + z0 * g22),
        (x1 * g00 + y1 * g10 + z1 * g20, x1 * g01 + y1 * g11 + z1 * g21, x1 * g02 + y1 * g12 + z1 * g22),
        (x2 * g00 + y2 * g10 + z2 * g20, x2 * g01 + y2 * g11 + z2 * g21, x2 * g02 + y2 * g12 + z2 * g22),
    )


def _constraint_error(st: _Setup, ca, sa, cb, sb):
    """Σ |N_i · R V_i| over the three edges at (α, β): |G_2| + |G_3| (edge 1's constraint holds by
    construction of the frames), from the half-angle forms s (1 + t²) = e0 + e1 t + e2 t², i.e.
    s = (e0 (1 + cos α) + e1 sin α + e2 (1 − cos α)) / 2."""
    p, m = 1 + ca, 1 - ca
    ((c0, c1, c2), (s0, s1, s2), (h0, h1, h2)), ((C0, C1, C2), (S0, S1, S2), (H0, H1, H2)) = st.E
    return abs(0.5 * (c0 * p + c1 * sa + c2 * m) * cb + 0.5 * (s0 * p + s1 * sa + s2 * m) * sb - 0.5 * (h0 * p + h1 * sa + h2 * m)) + abs(
        0.5 * (C0 * p + C1 * sa + C2 * m) * cb + 0.5 * (S0 * p + S1 * sa + S2 * m) * sb - 0.5 * (H0 * p + H1 * sa + H2 * m)
    )


def _beta_dependent(E, ca, sa):
    """Both (cos β, sin β) at roots where the two β-equations are dependent (nd ≈ 0), vectorised.

    Intersects the better conditioned equation, s_c cos β + s_s sin β = s_rhs, with the unit circle
    and keeps the intersections that also satisfy the other. E : the setup's half-angle quadratics
    (components (M,) arrays or floats); ca, sa : arrays (M,), cos α and sin α at the roots.
    Returns ``((cb1, sb1, ok1), (cb2, sb2, ok2))``, arrays (M,): the intersections β = φ ± δ and
    whether each is a solution (the second never where δ = 0, a tangent: it is the first).
    """
    # s (1 + t²) = e0 + e1 t + e2 t² and 1/(1 + t²) = (1 + cos α)/2, t = sin α/(1 + cos α):
    # s = e0 (1 + cos α)/2 + e1 sin α/2 + e2 (1 − cos α)/2.
    p, m = 1 + ca, 1 - ca
    (a0, a1, a2), (b0, b1, b2) = [[(e[0] * p + e[1] * sa + e[2] * m) / 2.0 for e in edge] for edge in E]
    na, nb = np.hypot(a0, a1), np.hypot(b0, b1)
    first = na >= nb  # the better conditioned equation (the first on a tie)
    e0, e1, e2, nk = np.where(first, a0, b0), np.where(first, a1, b1), np.where(first, a2, b2), np.where(first, na, nb)
    o0, o1, o2 = np.where(first, b0, a0), np.where(first, b1, a1), np.where(first, b2, a2)
    with np.errstate(all="ignore"):
        possible = (nk >= 1e-12) & (np.abs(e2) <= nk * (1.0 + 1e-9))
        phi = np.arctan2(e1, e0)
        delta = np.arccos(np.clip(e2 / nk, -1.0, 1.0))
    out = []
    for beta in (phi + delta, phi - delta):
        cb, sb = np.cos(beta), np.sin(beta)
        out.append((cb, sb, possible & (np.abs(o0 * cb + o1 * sb - o2) < 1e-6)))
    out[1] = (out[1][0], out[1][1], out[1][2] & (delta >= 1e-12))
    return out


def _roots(coef: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Real roots of degree-8 polynomials (B, 9) as half angles (hc, hs) ∝ (cos α/2, sin α/2).

    Companion-matrix eigenvalues, in one batched eigen-solve per kind and size of matrix:

    * coefficients below 1e-14 of a row's largest are zero;
    * when every odd coefficient vanishes, the polynomial is even (edges 2 and 3 orthogonal to
      edge 1 and parallel or orthogonal to each other: any three edges of a box) and is solved in
      s = t², a companion matrix of half the size, t = ±√s; unless its roots s span more than
      1e8 (|t| more than 1e4, α within ~1° of 0 or π), where the squared range costs accuracy:
      that row is solved in t as below;
    * when the constant and leading coefficients both vanish, t = 0 (α = 0) and u = 1/t = 0
      (α = π) are roots: they are deflated (one slot each) and the polynomial between the first
      and last non-zero coefficients is solved (by the companion matrix of ``np.roots``);
    * otherwise, when its leading coefficient is the smaller end, the reversed polynomial in
      u = cot(α/2) is solved instead, so α = π is found like any other root.

    Returns hc, hs (B, 8), unnormalised (hc² + hs² > 0), and the mask (B, 8) of real roots:
    eigenvalues whose imaginary part, mapped to α, is below 1e-4 rad.
    """
    B = len(coef)
    a = np.abs(coef)
    zero = a <= 1e-14 * a.max(axis=1, keepdims=True)
    nz = ~zero
    live = nz.any(axis=1)
    trim = zero[:, 0] & zero[:, 8] & live
    lo = np.where(trim, nz.argmax(axis=1), 0)
    hi = np.where(trim, 8 - nz[:, ::-1].argmax(axis=1), 8)
    rows = np.arange(B)
    rev = a[rows, hi] < a[rows, lo]
    hc, hs, real = np.ones((B, 8)), np.zeros((B, 8)), np.zeros((B, 8), dtype=bool)
    hc[trim, 1], hs[trim, 1] = 0.0, 1.0  # slot 0: t = 0; slot 1: α = π
    real[trim, :2] = True
    first = 2 * trim  # the first slot of the eigenvalues' roots

    def put(g, lam, reverse):
        """Store the roots lam (G, m) of the rows g (G,), in t (or in u where reverse)."""
        re, im = lam.real, lam.imag
        cols = first[g, None] + np.arange(lam.shape[1])
        hc[g[:, None], cols] = np.where(reverse, re, 1.0)
        hs[g[:, None], cols] = np.where(reverse, 1.0, re)
        real[g[:, None], cols] = 2.0 * np.abs(im) < _IMAG_TOL_RAD * (1.0 + re * re + im * im)

    t_rows = live & (hi > lo)
    even = t_rows & zero[:, 1::2].all(axis=1)
    for d in np.unique((hi - lo)[even] // 2).tolist():
        g = np.flatnonzero(even & ((hi - lo) == 2 * d))
        c = coef[g[:, None], lo[g, None] + 2 * np.arange(d + 1)]  # (G, d + 1), ascending in s
        r = rev[g, None]
        lam = _companion_eigvals(np.where(r, c[:, ::-1], c))
        mag = np.abs(lam)
        ok = mag.min(axis=1) >= 1e-8 * mag.max(axis=1)
        z = np.sqrt(lam[ok].astype(complex))
        put(g[ok], np.concatenate([z, -z], axis=1), r[ok])
        t_rows[g[ok]] = False
    for d, trimmed in set(zip((hi - lo)[t_rows].tolist(), trim[t_rows].tolist())):
        g = np.flatnonzero(t_rows & ((hi - lo) == d) & (trim == trimmed))
        c = coef[g[:, None], lo[g, None] + np.arange(d + 1)]  # (G, d + 1), ascending in t
        if trimmed:  # np.roots' companion matrix (first row), no reversal
            comp = np.broadcast_to(_SUBDIAGS[d], (len(g), d, d)).copy()
            comp[:, 0, :] = -c[:, d - 1 :: -1] / c[:, d:]
            put(g, np.linalg.eigvals(comp), np.zeros((len(g), 1), dtype=bool))
        else:
            r = rev[g, None]
            put(g, _companion_eigvals(np.where(r, c[:, ::-1], c)), r)
    return hc, hs, real


def _companion_eigvals(c: np.ndarray) -> np.ndarray:
    """Eigenvalues (G, d) of the companion matrices (last column −c_k / c_d, ones on the
    sub-diagonal) of polynomials c (G, d + 1), ascending: their roots."""
    d = c.shape[1] - 1
    comp = np.broadcast_to(_SUBDIAGS[d], (len(c), d, d)).copy()
    comp[:, :, d - 1] = -c[:, :d] / c[:, d:]
    return np.linalg.eigvals(comp)


def _roots_one(coef: list) -> list[tuple[float, float]]:
    """``_roots`` for one polynomial (9 floats), in plain Python around one LAPACK call (NumPy's
    eigvals wrapper costs more than the 8 × 8 eigenproblem): the real roots as half angles.

    Without the solve in s = t² of even polynomials: it would save ~6 µs (dgeev took 10 µs on the
    8 × 8 matrix, 3.5 µs on a 4 × 4 one here) but move the roots by rounding, and ``p3l`` keeps its
    solutions as they were, to the bit."""
    a = [abs(x) for x in coef]
    tol = 1e-14 * max(a)
    if a[0] <= tol and a[8] <= tol:  # t = 0 and α = π are roots: deflate them, np.roots the rest
        nz = [k for k in range(9) if a[k] > tol]
        if not nz:
            return []
        out = [(1.0, 0.0), (0.0, 1.0)]
        if nz[-1] > nz[0]:
            lam = np.roots(coef[nz[0] : nz[-1] + 1][::-1])
            for re, im in zip(lam.real.tolist(), lam.imag.tolist()):
                if 2.0 * abs(im) < _IMAG_TOL_RAD * (1.0 + re * re + im * im):
                    out.append((1.0, re))
        return out
    reverse = a[8] < a[0]
    wr, wi = _companion_dgeev(coef[::-1] if reverse else coef)
    out = []
    for re, im in zip(wr, wi):
        if 2.0 * abs(im) < _IMAG_TOL_RAD * (1.0 + re * re + im * im):
            out.append((re, 1.0) if reverse else (1.0, re))
    return out


def _companion_dgeev(c: list) -> tuple[list, list]:
    """Real and imaginary parts of the roots of the polynomial c (d + 1 floats, ascending): the
    eigenvalues of its companion matrix by LAPACK's dgeev."""
    d = len(c) - 1
    comp = _SUBDIAGS[d].copy()
    comp[:, d - 1] = c[:d]
    comp[:, d - 1] *= -1.0 / c[d]
    wr, wi, _, _, info = dgeev(comp, compute_vl=0, compute_vr=0)
    if info != 0:  # LAPACK did not converge (never seen): fall back on NumPy's driver
        lam = np.linalg.eigvals(comp)
        wr, wi = lam.real, lam.imag
    return wr.tolist(), wi.tolist()


def _rotations_one(n, ray, V) -> list:
    """Every rotation (rows, floats) with N_i · R V_i = 0 for one triple (components are floats):
    the same maths as ``p3l_rotations`` in plain Python."""
    st = _Setup(n, ray, V)
    out = []
    for hc, hs in _roots_one(st.coef):
        ca, sa, cb, sb, nd = _angles_at_root(st, hc, hs)
        if abs(nd) >= _DEPENDENT_TOL:
            err = _constraint_error(st, ca, sa, cb, sb)
            if err > 1e-12:  # polish an inaccurate root (near-double, or a near-real complex pair)
                ca, sa, cb, sb = _polish(st, ca, sa, cb, sb)
                err = _constraint_error(st, ca, sa, cb, sb)
            if err < _CONSTRAINT_TOL:
                out.append(_rotation(st, ca, sa, cb, sb))
            continue
        for cb_j, sb_j, ok in _beta_dependent(st.E, np.array([ca]), np.array([sa])):
            cb, sb = float(cb_j[0]), float(sb_j[0])
            if ok[0] and _constraint_error(st, ca, sa, cb, sb) < _CONSTRAINT_TOL:
                out.append(_rotation(st, ca, sa, cb, sb))
    return out


def p3l_rotations(n_world: np.ndarray, ray_world: np.ndarray, V_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every rotation R_world_obj with ``N_i · R V_i = 0`` for three edges, vectorised over triples.

    Parameters
    ----------
    n_world : array, shape (B, 3, 3)
        Unit normals (world) of the three interpretation planes, one triple per row.
    ray_world : array, shape (B, 3)
        A direction (world) in the first plane: the paper's ray of l1's first clicked pixel.
    V_obj : array, shape (B, 3, 3)
        Unit directions (object frame) of the matched model edges; V_1 must not be parallel to V_2
        or V_3 (the caller checks; ``p3l`` reorders the edges when needed).

    Returns
    -------
    R : array, shape (B, K, 3, 3), K = 8, or 16 when some root has two β (the two β-equations
        dependent there, a non-generic case)
        Candidate rotations R_world_obj.
    valid : array, shape (B, K), bool
        Which slots hold a solution (real root, constraints met to 3e-6).
    """
    with np.errstate(all="ignore"):  # slots of complex roots compute garbage, masked by ``valid``
        return _rotations_batch(n_world, ray_world, V_obj)


def _rotation_array(st: _Setup, ca, sa, cb, sb) -> np.ndarray:
    """``_rotation`` on arrays of angles (...): the rotations as one array (..., 3, 3)."""
    rows = _rotation(st, ca, sa, cb, sb)
    out = np.empty(np.shape(ca) + (3, 3))
    for i, row in enumerate(rows):
        for j, x in enumerate(row):
            out[..., i, j] = x
    return out


def _rotations_batch(n_world: np.ndarray, ray_world: np.ndarray, V_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``p3l_rotations`` itself: the component algebra on (B, 1) and (B, 8) arrays, and on the
    (M,) slots of the special cases (an inaccurate root to polish, dependent β-equations)."""
    # Components of shape (B, 1) broadcast against the roots' (B, 8).
    n = [[n_world[:, i, j, None] for j in range(3)] for i in range(3)]
    V = [[V_obj[:, i, j, None] for j in range(3)] for i in range(3)]
    ray = [ray_world[:, j, None] for j in range(3)]
    st = _Setup(n, ray, V)
    hc, hs, real = _roots(np.concatenate(st.coef, axis=1))
    ca, sa, cb, sb, nd = _angles_at_root(st, hc, hs)
    dependent = real & (np.abs(nd) < _DEPENDENT_TOL)
    err = _constraint_error(st, ca, sa, cb, sb)
    b, k = np.nonzero(real & ~dependent & (err > 1e-12))
    if len(b):  # polish the inaccurate roots (near-double, or a near-real complex pair)
        sub = st.rows(b)
        polished = _polish(sub, ca[b, k], sa[b, k], cb[b, k], sb[b, k])
        ca[b, k], sa[b, k], cb[b, k], sb[b, k] = polished
        err[b, k] = _constraint_error(sub, *polished)
    valid = real & ~dependent & (err < _CONSTRAINT_TOL)
    second = None
    b, k = np.nonzero(dependent)
    if len(b):  # each β on the unit circle: the first in the root's slot, a second in slot k + 8
        sub = st.rows(b)
        ca_k, sa_k = ca[b, k], sa[b, k]
        (cb1, sb1, ok1), (cb2, sb2, ok2) = _beta_dependent(sub.E, ca_k, sa_k)
        ok1 &= _constraint_error(sub, ca_k, sa_k, cb1, sb1) < _CONSTRAINT_TOL
        ok2 &= _constraint_error(sub, ca_k, sa_k, cb2, sb2) < _CONSTRAINT_TOL
        cb[b, k], sb[b, k] = np.where(ok1, cb1, cb2), np.where(ok1, sb1, sb2)
        valid[b, k] = ok1 | ok2
        both = ok1 & ok2
        if both.any():
            second = (b[both], k[both], _rotation_array(sub.rows(np.flatnonzero(both)), ca_k[both], sa_k[both], cb2[both], sb2[both]))
    R = _rotation_array(st, ca, sa, cb, sb)  # (B, 8, 3, 3)
    if second is not None:
        b2, k2, R2 = second
        R = np.concatenate([R, np.broadcast_to(np.eye(3), R.shape)], axis=1)
        valid = np.concatenate([valid, np.zeros_like(valid)], axis=1)
        R[b2, k2 + 8], valid[b2, k2 + 8] = R2, True
    return R, valid


def _det3(M):
    return _dot(M[0], _cross(M[1], M[2]))


def _first_edge_order(V) -> tuple[int, int, int]:
    """An order of the three edges (unit directions, float components) whose first is parallel to
    neither other (paper appendix: L2, L3 must not be parallel to L1); ValueError if all are."""
    c01, c02, c12 = _cross(V[0], V[1]), _cross(V[0], V[2]), _cross(V[1], V[2])
    tol2 = _PARALLEL_TOL**2
    p01, p02, p12 = _dot(c01, c01) > tol2, _dot(c02, c02) > tol2, _dot(c12, c12) > tol2
    if p01 and p02:
        return (0, 1, 2)
    if p01 and p12:
        return (1, 2, 0)
    if p02 and p12:
        return (2, 0, 1)
    raise ValueError(
        "the three model edges are parallel: the rotation about their common direction is not "
        "observable from them; click an edge with another direction"
    )


def _common_point(A, V):
    """The point where three model lines A_i + s V_i meet, or None (floats; V_0 ∦ V_1)."""
    # L0 and L1 meet iff (A1 − A0)·(V0 × V1) = 0; then X = A0 + s V0 with s from the 2D solve.
    w = [A[1][j] - A[0][j] for j in range(3)]
    c = _cross(V[0], V[1])
    cc = _dot(c, c)
    scale = max(1.0, max(map(abs, A[0] + A[1] + A[2])))
    if _dot(w, c) ** 2 > (1e-9 * scale) ** 2 * cc:
        return None
    s = _dot(_cross(w, V[1]), c) / cc
    X = [A[0][j] + s * V[0][j] for j in range(3)]
    D = [X[j] - A[2][j] for j in range(3)]
    if _dot(D, D) - _dot(D, V[2]) ** 2 > (1e-9 * scale) ** 2:
        return None
    return X


def _translations_from_points(camera: Camera, R: np.ndarray, n, d, A, clicks: Clicks, common) -> np.ndarray:
    """Translations (K, 3) when the three lines do not fix the depth: the three planes plus the
    pixel planes of the clicked points (eq. 4, normalised to metres), by least squares."""
    message = (
        "the three clicked edges meet in one vertex (or their interpretation planes share one line "
        "of sight), so lines alone do not fix the object's distance along that ray"
    )
    if clicks.n_points == 0:
        raise ConcurrentEdgesError(
            message + ": click a vertex of the object other than the common one as a point "
            "(points_uv/points_obj), or use an edge that does not pass through that vertex"
        )
    n, d, A = np.array(n), np.array(d), np.array(A)
    m_u, a_u, m_v, a_v = camera.pixel_planes(clicks.points_uv)
    rows = np.concatenate([m_u, m_v])
    norm = np.linalg.norm(rows, axis=1)
    rows, offs = rows / norm[:, None], np.concatenate([a_u, a_v]) / norm
    P = np.concatenate([clicks.points_obj, clicks.points_obj])
    A_all = np.concatenate([n, rows])
    sv = np.linalg.svd(A_all, compute_uv=False)
    scale = max(1.0, float(np.abs(A).max()))
    off_vertex = common is None or bool(np.any(np.linalg.norm(clicks.points_obj - np.array(common), axis=1) > 1e-9 * scale))
    if not off_vertex or sv[-1] <= 1e-9 * sv[0]:
        raise ConcurrentEdgesError(
            message + "; the clicked point(s) do not fix it either (the common vertex lies on that "
            "ray): click another vertex, or use an edge that does not pass through that vertex"
        )
    rhs = np.concatenate(
        [-d[None] - np.einsum("ki,bij,kj->bk", n, R, A), -offs[None] - np.einsum("ki,bij,kj->bk", rows, R, P)], axis=1
    )
    return np.linalg.lstsq(A_all, rhs.T, rcond=None)[0].T


def _check_segments(n) -> None:
    for i, j in ((0, 1), (0, 2), (1, 2)):
        c = _cross(n[i], n[j])
        if _dot(c, c) < _PARALLEL_TOL**2:
            raise ValueError(
                f"clicked segments {i} and {j} lie on one image line (same interpretation plane): "
                "they cannot tell two edges apart; click edges that are distinct in the image"
            )


def p3l(
    camera: Camera,
    segs_uv: np.ndarray,
    edges_obj: np.ndarray,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
) -> list[np.ndarray]:
    """Every pose of a known object that puts three model edges on three clicked image lines.

    Parameters
    ----------
    camera : Camera
        The calibrated global model C (any world frame, any scale and sign of C).
    segs_uv : array, shape (3, 2, 2), pixels
        Two clicked points on each of three image edges.
    edges_obj : array, shape (3, 2, 3), metres, object frame
        The matched model edges (two endpoints each).
    points_uv : array, shape (P, 2), pixels, optional
    points_obj : array, shape (P, 3), metres, object frame, optional
        Clicked points matched to model points (vertices): they enter the translation only when
        the three edges meet in one vertex, and the ranking always.

    Returns
    -------
    list of array, shape (4, 4)
        Every real solution ``T_world_obj`` (at most 8 generically) with each clicked model edge
        in front of the camera (at least one endpoint at positive depth) and each clicked model
        point in front, best first by the RMS pixel distance of the clicked pixels to the
        projected finite model segments and points (``segment_distances``). Possibly empty.

    Raises
    ------
    ValueError
        Wrong shapes; all three model edges parallel; two clicked segments on one image line;
        three edges meeting in one vertex without a clicked point that fixes the depth
        (``ConcurrentEdgesError``, a ValueError).
    """
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    segs_a = np.asarray(segs_uv, dtype=float)
    edges_a = np.asarray(edges_obj, dtype=float)
    if points_uv is None and points_obj is None and segs_a.shape == (3, 2, 2) and edges_a.shape == (3, 2, 3):
        # The common case, validated in plain Python: every number finite (else their sum is not)
        # and no two coinciding points; as_clicks explains any problem it finds.
        # Sums of squares: NaN or inf when any number is, and under the bound only when every one is
        # (core.checks: no product of the solver overflows); clicks ≥ 0.01 px and edges ≥ 1 µm long
        # pass as_clicks's test of coinciding points for any coordinates within the bounds.
        segs, edges = segs_a.tolist(), edges_a.tolist()
        sq_px, sq_m, ok = 0.0, 0.0, True
        for (u1, v1), (u2, v2) in segs:
            sq_px += u1 * u1 + v1 * v1 + u2 * u2 + v2 * v2
            du, dv = u1 - u2, v1 - v2
            ok = ok and du * du + dv * dv > 1e-4
        for (x1, y1, z1), (x2, y2, z2) in edges:
            sq_m += x1 * x1 + y1 * y1 + z1 * z1 + x2 * x2 + y2 * y2 + z2 * z2
            dx, dy, dz = x1 - x2, y1 - y2, z1 - z2
            ok = ok and dx * dx + dy * dy + dz * dz > 1e-12
        clicks = None if ok and sq_px <= _MAX_PX2 and sq_m <= _MAX_M2 else as_clicks(segs_a, edges_a)
        pts_obj, pts_uv = [], []
    else:
        clicks = as_clicks(segs_a, edges_a, points_uv, points_obj)
        if clicks.n_segments != 3:
            raise ValueError(f"p3l needs exactly 3 clicked segments and model edges, got {clicks.n_segments}")
        segs, edges = clicks.segs_uv.tolist(), clicks.edges_obj.tolist()
        pts_obj, pts_uv = clicks.points_obj.tolist(), clicks.points_uv.tolist()
    Cl = camera.C.tolist()
    (c00, c01, c02, c03), (c10, c11, c12, c13), (c20, c21, c22, c23) = Cl
    n, d = [], []
    for (u1, v1), (u2, v2) in segs:  # interpretation planes Cᵀ l, l = (u1, v1, 1) × (u2, v2, 1)
        l0, l1, l2 = v1 - v2, u2 - u1, u1 * v2 - u2 * v1
        p0, p1, p2 = l0 * c00 + l1 * c10 + l2 * c20, l0 * c01 + l1 * c11 + l2 * c21, l0 * c02 + l1 * c12 + l2 * c22
        k = (p0 * p0 + p1 * p1 + p2 * p2) ** -0.5
        n.append((p0 * k, p1 * k, p2 * k))
        d.append((l0 * c03 + l1 * c13 + l2 * c23) * k)
    _check_segments(n)
    A = [e[0] for e in edges]
    V = [_unit((b[0] - a[0], b[1] - a[1], b[2] - a[2])) for a, b in edges]
    i0, i1, i2 = _first_edge_order(V)
    # The paper's x axis of R_c1: the ray of l1's first clicked pixel, m_u × m_v (eq. 4).
    u, v = segs[i0][0]
    ray = _cross((c00 - u * c20, c01 - u * c21, c02 - u * c22), (c10 - v * c20, c11 - v * c21, c12 - v * c22))
    Rs = _rotations_one([n[i0], n[i1], n[i2]], ray, [V[i0], V[i1], V[i2]])
    if not Rs:
        return []
    Rs = _distinct(Rs)
    common = _common_point([A[i0], A[i1], A[i2]], [V[i0], V[i1], V[i2]])
    det = _det3(n)
    if common is None and abs(det) > 1e-9:
        # N_i·T = −d_i − N_i·(R A_i)  (eq. 5), by Cramer's rule: T = adj(N) rhs / det(N).
        (j00, j01, j02), (j10, j11, j12), (j20, j21, j22) = [
            [x / det for x in row] for row in zip(_cross(n[1], n[2]), _cross(n[2], n[0]), _cross(n[0], n[1]))
        ]
        (n00, n01, n02), (n10, n11, n12), (n20, n21, n22) = n
        d0, d1, d2 = d
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = A
        t = []
        for (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) in Rs:
            h0 = -d0 - n00 * (r00 * a00 + r01 * a01 + r02 * a02) - n01 * (r10 * a00 + r11 * a01 + r12 * a02) - n02 * (r20 * a00 + r21 * a01 + r22 * a02)
            h1 = -d1 - n10 * (r00 * a10 + r01 * a11 + r02 * a12) - n11 * (r10 * a10 + r11 * a11 + r12 * a12) - n12 * (r20 * a10 + r21 * a11 + r22 * a12)
            h2 = -d2 - n20 * (r00 * a20 + r01 * a21 + r02 * a22) - n21 * (r10 * a20 + r11 * a21 + r12 * a22) - n22 * (r20 * a20 + r21 * a21 + r22 * a22)
            t.append((j00 * h0 + j01 * h1 + j02 * h2, j10 * h0 + j11 * h1 + j12 * h2, j20 * h0 + j21 * h1 + j22 * h2))
    else:
        clicks = clicks if clicks is not None else as_clicks(segs_a, edges_a)
        t = _translations_from_points(camera, np.array(Rs), n, d, A, clicks, common).tolist()
    scored = []
    for k, (Rk, tk) in enumerate(zip(Rs, t)):
        # A clicked edge behind the camera (both endpoints at depth ≤ 0) rejects the candidate:
        # distance_cost's own test (the same depths), done first as it is ~5× cheaper.
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = Rk
        a0, a1, a2 = c20 * r00 + c21 * r10 + c22 * r20, c20 * r01 + c21 * r11 + c22 * r21, c20 * r02 + c21 * r12 + c22 * r22
        a3 = c20 * tk[0] + c21 * tk[1] + c22 * tk[2] + c23
        for (x0, x1, x2), (y0, y1, y2) in edges:
            if a0 * x0 + a1 * x1 + a2 * x2 + a3 <= 0.0 and a0 * y0 + a1 * y1 + a2 * y2 + a3 <= 0.0:
                break
        else:
            cost = distance_cost(Cl, Rk, tk, edges, segs, pts_obj, pts_uv)
            if cost is not None:
                scored.append((cost, k))
    scored.sort()
    return [np.array([Rs[k][0] + (t[k][0],), Rs[k][1] + (t[k][1],), Rs[k][2] + (t[k][2],), (0.0, 0.0, 0.0, 1.0)]) for _, k in scored]


def _distinct(Rs: list, tol: float = 1e-6) -> list:
    """The rotations (rows) not equal to an earlier one within tol in every entry: a near-double
    root can give two eigenvalues for one solution."""
    out = []
    for R in Rs:
        (r0, r1, r2), (r3, r4, r5), (r6, r7, r8) = R
        # A weighted sum of the entries differs by at most 45 tol between equal rotations: a
        # cheap first test (solutions related by a symmetry of the model share entries up to sign).
        key = r0 + 2.0 * r1 + 3.0 * r2 + 4.0 * r3 + 5.0 * r4 + 6.0 * r5 + 7.0 * r6 + 8.0 * r7 + 9.0 * r8
        for F, key_F in out:
            if abs(key - key_F) <= 45.0 * tol + 1e-12 and all(abs(a - b) <= tol for a, b in zip(R[0] + R[1] + R[2], F[0] + F[1] + F[2])):
                break  # equal to F
        else:
            out.append((R, key))
    return [R for R, _ in out]


def p3l_batch(camera: Camera, segs_uv: np.ndarray, edges_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``p3l`` for many triples at once (e.g. every assignment of three clicked edges to model
    edges), vectorised: the same maths on arrays, without ranking.

    Parameters
    ----------
    camera : Camera
    segs_uv : array, shape (B, 3, 2, 2) or (3, 2, 2), pixels
        Three clicked segments per triple (the same three for every triple when (3, 2, 2)).
    edges_obj : array, shape (B, 3, 2, 3), metres, object frame
        Three model edges per triple.

    Returns
    -------
    T_world_obj : array, shape (B, K, 4, 4), K = 8 (16 in the rare case of ``p3l_rotations``)
    valid : array, shape (B, K), bool
        The slots holding a solution with every model edge in front of the camera (an endpoint at
        positive depth). Triples ``p3l`` would reject (all three edges parallel, two segments on
        one image line, three edges through one vertex, which needs a clicked point: use ``p3l``)
        have no valid slot. Rank the solutions with ``residuals.distance_cost`` as ``p3l`` does.
    """
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    edges = np.asarray(edges_obj, dtype=float)
    if edges.ndim != 4 or edges.shape[1:] != (3, 2, 3):
        raise ValueError(f"edges_obj must have shape (B, 3, 2, 3), got {edges.shape}")
    B = len(edges)
    segs = np.asarray(segs_uv, dtype=float)
    if segs.shape == (3, 2, 2):
        segs = np.broadcast_to(segs, (B, 3, 2, 2))
    if segs.shape != (B, 3, 2, 2):
        raise ValueError(f"segs_uv must have shape (3, 2, 2) or ({B}, 3, 2, 2), got {segs.shape}")
    for k in range(3):  # validation of each segment and edge (shapes, NaN, coinciding points)
        as_clicks(segs[:, k], edges[:, k])
    n, d = interpretation_planes(camera, segs.reshape(-1, 2, 2))
    n, d = n.reshape(B, 3, 3), d.reshape(B, 3)
    A = edges[:, :, 0]
    V = edges[:, :, 1] - A
    V /= np.linalg.norm(V, axis=-1, keepdims=True)
    ok = np.ones(B, dtype=bool)
    for i, j in ((0, 1), (0, 2), (1, 2)):  # two segments on one image line
        ok &= np.linalg.norm(np.cross(n[:, i], n[:, j]), axis=-1) > _PARALLEL_TOL
    # First edge parallel to neither other (p3l's reordering), per triple.
    par = {(i, j): np.linalg.norm(np.cross(V[:, i], V[:, j]), axis=-1) <= _PARALLEL_TOL for i, j in ((0, 1), (0, 2), (1, 2))}
    orders = ((0, 1, 2), (1, 2, 0), (2, 0, 1))
    usable = [~(par[(0, 1)] | par[(0, 2)]), ~(par[(0, 1)] | par[(1, 2)]), ~(par[(0, 2)] | par[(1, 2)])]
    which = np.where(usable[0], 0, np.where(usable[1], 1, 2))
    ok &= usable[0] | usable[1] | usable[2]
    perm = np.array(orders)[which]  # (B, 3)
    rows = np.arange(B)[:, None]
    n_o, V_o = n[rows, perm], V[rows, perm]
    first = segs[np.arange(B), perm[:, 0], 0]  # (B, 2): l1's first clicked pixel
    C = camera.C
    m_u = C[0, :3] - first[:, :1] * C[2, :3]
    m_v = C[1, :3] - first[:, 1:] * C[2, :3]
    # Keep degenerate triples harmless in the arithmetic; they are masked out below.
    V_o = np.where(ok[:, None, None], V_o, np.eye(3))
    R, valid = p3l_rotations(n_o, np.cross(m_u, m_v), V_o)
    R = np.where(valid[..., None, None], R, np.eye(3))
    valid &= ok[:, None]
    # Translation from the three planes (eq. 5); no depth when the three lines meet in one point.
    det = np.linalg.det(n)
    w = A[:, 1] - A[:, 0]
    c01 = np.cross(V[:, 0], V[:, 1])
    cc = np.sum(c01 * c01, axis=-1)
    scale = np.maximum(1.0, np.abs(A).max(axis=(1, 2)))
    meet01 = np.abs(np.sum(w * c01, axis=-1)) <= 1e-9 * scale * np.sqrt(cc)
    s = np.sum(np.cross(w, V[:, 1]) * c01, axis=-1) / np.where(cc > 0, cc, 1.0)
    D = A[:, 0] + s[:, None] * V[:, 0] - A[:, 2]
    on2 = np.sum(D * D, axis=-1) - np.sum(D * V[:, 2], axis=-1) ** 2 <= (1e-9 * scale) ** 2
    concurrent = (meet01 & on2 & (cc > _PARALLEL_TOL**2)) | (np.abs(det) <= 1e-9)
    valid &= ~concurrent[:, None]
    n_safe = np.where(concurrent[:, None, None], np.eye(3), n)
    rhs = -d[:, None] - ((n[:, None] @ R) * A[:, None]).sum(axis=-1)  # (B, K, 3): N_i·(R A_i)
    t = rhs @ np.swapaxes(np.linalg.inv(n_safe), -1, -2)
    # Depths of the six endpoints: C₂·(R X + t) + C₂₃ = X·(Rᵀ C₂) + C₂·t + C₂₃, (B, K, 6).
    depth = edges.reshape(B, 1, 6, 3) @ (C[2, :3] @ R)[..., None] + (t @ C[2, :3] + C[2, 3])[..., None, None]
    valid &= (depth.reshape(B, -1, 3, 2).max(axis=-1) > 0).all(axis=-1)
    T = np.zeros(R.shape[:2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T, valid
