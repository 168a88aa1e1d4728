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

        rho = np.linspace(0.0, r + 5.0 * sigma + 1.0, 160)
        _PROFILES[key] = (rho, _blur_model(-np.inf, rho, key[0], key[1], n_r=24, n_th=32))
    return _PROFILES[key]


def _model(xy, centres, r, sigma, C):
    rho_t, val = _profile(r, sigma)
    out = np.zeros(len(xy))
    for c in centres:
        out += np.interp(np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]), rho_t, val, right=0.0)
    return C * out


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
    from scipy.signal import fftconvolve

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
        rho_t, val = _profile(r, sigma)
        # greedy start: the best match of a disc template in what the discs so far leave
        tmpl = np.interp(np.hypot(A, B), rho_t, val, right=0.0)
        res = img.astype(np.float64).copy()
        cen = []
        for _ in range(k):
            resp = fftconvolve(res, tmpl[::-1, ::-1], mode="same")
            for c0 in cen:  # no second disc on top of a first
                resp[np.hypot(A - c0[0], B - c0[1]) < 1.6 * r] = -np.inf
            i, j = np.unravel_index(int(np.argmax(resp)), resp.shape)
            if not np.isfinite(resp[i, j]):
                break
            cen.append((g1[i], g1[j]))
            res -= C * np.interp(np.hypot(A - g1[i], B - g1[j]), rho_t, val, right=0.0)
        if len(cen) < k:
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
