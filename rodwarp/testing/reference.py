"""Independent NumPy reference for the exact local fields (no Warp): test oracle and speed peer.

Everything here is written from the formulas alone and shares no code with
:mod:`rodwarp.kernels` (or :mod:`rodwarp.analysis`), so that agreement between the two is
evidence, not tautology:

* **Clipping.**  Segment ``p0 -> p1`` meets the ball ``|y - x| <= R`` where
  ``|p0 + t (p1 - p0) - x| = R``; with ``d = p1 - p0`` and ``f = p0 - x`` the roots are
  ``t = (-f.d +- sqrt(disc)) / d.d`` with ``disc = (d.d) R^2 - |f x d|^2`` (the cross-product
  form, free of the cancellation in ``(f.d)^2 - (d.d)(f.f - R^2)``).  The roots are clamped
  to ``[0, 1]``; a segment whose clamped interval is empty drops out, otherwise its clipped
  part is the one segment ``p0 + t0 d -> p0 + t1 d``.
* **Gauss integral.**  The signed Gauss linking integral of two straight segments is
  ``1/(4 pi)`` times the solid angle that the parallelogram with vertices ``a = p1-p3``,
  ``b = p2-p3``, ``c = p2-p4``, ``d = p1-p4`` subtends at the origin (``docs/fields.md``, "The average crossing number").
  All four vertices lie in one plane at signed height ``h = a.(e1 x e2)``; a triangle's
  solid angle is ``2 atan2(u.(v x w), |u||v||w| + (u.v)|w| + (u.w)|v| + (v.w)|u|)``
  (Van Oosterom-Strackee).  Two decompositions, neither the Warp kernel's (which splits along
  ``a - c``):

  - ``form="foot"`` (default, the oracle): a fan of four triangles ``(f, v_i, v_i+1)`` from
    the foot ``f`` of the perpendicular from the origin to the plane, ``|f| = delta = |h| /
    |e1 x e2|``.  Substituting ``v = f + w`` (``w`` in the plane) the height cancels exactly:
    ``tan(Omega_i / 2) = sign(h) n^.(w_i x w_i+1) / (|v_i||v_i+1| + delta (|v_i| + |v_i+1|)
    + delta^2 + w_i.w_i+1)``.  Numerator and denominator are then O(1), so nearly touching
    pairs keep full accuracy wherever the origin's projection lies.  A two-triangle split
    instead divides two O(delta) quantities computed from O(1) vectors, and loses about
    ``1e-16 / delta`` (relative to segment length) when the projection lies within a few
    ``delta`` of the split diagonal: 4e-10 at gap 1e-7, 4e-12 at gap 1e-5.
  - ``form="product"``: the same fan, but the four half-angles (each in (-pi/2, pi/2), since
    every denominator is positive) are added as the argument of the product of the four
    complex numbers ``den + i num``, one ``arctan2`` instead of four: rodwarp's Warp kernel
    evaluates exactly this, so it is the same-formula speed peer of ``rodwarp.analysis.compute_fields``.
  - ``form="diagonal"``: the two triangles ``(d, c, b)`` and ``(b, a, d)`` split along
    ``b - d``, the same cost and the same conditioning as the Warp kernel (speed peer).

  ``|h| <= 1e-14 |e1||e2| max(|a|, |e1|, |e2|)`` (coplanar, parallel, touching, collinear or
  degenerate) gives exactly 0, as in the kernel.  Near a parallelogram *edge* (one segment's
  end within ``delta`` of the other segment) G itself changes by O(1) over a distance
  ``delta``, so rounding of the input differences costs about ``1e-16 / delta`` in any form.
* **Fields** (per ball centre ``x``, radius ``R``): ``n`` distinct rods with a clipped part of
  positive length; ``length`` the clipped centreline length; ``phi`` the clipped rod volume
  over the ball volume; ``S`` the largest eigenvalue of the length-weighted nematic tensor
  ``Q = sum L (3 u u^T - I) / 2 / sum L``; ``contacts`` the contact points within ``R``;
  ``e`` the sum over pairs of clipped segments on *different* rods of ``|G|``.

Candidate segments per centre come from a ``scipy.spatial.cKDTree`` on segment midpoints
(radius ``R`` + the largest half segment length), then the clip and the pair sums are
vectorised over blocks of centres.
"""

