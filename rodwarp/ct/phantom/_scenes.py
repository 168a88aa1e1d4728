"""Phantom scenes in voxel units with their true contacts: the test material of CT segmentation.

Straight rods (:func:`scene_isolated`, :func:`scene_crossing_pair`, :func:`scene_parallel_pair`,
:func:`scene_random_packing`: gaps exactly 0 or at least 2 voxels), bundles of touching
parallel rods (:func:`scene_bundles`) and curved ones (:func:`scene_arcs`, gently curved rods;
:func:`scene_wire_tangle`, a nest-like tangle of wires).  Points are ``(x, y, z)`` with the
centre of voxel ``(0, 0, 0)`` at the origin; every scene keeps its rods ``_MARGIN`` voxels
inside the volume faces and records its truth contacts (:func:`rodwarp.ct.phantom_truth`).
Render one with :func:`rodwarp.ct.render_phantom`.
"""

from __future__ import annotations

import math

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.ct.phantom._truth import DEFAULT_TOLERANCE_VOXELS, phantom_truth
from rodwarp.ct.phantom._phantom_render import _check_shape
from rodwarp.rodset import RodSet, segment_distance

__all__ = ["scene_isolated", "scene_crossing_pair", "scene_parallel_pair", "scene_random_packing",
           "scene_bundles", "scene_arcs", "scene_wire_tangle"]

#: Margin (voxels) between the rods' surfaces and the volume faces in the scenes.
_MARGIN = 2.0


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _random_direction(rng: np.random.Generator) -> np.ndarray:
    while True:
        v = rng.normal(size=3)
        n = np.linalg.norm(v)
        if n > 1e-8:
            return v / n


def _centre_range(direction, length, radius, shape_xyz, margin=_MARGIN):
    """Allowed centre box (lo, hi) so the capsule stays ``margin`` voxels inside the volume faces."""
    half = 0.5 * length * np.abs(direction) + radius + margin
    lo = -0.5 + half
    hi = np.asarray(shape_xyz, dtype=np.float64) - 0.5 - half
    return lo, hi


def _finish(rods: RodSet, tolerance=DEFAULT_TOLERANCE_VOXELS, **attrs) -> RodSet:
    rods.contacts = phantom_truth(rods, tolerance)
    rods.attrs.update(attrs)
    return rods


def scene_isolated(shape, radius: float = 3.0, length: float | None = None, seed: int = 0) -> RodSet:
    """One straight rod at a random orientation, fully inside the volume (2-voxel margin).

    ``length`` (axis length, voxels) defaults to 0.6 of the smallest volume side.
    """
    shape = _check_shape(shape)
    shape_xyz = shape[::-1]
    rng = np.random.default_rng(seed)
    L = 0.6 * min(shape) if length is None else float(length)
    for _ in range(1000):
        d = _random_direction(rng)
        lo, hi = _centre_range(d, L, radius, shape_xyz)
        if np.all(hi >= lo):
            c = rng.uniform(lo, hi)
            rods = RodSet.from_straight(c[None], d[None], L, radius, n_vertices=2, units="voxel")
            return _finish(rods, scene="isolated", seed=int(seed))
    raise _fail(f"a rod of length {L} and radius {radius} does not fit in a volume of shape {shape}; "
                f"shorten it or enlarge the volume")


def _pair_length(shape, radius, offset, length):
    rfit = (min(shape) - 1) / 2.0 - radius - _MARGIN
    if length is not None:
        return float(length)
    if rfit <= abs(offset) + radius:
        raise _fail(f"the volume of shape {shape} is too small for two rods of radius {radius}")
    return 2.0 * math.sqrt(rfit ** 2 - offset ** 2)


def _rotate_about_centre(centres, dirs, shape, seed):
    if seed is None:
        return centres, dirs
    rng = np.random.default_rng(seed)
    # random rotation matrix via QR of a Gaussian matrix
    m = rng.normal(size=(3, 3))
    Q, Rm = np.linalg.qr(m)
    Q = Q * np.sign(np.diag(Rm))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    mid = (np.asarray(shape[::-1], dtype=np.float64) - 1) / 2.0
    return (centres - mid) @ Q.T + mid, dirs @ Q.T


