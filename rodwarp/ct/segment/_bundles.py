"""Bundles of touching parallel rods: how many rods a thick traced axis holds, and where.

Binarised, a bundle of parallel rods in contact is one thick rod: the notches between the
rods fill at the half level of a blurred, denoised image, and the skeleton (and a straight
fit) runs along the bundle's middle.  The cross-section of the *greyscale* image normal to
the axis (the median over positions along it, so that staggered ends do not matter and the
noise averages out) is, for rods that touch without overlapping, exactly a sum of k blurred
discs: :func:`fit_discs` finds k and the disc centres by least squares, each k with the
radius its intensity mass implies (``mass = k C pi r^2``: blur does not change it) as the
start of a common free radius, discs kept from overlapping; the best fit's radius then counts
the rods, ``k = mass / (C pi r^2)``, and that k's fit is taken.

:func:`looks_bundled` is the cheap screen the tracer applies first: a single rod's
cross-section is a disc whose distance-transform depth equals its area radius; a bundle's is
much shallower (a triangle of three rods: 0.58).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

__all__ = ["cross_section", "looks_bundled", "fit_discs"]

#: ratio of the distance-transform depth to the area radius below which a cross-section is
#: examined as a bundle (one rod: 0.94-1.02 on phantoms, 5th to 95th percentile; bundles of 3-5
#: rods: 0.71-0.85)
BUNDLE_DEPTH_RATIO = 0.88
#: smallest area radius (voxels) of a cross-section examined as a bundle (three rods of radius 2.3)
MIN_AREA_RADIUS = 4.0
#: largest number of rods fitted in one cross-section
MAX_RODS = 7


def cross_section(sampler, c, u, e1, e2, t0, t1, half_width, h=0.5, n_pos=16):
    """Median cross-section (m, m) on a grid of step ``h`` within ``half_width`` of the axis,
    over ``n_pos`` positions in the middle 70% of [t0, t1]; also the grid coordinates."""
    g1 = np.arange(-half_width, half_width + 1e-9, h)
    A, B = np.meshgrid(g1, g1, indexing="ij")
    lo, hi = t0 + 0.15 * (t1 - t0), t1 - 0.15 * (t1 - t0)
    ts = np.linspace(lo, hi, int(min(n_pos, max(3, hi - lo))))
    pts = c + ts[:, None, None] * u + A.ravel()[None, :, None] * e1 + B.ravel()[None, :, None] * e2
    v = sampler(pts)
    ok = np.isfinite(v)
    if ok.mean() < 0.8:
        return None, g1
    import warnings

    v = np.where(ok, v, np.nan)
    with warnings.catch_warnings():  # columns all outside the volume: NaN, then 0
        warnings.simplefilter("ignore", RuntimeWarning)
        img = np.nanmedian(v, axis=0).reshape(A.shape)
    return np.nan_to_num(img, nan=0.0), g1


def looks_bundled(img: np.ndarray, h: float) -> bool:
    """True when the half-level blob at the centre is much shallower than its area radius."""
    m = img > 0.5
    lab, n = ndimage.label(m)
    ci = img.shape[0] // 2
    k = lab[ci, ci]
    if n == 0 or k == 0:
        return False
    m = lab == k
    depth = float(ndimage.distance_transform_edt(m).max()) * h
    area_r = math.sqrt(float(m.sum()) * h * h / math.pi)
    # below an area radius of 4 voxels the depth is a few grid steps: too coarse to judge (and
    # a pair side by side, the commonest case there, is split by the tracer's moment test)
    return depth < BUNDLE_DEPTH_RATIO * area_r and area_r >= MIN_AREA_RADIUS


_PROFILES: dict = {}


def _profile(r: float, sigma: float):
    """Tabulated blurred-disc profile (unit contrast) of radius r: (rho grid, values)."""
    key = (round(r, 2), round(sigma, 2))
    if key not in _PROFILES:
        from rodwarp.ct.segment._profile import _blur_model

        # (from the key alone: a table must not depend on which caller made it first)
        rho = np.linspace(0.0, key[0] + 5.0 * key[1] + 1.0, 160)
        _PROFILES[key] = (rho, _blur_model(-np.inf, rho, key[0], key[1], n_r=24, n_th=32))
    return _PROFILES[key]


def _model(xy, centres, r, sigma, C):
    rho_t, val = _profile(r, sigma)
    out = np.zeros(len(xy))
    for c in centres:
        out += np.interp(np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]), rho_t, val, right=0.0)
    return C * out


def _disc_values(rho, r, sigma):
    """Blurred-disc profile (unit contrast) at distances ``rho``, its slope in rho and its
    derivative in the radius: linear between the tables at the radii 0.01 voxel either side,
    so that it is continuous in r."""
    lo = math.floor(r * 100.0) / 100.0
    w = (r - lo) * 100.0
    a, b = _profile(lo, sigma), _profile(lo + 0.01, sigma)
    fa = np.interp(rho, a[0], a[1], right=0.0)
    fb = np.interp(rho, b[0], b[1], right=0.0)
    sa = np.interp(rho, a[0], np.gradient(a[1], a[0]), right=0.0)
    sb = np.interp(rho, b[0], np.gradient(b[1], b[0]), right=0.0)
    return (1.0 - w) * fa + w * fb, (1.0 - w) * sa + w * sb, (fb - fa) * 100.0


def _fit_disc_model(img, A, B, centres, radii, sigma, C, lo, hi, common=True, touching=True, max_nfev=300):
    """Least squares of blurred discs to a cross-section, with the Jacobian in closed form.

    The centres (k, 2) move freely; the radius is one for all (``common``) or one per disc,
    clipped to ``[lo, hi]`` (scalars, or one per disc); with ``touching`` two discs closer than
    1.9 radii are pushed apart (touching rods do not overlap).  A disc's profile is
    :func:`_disc_values`.  Returns (centres (k, 2), radii (k,), sse of the image residual).
    """
    from scipy.optimize import least_squares

    xy = np.stack([A.ravel(), B.ravel()], 1)
    y = img.ravel().astype(np.float64)
    k = len(centres)
    lo = np.broadcast_to(np.asarray(lo, float), (k,))
    hi = np.broadcast_to(np.asarray(hi, float), (k,))
    nr = 1 if common else k
    pairs = [(a, b) for a in range(k) for b in range(a + 1, k)] if touching else []

    def radii_of(p):
        rr = np.full(k, p[2 * k]) if common else p[2 * k:].copy()
        return np.clip(rr, lo, hi), (rr >= lo) & (rr <= hi)

    cache: dict = {}

    def evaluate(p):
        key = p.tobytes()
        if key not in cache:
            cache.clear()
            cc = p[:2 * k].reshape(k, 2)
            rr, free = radii_of(p)
            parts = []
            for i in range(k):
                dx, dy = xy[:, 0] - cc[i, 0], xy[:, 1] - cc[i, 1]
                rho = np.hypot(dx, dy)
                parts.append((dx, dy, rho) + _disc_values(rho, float(rr[i]), sigma))
            cache[key] = (cc, rr, free, parts)
        return cache[key]

    def fun(p):
        cc, rr, _, parts = evaluate(p)
        out = C * sum(part[3] for part in parts) - y
        pen = [10.0 * max(0.0, 1.9 * rr[0] - math.hypot(*(cc[a] - cc[b]))) for a, b in pairs]
        return np.concatenate([out, pen]) if pen else out

    def jac(p):
        cc, rr, free, parts = evaluate(p)
        J = np.zeros((len(y) + len(pairs), 2 * k + nr))
        for i, (dx, dy, rho, _, slope, d_r) in enumerate(parts):
            safe = np.maximum(rho, 1e-9)
            J[:len(y), 2 * i] = -C * slope * dx / safe
            J[:len(y), 2 * i + 1] = -C * slope * dy / safe
            if free[i]:
                J[:len(y), 2 * k + (0 if common else i)] += C * d_r
        for row, (a, b) in enumerate(pairs):
            d = cc[a] - cc[b]
            dist = math.hypot(*d)
            if 1.9 * rr[0] - dist > 0:
                g = d / max(dist, 1e-9)
                J[len(y) + row, 2 * a:2 * a + 2] = -10.0 * g
                J[len(y) + row, 2 * b:2 * b + 2] = 10.0 * g
                if free[0]:
                    J[len(y) + row, 2 * k] = 19.0
        return J

    p0 = np.concatenate([np.asarray(centres, float).ravel(), np.asarray(radii, float).ravel()[:nr]])
    sol = least_squares(fun, p0, jac=jac, method="lm", max_nfev=max_nfev)
    rr, _ = radii_of(sol.x)
    return sol.x[:2 * k].reshape(k, 2), rr, float((sol.fun[:len(y)] ** 2).sum())


def _greedy_centres(img, A, B, k, r, sigma, C):
    """Start for k discs of radius r: the best match of a disc template in what the discs so
    far leave, no second disc on top of a first; None when k do not fit."""
    from scipy.signal import fftconvolve

    rho_t, val = _profile(r, sigma)
    g1 = A[:, 0]
    tmpl = np.interp(np.hypot(A, B), rho_t, val, right=0.0)
    res = img.astype(np.float64).copy()
    cen = []
    for _ in range(k):
        resp = fftconvolve(res, tmpl[::-1, ::-1], mode="same")
        for c0 in cen:
            resp[np.hypot(A - c0[0], B - c0[1]) < 1.6 * r] = -np.inf
        i, j = np.unravel_index(int(np.argmax(resp)), resp.shape)
        if not np.isfinite(resp[i, j]):
            return None
        cen.append((g1[i], g1[j]))
        res -= C * np.interp(np.hypot(A - g1[i], B - g1[j]), rho_t, val, right=0.0)
    return np.asarray(cen, float)


def fit_discs(img: np.ndarray, g1: np.ndarray, sigma: float = 1.0, C: float = 1.0, max_rods: int = MAX_RODS):
    """Centres (k, 2) and radius of the touching discs that best explain a cross-section.

    Parameters
    ----------
    img : (m, m) array
        Normalised cross-section (background 0, rod plateau ``C``), grid ``g1`` on both axes.
    sigma : float
        Blur sigma (voxels) of the discs.
    C : float
        Plateau of a rod.

    Returns
    -------
    (centres (k, 2), r, sse) or None
        Disc centres in the grid's coordinates, the common radius (voxels), residual sum.
    """
    from scipy.optimize import least_squares

    h = float(g1[1] - g1[0])
    A, B = np.meshgrid(g1, g1, indexing="ij")
    xy = np.stack([A.ravel(), B.ravel()], 1)
    # background offset: the median of the border (rods are fitted to what lies above it)
    edge = np.concatenate([img[0], img[-1], img[:, 0], img[:, -1]])
    img = img - float(np.median(edge))
    y = img.ravel().astype(np.float64)
    mass = float(img.sum()) * h * h
    if mass <= 0:
        return None
    results = []
    for k in range(1, max_rods + 1):
        r = math.sqrt(mass / (k * math.pi * C))
        if r < 0.75:
            break
        cen = _greedy_centres(img, A, B, k, r, sigma, C)
        if cen is None:
            break

        def fun(p):
            rr = float(np.clip(p[0], 0.5, 3.0 * r))
            cc = p[1:].reshape(-1, 2)
            out = _model(xy, cc, round(rr, 2), sigma, C) - y
            pen = []
            for a in range(len(cc)):  # touching rods do not overlap
                for b in range(a + 1, len(cc)):
                    d = math.hypot(*(cc[a] - cc[b]))
                    pen.append(10.0 * max(0.0, 1.9 * rr - d))
            return np.concatenate([out, pen]) if pen else out

        p0 = np.concatenate([[r], np.asarray(cen, float).ravel()])
        sol = least_squares(fun, p0, method="lm", max_nfev=300, diff_step=1e-2)
        results.append((k, sol.x[1:].reshape(-1, 2), float(sol.x[0]), float((sol.fun ** 2).sum())))
    if not results:
        return None
    # the best fit gives the rods' radius; the mass then counts them (an extra disc lowers the
    # residual a little by fitting the blur's tails, but does not change the radius)
    kb, cen, r, sse = min(results, key=lambda x: x[3])
    k_mass = int(round(mass / (math.pi * r * r * C)))
    for x in results:
        if x[0] == k_mass:
            kb, cen, r, sse = x
    return cen, r, sse


#: a refined rod whose intensity mass per unit length is at least this many times a single
#: rod's is examined as touching rods traced as one (two rods side by side: 1.7-2.0 measured
#: through a window that truncates them; single rods: 0.9-1.15)
FAT_MASS_RATIO = 1.25
#: k discs of the single rods' radius replace one fatter disc when their residual is below
#: this share of the one disc's
SPLIT_SSE_RATIO = 0.7
#: a group's traced axes refitted as discs and moved by more than this (voxels) are moved there
MOVE_VOXELS = 0.5


def _section_samples(sample, p0, p1, e1, e2, g1, n_pos):
    """Normalised samples (n_pos, m * m) on cross-sections of grid ``g1`` over the middle 70% of
    the segment p0-p1, and the sample points (n_pos, m * m, 3)."""
    u = p1 - p0
    L = float(np.linalg.norm(u))
    u = u / L
    A, B = np.meshgrid(g1, g1, indexing="ij")
    ts = np.linspace(0.15 * L, 0.85 * L, int(min(n_pos, max(3, 0.7 * L))))
    pts = p0 + ts[:, None, None] * u + A.ravel()[None, :, None] * e1 + B.ravel()[None, :, None] * e2
    return sample(pts.reshape(-1, 3)).reshape(len(ts), -1), pts


def _fit_touching_discs(img, A, B, k, r, sigma, C):
    """k touching discs of one radius (starting at ``r``, free within 0.6-1.3 r): (centres
    (k, 2), radius, sse), from a greedy start and least squares; None when k discs do not fit."""
    cen = _greedy_centres(img, A, B, k, r, sigma, C)
    if cen is None:
        return None
    cc, rr, sse = _fit_disc_model(img, A, B, cen, [r], sigma, C, 0.6 * r, 1.3 * r)
    return cc, float(rr[0]), sse


def _fit_traced_discs(img, A, B, starts, sigma, C):
    """The traced axes as discs, each of its own free radius: (centres (n, 2), radii, sse)."""
    st = np.asarray(starts, float)
    return _fit_disc_model(img, A, B, st[:, :2], st[:, 2], sigma, C, 0.5, 4.0 * st[:, 2], common=False,
                           touching=False, max_nfev=200 * len(st))


def split_touching(sample, members, r, sigma, C, neighbours=(), h=0.5, n_pos=12):
    """Axes of the touching rods a group of traced parallel axes holds, or None when the traced
    axes are right.

    A bundle of thin touching rods binarises into one blob, so that tracing finds fewer axes
    than rods (two rods as one axis between them, three as two).  The median cross-section of
    the image about the group's mean axis (its other neighbours' modelled discs taken off first,
    so that a rod beside or across it does not count) is fitted two ways: the traced axes as
    discs, each of free radius; and k touching discs of the single rods' radius (free within
    0.6-1.3 ``r``), for each k above the number of traced axes up to ``round(mass) + 1``, the
    mass counted in single rods.  The k discs replace the traced axes when their residual is
    below :data:`SPLIT_SSE_RATIO` of the traced axes': a thick rod is one round disc, two thin
    rods side by side are not.

    Parameters
    ----------
    sample : callable
        Normalised image (background 0, plateau ``C``) at points (n, 3) in (x, y, z) voxels;
        NaN outside the volume.
    members : sequence of (p0, p1)
        The group's traced axes (voxels), parallel; the first sets the direction.
    r, sigma, C : float
        A single rod's radius and the image's blur (voxels), the rods' plateau.
    neighbours : sequence of (q0, q1, radius)
        Other rods near the group (voxels).

    Returns
    -------
    list of (p0, p1) or None
        The rods' axes (parallel to the first member, spanning the members' extent), the discs
        cut by the section's edge left out.
    """
    from rodwarp.ct._voxels import _basis, _point_segment_distance

    m0 = [np.asarray(a, float) for a in members[0]]
    L0 = float(np.linalg.norm(m0[1] - m0[0]))
    if L0 < 4.0 * r:
        return None
    u = (m0[1] - m0[0]) / L0
    e1, e2 = _basis(u)
    ends = np.array([[np.asarray(q, float) for q in ax] for ax in members])  # (n, 2, 3)
    t = (ends - m0[0]) @ u
    t_lo, t_hi = float(np.max(t.min(1))), float(np.min(t.max(1)))  # the span all members share
    t_all = (float(t.min()), float(t.max()))
    if t_hi - t_lo < 4.0 * r:
        return None
    mids = ends.mean(1)
    off = np.stack([(mids - m0[0]) @ e1, (mids - m0[0]) @ e2], 1)
    o = off.mean(0)
    off = off - o
    origin = m0[0] + o[0] * e1 + o[1] * e2
    W = float(np.max(np.hypot(off[:, 0], off[:, 1]))) + 3.0 * r + 2.0 * sigma + 1.0
    g1 = np.arange(-W, W + 1e-9, h)
    A, B = np.meshgrid(g1, g1, indexing="ij")
    v, pts = _section_samples(sample, origin + t_lo * u, origin + t_hi * u, e1, e2, g1, n_pos)
    if np.mean(np.isfinite(v)) < 0.8:
        return None
    flat = pts.reshape(-1, 3)
    for q0, q1, rq in neighbours:  # take the neighbours' modelled discs off
        d = _point_segment_distance(flat, np.asarray(q0, float), np.asarray(q1, float))
        near = d < rq + 3.0 * sigma + 1.0
        if near.any():
            rho_t, val = _profile(rq, sigma)
            v.reshape(-1)[near] -= C * np.interp(d[near], rho_t, val, right=0.0)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        img = np.nan_to_num(np.nanmedian(v, axis=0).reshape(A.shape), nan=0.0)
    # the section's own mass in single rods, its neighbours off: a rod made fat by a neighbour's
    # share is not more than one
    k_img = float(img.sum()) * h * h / (math.pi * r * r * C)
    n = len(members)
    if k_img < FAT_MASS_RATIO:
        return None
    r_each = math.sqrt(k_img / n) * r
    c0, r0, sse0 = _fit_traced_discs(img, A, B, [(x, y, r_each) for x, y in off], sigma, C)
    best = None
    for k in range(n + 1, int(min(MAX_RODS, round(k_img) + 1)) + 1):
        got = _fit_touching_discs(img, A, B, k, r, sigma, C)
        if got is not None and (best is None or got[2] < best[2]):
            best = got
    if best is not None and best[2] < SPLIT_SSE_RATIO * sse0:
        cen, r_fit = best[0], best[1]
    elif n > 1 and np.max(np.hypot(*(c0 - off).T)) > MOVE_VOXELS:
        # as many rods as traced, but the tracing packed them together (a binarised bundle's
        # skeleton runs in its middle): the refitted centres
        cen, r_fit = c0, float(np.median(r0))
    else:
        return None
    # a disc at the section's edge is a neighbour cut by it, not a member
    cen = [c for c in cen if np.all(np.abs(c) <= W - r_fit)]
    return [(origin + t_all[0] * u + x * e1 + y * e2, origin + t_all[1] * u + x * e1 + y * e2) for x, y in cen]