from __future__ import annotations

import math

import numpy as np

from rodwarp.errors import RodwarpError

COPLANAR_TOL = 1.0e-14
_PAIR_BUDGET = 1 << 20  # clipped-segment pairs evaluated at once (about 0.5 KB each)


# ----------------------------------------------------------------------------------------------
# Gauss linking integral of segment pairs
# ----------------------------------------------------------------------------------------------

def _solid_angle(u, v, w, lu, lv, lw):
    """Signed solid angle of triangles (u, v, w) at the origin; components first, shape (3, n)."""
    num = (u[0] * (v[1] * w[2] - v[2] * w[1]) + u[1] * (v[2] * w[0] - v[0] * w[2])
           + u[2] * (v[0] * w[1] - v[1] * w[0]))
    uv = u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    uw = u[0] * w[0] + u[1] * w[1] + u[2] * w[2]
    vw = v[0] * w[0] + v[1] * w[1] + v[2] * w[2]
    den = lu * lv * lw + uv * lw + uw * lv + vw * lu
    return 2.0 * np.arctan2(num, den)


def _norm(v):
    return np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _dot3(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _cross3(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def _gauss_cf(p1, p2, p3, p4, form: str = "foot"):
    """Signed G of segment pairs given as component-first arrays of shape (3, n).

    ``form="diagonal"``: the parallelogram split along b - d into two triangles.
    ``form="foot"``: a fan of four triangles from the foot p of the perpendicular from the
    origin to the parallelogram's plane, with the height factored out of numerator and
    denominator (see :func:`gauss_linking_numpy`).
    """
    e1 = p2 - p1
    e2 = p4 - p3
    a = p1 - p3
    b = p2 - p3
    c = p2 - p4
    d = p1 - p4
    n = _cross3(e1, e2)
    h = _dot3(a, n)
    la, lb, lc, ld = _norm(a), _norm(b), _norm(c), _norm(d)
    l1, l2 = _norm(e1), _norm(e2)
    scale = l1 * l2 * np.maximum(la, np.maximum(l1, l2))
    degenerate = np.abs(h) <= COPLANAR_TOL * scale
    with np.errstate(invalid="ignore", divide="ignore"):
        if form == "diagonal":
            g = (_solid_angle(d, c, b, ld, lc, lb) + _solid_angle(b, a, d, lb, la, ld)) / (4.0 * math.pi)
        elif form in ("foot", "product"):
            nn = _dot3(n, n)
            ln = np.sqrt(nn)
            k = h / nn
            foot = (k * n[0], k * n[1], k * n[2])           # foot of the perpendicular, |foot| = delta
            delta = np.abs(h) / ln
            sgn = np.sign(h) / ln                             # sign(h) * (1 / |n|) so that n * sgn = +-n_hat
            verts = ((a, la), (d, ld), (c, lc), (b, lb))      # traversal a -> d -> c -> b
            w = [(v[0] - foot[0], v[1] - foot[1], v[2] - foot[2]) for v, _ in verts]
            g = 0.0
            zr, zi = 1.0, 0.0
            for i in range(4):
                j = (i + 1) % 4
                li, lj = verts[i][1], verts[j][1]
                num = sgn * _dot3(n, _cross3(w[i], w[j]))
                den = li * lj + delta * (li + lj) + delta * delta + _dot3(w[i], w[j])
                if form == "foot":
                    g = g + 2.0 * np.arctan2(num, den)
                else:  # den > 0: the four half-angles sum to 2 pi G in (-pi, pi), the argument of the product
                    zr, zi = zr * den - zi * num, zr * num + zi * den
            g = g / (4.0 * math.pi) if form == "foot" else np.arctan2(zi, zr) / (2.0 * math.pi)
        else:
            raise RodwarpError(f"unknown form '{form}'; use 'foot', 'product' or 'diagonal'")
    return np.where(degenerate, 0.0, g)


def _as_points(name, p):
    arr = np.asarray(p, dtype=np.float64)
    if arr.ndim == 1 and arr.size == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise RodwarpError(f"{name} must be an array of 3D points of shape (n, 3), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise RodwarpError(f"{name} holds NaN or infinite coordinates; remove or repair those points")
    return arr


def gauss_linking_numpy(p1, p2, p3, p4, form: str = "foot") -> np.ndarray:
    """Signed Gauss linking integral of segment pairs, exact (closed form), vectorised NumPy.

    Parameters
    ----------
    p1, p2, p3, p4 : array_like, shape (n, 3) or (3,)
        Segment ``i`` joins ``p1[i]`` to ``p2[i]``; its partner joins ``p3[i]`` to ``p4[i]``.
        Any length unit (G is dimensionless).
    form : {"foot", "diagonal"}
        ``"foot"``: fan of four triangles from the foot of the perpendicular, accurate for
        nearly touching pairs (default); ``"diagonal"``: two triangles, the Warp kernel's cost
        and conditioning (about 1.5x faster).  See the module docstring.

    Returns
    -------
    ndarray of float64, shape (n,)
        G in (-1/2, 1/2), sign convention ``(e1 x e2).(r1 - r2)`` (e.g. ``-1/6`` for
        ``(-1,0,0)->(1,0,0)`` against ``(0,-1,1)->(0,1,1)``); the pair's average crossing
        number is ``abs(G)``.  Coplanar, parallel, touching and degenerate pairs give 0.
    """
    arrs = [_as_points(f"p{k + 1}", p) for k, p in enumerate((p1, p2, p3, p4))]
    n = arrs[0].shape[0]
    if any(a.shape[0] != n for a in arrs):
        raise RodwarpError("p1, p2, p3 and p4 must hold the same number of points")
    return _gauss_cf(*(np.ascontiguousarray(a.T) for a in arrs), form=form)


# ----------------------------------------------------------------------------------------------
# clipping
# ----------------------------------------------------------------------------------------------

def clip_segments_to_ball(p0, p1, x, radius):
    """Exact clip of segments to balls, vectorised over rows.

    Parameters
    ----------
    p0, p1 : ndarray, shape (n, 3)
        Segment endpoints (length unit, e.g. m).
    x : ndarray, shape (n, 3) or (3,)
        Ball centre of each row.
    radius : float
        Ball radius R (same unit).

    Returns
    -------
    q0, q1 : ndarray, shape (n, 3)
        Clipped endpoints (``q0 == p0`` exactly where the segment starts inside).
    length : ndarray, shape (n,)
        Clipped length; 0 for segments that miss the ball or only touch it.
    """
    p0 = np.asarray(p0, np.float64)
    p1 = np.asarray(p1, np.float64)
    d = p1 - p0
    f = p0 - np.asarray(x, np.float64)
    dd = np.einsum("ij,ij->i", d, d)
    fd = np.einsum("ij,ij->i", f, d)
    fxd = np.cross(f, d)
    disc = dd * radius * radius - np.einsum("ij,ij->i", fxd, fxd)
    ok = (dd > 0) & (disc > 0)
    safe = np.where(ok, dd, 1.0)
    tc = -fd / safe
    half = np.sqrt(np.where(ok, disc, 0.0)) / safe
    t0 = np.clip(tc - half, 0.0, 1.0)
    t1 = np.clip(tc + half, 0.0, 1.0)
    ok &= t1 > t0
    t0 = np.where(ok, t0, 0.0)
    t1 = np.where(ok, t1, 0.0)
    # exact endpoints where not clipped (so shared vertices of a subdivided rod stay shared)
    q0 = np.where((t0 == 0.0)[:, None], p0, p0 + t0[:, None] * d)
    q1 = np.where((t1 == 1.0)[:, None], p1, p0 + t1[:, None] * d)
    length = (t1 - t0) * np.sqrt(dd)
    return q0, q1, length


# ----------------------------------------------------------------------------------------------
# fields
# ----------------------------------------------------------------------------------------------

def _pairs_within_groups(starts, ends, budget):
    """Yield (i, j) index arrays of all pairs i < j inside each group [start, end), in batches."""
    m = int(ends[-1]) if len(ends) else 0
    if m == 0:
        return
    grp_end = np.repeat(ends, ends - starts)           # end of each element's group
    cnt = grp_end - np.arange(m) - 1                   # partners after element j in its group
    csum = np.cumsum(cnt)
    lo = 0
    while lo < m:
        base = csum[lo - 1] if lo > 0 else 0
        hi = int(np.searchsorted(csum, base + budget, side="right"))
        hi = max(hi, lo + 1)
        c = cnt[lo:hi]
        tot = int(c.sum())
        if tot:
            i = np.repeat(np.arange(lo, hi), c)
            first = np.cumsum(c) - c
            j = i + 1 + (np.arange(tot) - np.repeat(first, c))
            yield i, j
        lo = hi


def fields_numpy(p0, p1, seg_rod, diameter, centers, radius, contact_points=None, chunk: int = 1024,
                 form: str = "foot") -> dict:
    """Exact local fields in balls of radius ``R`` around ``centers`` (NumPy + scipy, no Warp).

    Parameters
    ----------
    p0, p1 : array_like, shape (m, 3)
        Segment endpoints, length unit L (e.g. m).
    seg_rod : array_like of int, shape (m,)
        Rod id of each segment; pairs of segments on one rod do not count in ``e``.
    diameter : float or array_like, shape (m,)
        Rod diameter (unit L), one value or one per segment.
    centers : array_like, shape (k, 3) or (3,)
        Ball centres (unit L).
    radius : float
        Ball radius R (unit L), > 0.
    contact_points : array_like, shape (c, 3), optional
        Contact locations (unit L); ``contacts`` counts those within distance ``<= R``.
    chunk : int
        Centres processed per block (memory bound; the pair sums are further split into
        batches of at most 2^20 segment pairs).
    form : {"foot", "diagonal"}
        Closed form of the pair integrals (see :func:`gauss_linking_numpy`); ``"diagonal"``
        matches the Warp kernel's cost, for speed comparisons.

    Returns
    -------
    dict of ndarray, each of shape (k,)
        ``n`` (int64): distinct rods with a clipped part of positive length;
        ``length`` (unit L): total clipped centreline length;
        ``phi`` (dimensionless): ``sum (pi d^2 / 4) L_clip / (4/3 pi R^3)``;
        ``S`` (dimensionless): largest eigenvalue of ``Q = sum L (3 u u^T - I)/2 / sum L``,
        0 where there is no length;
        ``contacts`` (int64): contact points within ``R`` (0 when none given);
        ``e`` (dimensionless): sum of ``|G|`` over pairs of clipped segments on different rods.
    """
    from scipy.spatial import cKDTree

    p0 = _as_points("p0", p0)
    p1 = _as_points("p1", p1)
    m = p0.shape[0]
    if p1.shape[0] != m:
        raise RodwarpError(f"p0 and p1 must hold the same number of points ({m} vs {p1.shape[0]})")
    seg_rod = np.asarray(seg_rod).reshape(-1)
    if seg_rod.shape[0] != m:
        raise RodwarpError(f"seg_rod needs one rod id per segment ({m}), got {seg_rod.shape[0]}")
    # compact rod ids 0..nr-1 (any integer labels allowed)
    _, seg_rod = np.unique(seg_rod, return_inverse=True)
    seg_rod = seg_rod.reshape(-1).astype(np.int64)
    n_rods = int(seg_rod.max()) + 1 if m else 1
    diam = np.asarray(diameter, np.float64)
    if diam.ndim == 0:
        area = np.full(m, math.pi * float(diam) ** 2 / 4.0)
    else:
        diam = diam.reshape(-1)
        if diam.shape[0] != m:
            raise RodwarpError(f"diameter must be one value or one per segment ({m}), got {diam.shape[0]}")
        area = math.pi * diam ** 2 / 4.0
    x = _as_points("centers", centers)
    k = x.shape[0]
    R = float(radius)
    if not (R > 0 and math.isfinite(R)):
        raise RodwarpError(f"radius must be a positive finite length, got {radius}")
    chunk = max(int(chunk), 1)
    if form not in ("foot", "product", "diagonal"):
        raise RodwarpError(f"unknown form '{form}'; use 'foot', 'product' or 'diagonal'")

    out = {
        "n": np.zeros(k, np.int64),
        "length": np.zeros(k),
        "phi": np.zeros(k),
        "S": np.zeros(k),
        "contacts": np.zeros(k, np.int64),
        "e": np.zeros(k),
    }
    if contact_points is not None:
        cp = np.asarray(contact_points, np.float64).reshape(-1, 3)
        if len(cp):
            out["contacts"] = cKDTree(cp).query_ball_point(x, R, return_length=True).astype(np.int64)
    if m == 0 or k == 0:
        return out

    mid = 0.5 * (p0 + p1)
    half = 0.5 * np.sqrt(np.einsum("ij,ij->i", p1 - p0, p1 - p0))
    reach = (R + float(half.max())) * (1.0 + 1e-12)
    tree = cKDTree(mid)
    ball_volume = 4.0 / 3.0 * math.pi * R ** 3

    for lo in range(0, k, chunk):
        xs = x[lo:lo + chunk]
        nc = xs.shape[0]
        cand = tree.query_ball_point(xs, reach)
        sizes = np.fromiter((len(c) for c in cand), np.int64, nc)
        if sizes.sum() == 0:
            continue
        seg = np.fromiter((s for c in cand for s in sorted(c)), np.int64, int(sizes.sum()))
        cen = np.repeat(np.arange(nc), sizes)
        q0, q1, L = clip_segments_to_ball(p0[seg], p1[seg], xs[cen], R)
        keep = L > 0
        seg, cen, q0, q1, L = seg[keep], cen[keep], q0[keep], q1[keep], L[keep]
        if len(seg) == 0:
            continue
        rod = seg_rod[seg]
        sl = slice(lo, lo + nc)
        # length, phi
        Lsum = np.bincount(cen, weights=L, minlength=nc)
        out["length"][sl] = Lsum
        out["phi"][sl] = np.bincount(cen, weights=area[seg] * L, minlength=nc) / ball_volume
        # distinct rods
        key = np.unique(cen * n_rods + rod)
        out["n"][sl] = np.bincount(key // n_rods, minlength=nc)
        # nematic order: sum L u u^T = sum (q1 - q0)(q1 - q0)^T / L
        v = q1 - q0
        M = np.zeros((nc, 3, 3))
        for a in range(3):
            for b in range(a, 3):
                M[:, a, b] = np.bincount(cen, weights=v[:, a] * v[:, b] / L, minlength=nc)
                M[:, b, a] = M[:, a, b]
        has = Lsum > 0
        Q = (3.0 * M[has] / Lsum[has, None, None] - np.eye(3)) / 2.0
        S = np.zeros(nc)
        S[has] = np.linalg.eigvalsh(Q)[:, -1]
        out["S"][sl] = S
        # entanglement: pairs of clipped segments in one ball (groups are contiguous in cen)
        counts = np.bincount(cen, minlength=nc)
        ends = np.cumsum(counts)
        starts = ends - counts
        cf0 = np.ascontiguousarray(q0.T)
        cf1 = np.ascontiguousarray(q1.T)
        e = np.zeros(nc)
        for i, j in _pairs_within_groups(starts, ends, _PAIR_BUDGET):
            diff = rod[i] != rod[j]
            i, j = i[diff], j[diff]
            if len(i) == 0:
                continue
            g = _gauss_cf(cf0[:, i], cf1[:, i], cf0[:, j], cf1[:, j], form=form)
            e += np.bincount(cen[i], weights=np.abs(g), minlength=nc)
        out["e"][sl] = e
    return out