def _check_inside(rods: RodSet, shape) -> None:
    bb = rods.bounding_box()
    if np.any(bb[0] < -0.5) or np.any(bb[1] > np.asarray(shape[::-1]) - 0.5):
        raise _fail(f"the rods do not fit inside a volume of shape {tuple(shape)}; shorten them or enlarge the volume")


def scene_crossing_pair(shape, angle_deg: float = 90.0, radius: float = 3.0, gap: float = 0.0,
                        length: float | None = None, seed: int | None = None) -> RodSet:
    """Two straight rods crossing at ``angle_deg`` with a surface gap of ``gap`` voxels (0 = touching).

    Both rods pass over the volume centre in planes normal to z (rotated rigidly by a random
    rotation about the centre if ``seed`` is given); their axes are ``2 radius + gap`` apart along
    the common normal, at the middle of each rod. ``length`` defaults to the longest that fits
    in any orientation.
    """
    shape = _check_shape(shape)
    a = math.radians(float(angle_deg))
    if not (0 < a < math.pi):
        raise _fail(f"angle_deg must be between 0 and 180 (exclusive), got {angle_deg!r}")
    if gap < 0:
        raise _fail(f"gap must be >= 0 voxels, got {gap!r}")
    off = radius + 0.5 * gap
    L = _pair_length(shape, radius, off, length)
    mid = (np.asarray(shape[::-1], dtype=np.float64) - 1) / 2.0
    d0 = np.array([math.cos(-a / 2), math.sin(-a / 2), 0.0])
    d1 = np.array([math.cos(a / 2), math.sin(a / 2), 0.0])
    n = np.array([0.0, 0.0, 1.0])
    centres = np.stack([mid - off * n, mid + off * n])
    dirs = np.stack([d0, d1])
    centres, dirs = _rotate_about_centre(centres, dirs, shape, seed)
    rods = RodSet.from_straight(centres, dirs, L, radius, n_vertices=2, units="voxel")
    _check_inside(rods, shape)
    return _finish(rods, scene="crossing_pair", angle_deg=float(angle_deg), gap=float(gap),
                   seed=None if seed is None else int(seed))


def scene_parallel_pair(shape, radius: float = 3.0, gap: float = 0.0, length: float | None = None,
                        seed: int | None = None) -> RodSet:
    """Two parallel straight rods along x, side by side in y with a surface gap of ``gap`` voxels.

    Rotated rigidly about the volume centre by a random rotation if ``seed`` is given.
    """
    shape = _check_shape(shape)
    if gap < 0:
        raise _fail(f"gap must be >= 0 voxels, got {gap!r}")
    off = radius + 0.5 * gap
    L = _pair_length(shape, radius, off, length)
    mid = (np.asarray(shape[::-1], dtype=np.float64) - 1) / 2.0
    centres = np.stack([mid - [0, off, 0], mid + [0, off, 0]])
    dirs = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    centres, dirs = _rotate_about_centre(centres, dirs, shape, seed)
    rods = RodSet.from_straight(centres, dirs, L, radius, n_vertices=2, units="voxel")
    _check_inside(rods, shape)
    return _finish(rods, scene="parallel_pair", gap=float(gap), seed=None if seed is None else int(seed))


def _seg_dist(a, b, A, B):
    """(K, N) distances between K candidate segments a-b and N placed segments A-B."""
    return segment_distance(a[:, None], b[:, None], A[None], B[None])


def scene_random_packing(shape, n_rods: int = 100, radius=3.0, aspect: float = 30.0,
                         touching_fraction: float = 0.5, seed: int = 0, max_attempts: int = 20000,
                         fov_radius: float | None = None) -> RodSet:
    """Random straight rods, fully inside the volume, with about ``touching_fraction`` touching.

    Rods have axis length ``aspect * 2 radius`` and random orientations; every rod keeps a
    2-voxel margin to the volume faces. Pairs either touch exactly (surface gap 0: the new rod's
    axis is placed at distance 2r from a point on an existing rod, along the common normal) or
    are at least 2 voxels apart, so contact scoring is unambiguous. No rods overlap. Rods are
    single segments (2 vertices); ``rods.contacts`` holds the truth contacts (gap 0).

    Random sequential placement saturates: 200 rods of aspect 30 and radius 3 (length 180) in
    256^3 is close to the limit (about 5 s); raise ``max_attempts`` or lower the count if it fails.

    ``radius`` may be a pair ``(low, high)``: each rod then draws its own radius uniformly from
    that range (mixed radii; the length is ``aspect`` times the mean diameter for every rod).
    ``fov_radius`` (voxels) keeps every rod inside the cylinder of that radius about the slice
    centre (the field of view of a reconstruction, see ``render_phantom(fov=...)``).

    Raises
    ------
    RodwarpError
        If the rods cannot be placed (volume too crowded, or rods too long for it).
    """
    shape = _check_shape(shape)
    n_rods = int(n_rods)
    if n_rods < 1:
        raise _fail(f"n_rods must be >= 1, got {n_rods}")
    if not (0.0 <= touching_fraction <= 1.0):
        raise _fail(f"touching_fraction must be in [0, 1], got {touching_fraction!r}")
    if np.ndim(radius) == 0:
        r_lo = r_hi = float(radius)
    else:
        r_lo, r_hi = (float(v) for v in radius)
    if not (0 < r_lo <= r_hi):
        raise _fail(f"radius must be positive (or a range low <= high), got {radius!r}")
    L = float(aspect) * (r_lo + r_hi)
    if not L > 0:
        raise _fail(f"aspect must be positive, got aspect={aspect!r}")
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    A = np.zeros((0, 3))
    B = np.zeros((0, 3))
    RR = np.zeros(0)
    touching = np.zeros(0, dtype=bool)
    K = 64  # candidates per batch
    r = r_hi
    centre_xy = 0.5 * (shape_xyz[:2] - 1.0)

    def random_dirs(k):
        v = rng.normal(size=(k, 3))
        return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)

    def in_fov(a, b):
        if fov_radius is None:
            return np.ones(len(a), bool)
        lim = float(fov_radius) - r - _MARGIN  # the cylinder is convex: both ends inside suffice
        return (np.linalg.norm(a[:, :2] - centre_xy, axis=1) <= lim) & \
            (np.linalg.norm(b[:, :2] - centre_xy, axis=1) <= lim)

    def inside(a, b):
        lo = np.minimum(a, b) - r - _MARGIN
        hi = np.maximum(a, b) + r + _MARGIN
        return np.all(lo >= -0.5, axis=1) & np.all(hi <= shape_xyz - 0.5, axis=1) & in_fov(a, b)

    def try_free(rn):
        d = random_dirs(K)
        lo, hi = _centre_range(d.T, L, r, shape_xyz[:, None])
        lo, hi = lo.T, hi.T
        ok = np.all(hi >= lo, axis=1)
        c = lo + rng.random((K, 3)) * (hi - lo)
        a, b = c - 0.5 * L * d, c + 0.5 * L * d
        ok &= in_fov(a, b)
        if len(A):  # "clearly apart": surface gaps of at least 2 voxels
            ok &= np.all(_seg_dist(a, b, A, B) >= RR[None] + rn + 2.0, axis=1)
        k = np.flatnonzero(ok)
        return None if k.size == 0 else (a[k[0]], b[k[0]], None)

    def try_touch(rn):
        if len(A) == 0:
            return None
        j = rng.integers(len(A), size=K)
        u = B[j] - A[j]
        p = A[j] + rng.uniform(0.1, 0.9, size=(K, 1)) * u
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        d = random_dirs(K)
        nrm = np.cross(u, d)
        sn = np.linalg.norm(nrm, axis=1)
        ok = sn >= 0.3  # nearly parallel pairs would have an ill-defined contact point
        nrm = nrm / np.maximum(sn, 1e-12)[:, None] * np.where(rng.random(K) < 0.5, -1.0, 1.0)[:, None]
        q = p + (RR[j] + rn)[:, None] * nrm
        c = q + rng.uniform(-0.4 * L, 0.4 * L, size=(K, 1)) * d
        a, b = c - 0.5 * L * d, c + 0.5 * L * d
        ok &= inside(a, b)
        if not ok.any():
            return None
        k = np.flatnonzero(ok)
        dist = _seg_dist(a[k], b[k], A, B)
        own = dist[np.arange(k.size), j[k]].copy()
        dist[np.arange(k.size), j[k]] = np.inf
        good = np.all(dist >= RR[None] + rn + 2.0, axis=1) & (np.abs(own - (RR[j[k]] + rn)) <= 1e-9)
        g = np.flatnonzero(good)
        return None if g.size == 0 else (a[k[g[0]]], b[k[g[0]]], int(j[k[g[0]]]))

    batches = max(1, int(max_attempts) // K)
    for k in range(n_rods):
        want_touch = touching_fraction > 0 and len(A) > 0 and touching.sum() < touching_fraction * (k + 1)
        # a single radius draws nothing, so single-radius scenes stay as they were for a seed
        rn = r_lo if r_hi == r_lo else float(rng.uniform(r_lo, r_hi))
        placed = None
        for _ in range(batches):
            placed = try_touch(rn) if want_touch else try_free(rn)
            if placed is not None:
                break
        if placed is None:  # fall back to the other kind
            for _ in range(batches):
                placed = try_free(rn) if want_touch else try_touch(rn)
                if placed is not None:
                    break
        if placed is None:
            raise _fail(f"could only place {len(A)} of {n_rods} rods (length {L:g}, radius {r:g}) in a volume of "
                        f"shape {shape}; use fewer or shorter rods or a bigger volume")
        a, b, j = placed
        A = np.vstack([A, a])
        B = np.vstack([B, b])
        RR = np.append(RR, rn)
        touching = np.append(touching, j is not None)
        if j is not None:
            touching[j] = True
    dirs = B - A
    centres = 0.5 * (A + B)
    rods = RodSet.from_straight(centres, dirs, L, RR, n_vertices=2, units="voxel")
    # from_straight renormalises; put the exact end points back so touching gaps stay exact
    rods.points[0::2] = A
    rods.points[1::2] = B
    return _finish(rods, scene="random_packing", n_rods=n_rods,
                   radius=r_lo if r_lo == r_hi else [r_lo, r_hi], aspect=float(aspect),
                   touching_fraction=float(touching_fraction), seed=int(seed),
                   touching_rods=int(touching.sum()))


def _polyline_gaps(poly, radius, placed, placed_r):
    """Smallest surface gap between a polyline (n, 3) of ``radius`` and each placed polyline."""
    if not placed:
        return np.zeros(0)
    a, b = poly[:-1], poly[1:]
    out = np.empty(len(placed))
    for k, (q, rq) in enumerate(zip(placed, placed_r)):
        d = segment_distance(a[:, None], b[:, None], q[None, :-1], q[None, 1:])
        out[k] = float(d.min()) - radius - rq
    return out


def _place_polylines(n: int, candidate, radius: float, min_gap: float, max_attempts: int, failure) -> list:
    """Random sequential addition of ``n`` polylines of one radius (voxels).

    ``candidate()`` proposes a polyline, or None when its draw does not fit the volume; it is
    kept when its surface stays at least ``min_gap`` voxels from every polyline kept before.
    ``failure(k)`` is the message when a polyline finds no place in ``max_attempts`` draws
    after ``k`` were placed.
    """
    polys: list[np.ndarray] = []
    for k in range(n):
        for _ in range(max_attempts):
            pts = candidate()
            if pts is None:
                continue
            if polys and _polyline_gaps(pts, radius, polys, [radius] * len(polys)).min() < min_gap:
                continue
            polys.append(pts)
            break
        else:
            raise _fail(failure(k))
    return polys


def _polyline_inside(poly, radius, shape_xyz, margin=_MARGIN):
    return bool(np.all(poly - radius - margin >= -0.5) and np.all(poly + radius + margin <= shape_xyz - 0.5))


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    m = rng.normal(size=(3, 3))
    Q, Rm = np.linalg.qr(m)
    Q = Q * np.sign(np.diag(Rm))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def scene_bundles(shape, n_bundles: int = 8, sizes=(3, 5), radius: float = 3.0, length: float | None = None,
                  stagger: float = 0.1, seed: int = 0, max_attempts: int = 20000) -> RodSet:
    """Bundles of parallel straight rods touching side by side (gap 0), bundles apart.

    Each bundle holds ``k`` rods (``k`` drawn uniformly from ``sizes``, inclusive) on the
    closest-packed (triangular) lattice of spacing ``2 radius`` in its cross-section, so
    neighbours in a bundle touch exactly; the rods are shifted along the common axis by up to
    ``stagger`` times the length (ends not flush, as in a real bundle).  Bundles have random
    orientations and positions, stay 2 voxels (surface gap) from each other and inside the
    volume (2-voxel margin).  ``length`` defaults to 0.7 of the smallest volume side.
    ``rods.contacts`` holds the truth contacts (the touching neighbours in each bundle).
    """
    shape = _check_shape(shape)
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    r = float(radius)
    L = 0.7 * min(shape) if length is None else float(length)
    k_lo, k_hi = int(sizes[0]), int(sizes[1])
    if not (r > 0 and L > 0 and 1 <= k_lo <= k_hi <= 12):
        raise _fail(f"bundles need radius > 0, length > 0 and 1 <= sizes <= 12, got {radius!r}, {length!r}, {sizes!r}")
    # closest-packed lattice points ordered outward from the centre of the first triangle
    ij = np.array([(i, j) for i in range(-4, 5) for j in range(-4, 5)], float)
    lat = np.stack([ij[:, 0] + 0.5 * ij[:, 1], ij[:, 1] * math.sqrt(3) / 2], 1) * 2.0 * r
    c0 = np.array([r, r / math.sqrt(3)])
    order = np.lexsort((lat[:, 1], lat[:, 0], np.round(np.linalg.norm(lat - c0, axis=1), 6)))
    lat = lat[order] - c0
    A = np.zeros((0, 3))
    B = np.zeros((0, 3))
    bundle_of: list[int] = []
    for nb in range(int(n_bundles)):
        k = int(rng.integers(k_lo, k_hi + 1))
        placed = False
        for _ in range(max(1, int(max_attempts) // 50)):
            Q = _random_rotation(rng)
            u, e1, e2 = Q[:, 0], Q[:, 1], Q[:, 2]
            off = lat[:k, 0:1] * e1 + lat[:k, 1:2] * e2
            shift = rng.uniform(-stagger, stagger, k)[:, None] * L * u
            ext = np.abs(u) * 0.5 * L * (1 + 2 * stagger) + np.abs(off).max(0) + r + _MARGIN
            lo, hi = ext - 0.5, shape_xyz - 0.5 - ext
            if np.any(hi < lo):
                continue
            c = lo + rng.random(3) * (hi - lo)
            a = c + off + shift - 0.5 * L * u
            b = c + off + shift + 0.5 * L * u
            if not all(_polyline_inside(np.stack([p, q]), r, shape_xyz) for p, q in zip(a, b)):
                continue
            if len(A) and np.any(segment_distance(a[:, None], b[:, None], A[None], B[None]) < 2 * r + 2.0):
                continue
            A, B = np.vstack([A, a]), np.vstack([B, b])
            bundle_of += [nb] * k
            placed = True
            break
        if not placed:
            raise _fail(f"could only place {nb} of {n_bundles} bundles (length {L:g}, radius {r:g}) in a volume "
                        f"of shape {shape}; use fewer bundles, shorter rods or a bigger volume")
    rods = RodSet.from_straight(0.5 * (A + B), B - A, L, r, n_vertices=2, units="voxel")
    rods.points[0::2] = A
    rods.points[1::2] = B
    return _finish(rods, scene="bundles", n_bundles=int(n_bundles), sizes=[k_lo, k_hi], radius=r, length=L,
                   seed=int(seed), bundle=[int(b) for b in bundle_of])


def scene_arcs(shape, n_rods: int = 20, radius: float = 3.0, length: float | None = None,
               curvature_radius=(2.0, 5.0), seed: int = 0, max_attempts: int = 5000) -> RodSet:
    """Gently curved rods: circular arcs of axis length ``length`` (default 0.6 of the smallest side).

    Each arc's radius of curvature is drawn uniformly from ``curvature_radius`` (in units of
    the arc length); arcs lie in random planes, every pair keeps a surface gap of at least 2
    voxels, and every arc stays inside the volume (2-voxel margin).  Arcs are polylines with a
    vertex every voxel or so of arc length.
    """
    shape = _check_shape(shape)
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    r = float(radius)
    L = 0.6 * min(shape) if length is None else float(length)

    def arc():
        Rc = float(rng.uniform(*curvature_radius)) * L
        phi = L / Rc
        nv = max(8, int(math.ceil(L)) + 1)
        th = np.linspace(-0.5 * phi, 0.5 * phi, nv)
        loc = np.stack([Rc * np.sin(th), Rc * (1.0 - np.cos(th)), np.zeros(nv)], 1)
        loc -= loc.mean(0)
        Q = _random_rotation(rng)
        pts = loc @ Q.T
        ext = np.abs(pts).max(0) + r + _MARGIN
        lo, hi = ext - 0.5, shape_xyz - 0.5 - ext
        if np.any(hi < lo):
            return None
        return pts + lo + rng.random(3) * (hi - lo)

    polys = _place_polylines(int(n_rods), arc, r, 2.0, int(max_attempts),
                             lambda k: f"could only place {k} of {n_rods} arcs (length {L:g}, radius {r:g}) in a "
                                       f"volume of shape {shape}; use fewer or shorter arcs or a bigger volume")
    rods = RodSet.from_polylines(polys, r, units="voxel")
    return _finish(rods, scene="arcs", n_rods=int(n_rods), radius=r, length=L,
                   curvature_radius=[float(v) for v in curvature_radius], seed=int(seed))


def _wander(rng, shape_xyz, start, length, persistence, reach):
    """A smooth random curve: a persistent random walk of unit steps, steered back from the faces."""
    n = int(math.ceil(length))
    p = np.array(start, float)
    d = _random_direction(rng)
    pts = [p.copy()]
    mid = 0.5 * (shape_xyz - 1.0)
    half = 0.5 * (shape_xyz - 1.0) - reach
    for _ in range(n):
        kick = rng.normal(size=3) * math.sqrt(2.0 / persistence)
        kick -= (kick @ d) * d
        d = d + kick
        # steer away from the faces: a push that grows over the last ``reach`` voxels
        w = (p - mid) / np.maximum(half, 1.0)
        push = np.where(np.abs(w) > 0.7, -np.sign(w) * (np.abs(w) - 0.7) * 1.5, 0.0)
        d = d + push
        d /= np.linalg.norm(d)
        p = p + d
        pts.append(p.copy())
    return np.array(pts)


def scene_wire_tangle(shape, n_wires: int = 20, radius: float = 2.5, length=(150.0, 250.0),
                      persistence: float = 60.0, seed: int = 0, max_attempts: int = 400) -> RodSet:
    """A nest-like tangle of curved wires (smooth random curves) with truth.

    Each wire is a persistent random walk (persistence length ``persistence`` voxels, so a
    typical radius of curvature of that order) of length drawn from ``length``, kept inside
    the volume (2-voxel margin); wires never overlap (surface gap >= 0: they may touch, and
    cross above and below each other as in a nest).  Polylines with a vertex every 2 voxels.
    """
    shape = _check_shape(shape)
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    r = float(radius)
    reach = r + _MARGIN + 1.0
    def wire():
        Lw = float(rng.uniform(*length))
        start = reach + rng.random(3) * (shape_xyz - 1.0 - 2 * reach)
        pts = _wander(rng, shape_xyz, start, Lw, persistence, reach)[::2]
        return pts if _polyline_inside(pts, r, shape_xyz) else None

    # wires may touch (gap 0) but not overlap
    polys = _place_polylines(int(n_wires), wire, r, 0.0, int(max_attempts),
                             lambda k: f"could only place {k} of {n_wires} wires in a volume of shape {shape}; "
                                       f"use fewer or shorter wires or a bigger volume")
    rods = RodSet.from_polylines(polys, r, units="voxel")
    return _finish(rods, scene="wire_tangle", n_wires=int(n_wires), radius=r,
                   length=[float(v) for v in length], persistence=float(persistence), seed=int(seed))
