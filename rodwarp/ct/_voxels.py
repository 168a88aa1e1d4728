"""Geometry in voxel space shared by ``rodwarp.ct``: bases, discs, segment windows, samplers, polyline
resampling; and the parsing of voxel sizes (volume files and segmentation alike).

Points are ``(x, y, z)`` in working voxels; arrays are indexed ``(z, y, x)``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from rodwarp._util import one_line_error as _fail
from rodwarp.errors import RodwarpError


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _basis(u):
    """Two unit vectors orthogonal to u (and to each other), chosen deterministically."""
    k = int(np.argmin(np.abs(u)))
    a = np.zeros(3)
    a[k] = 1.0
    e1 = _unit(np.cross(u, a))
    e2 = np.cross(u, e1)
    return e1, e2


def _canonical(u):
    """Sign convention: the largest component of a direction is positive."""
    return u if u[int(np.argmax(np.abs(u)))] >= 0 else -u


def _disc_offsets(radius, spacing=1.0, min_points=5):
    """Grid offsets (m, 2) inside a disc (at least the centre and its 4 neighbours)."""
    n = int(math.ceil(radius / spacing))
    g = np.arange(-n, n + 1) * spacing
    a, b = np.meshgrid(g, g, indexing="ij")
    o = np.stack([a.ravel(), b.ravel()], 1)
    keep = (o ** 2).sum(1) <= radius * radius + 1e-9
    o = o[keep]
    if len(o) < min_points:
        o = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]], float) * min(spacing, max(radius, 0.5))
    return o


def _point_segment_distance(pts, a, b):
    """Distance from points (n,3) to segment a-b."""
    d = np.asarray(b, dtype=np.float64) - a
    L2 = float(d @ d)
    w = pts - a
    if L2 <= 1e-300:
        return np.sqrt(np.einsum("ij,ij->i", w, w))
    t = np.clip(w @ d / L2, 0.0, 1.0)
    w -= t[:, None] * d
    return np.sqrt(np.einsum("ij,ij->i", w, w))


def _window_voxels(a_zyx, b_zyx, R, shape):
    """Integer voxels (zyx) whose centres lie within R of segment a-b (zyx coordinates).

    Returns (zyx (n,3) int64, t (n,) axial coordinate from a along the unit axis, rho (n,)
    distance to the segment's infinite line, dist (n,) distance to the segment).
    """
    a = np.asarray(a_zyx, float)
    b = np.asarray(b_zyx, float)
    d = b - a
    L = float(np.linalg.norm(d))
    u = d / L if L > 0 else np.array([1.0, 0, 0])
    k = int(np.argmax(np.abs(u)))
    i, j = [x for x in range(3) if x != k]
    uk = u[k]
    lo_k = int(math.ceil(min(a[k], b[k]) - R))
    hi_k = int(math.floor(max(a[k], b[k]) + R))
    lo_k, hi_k = max(lo_k, 0), min(hi_k, shape[k] - 1)
    if hi_k < lo_k:
        return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0), np.zeros(0)
    s = np.arange(lo_k, hi_k + 1, dtype=np.float64)
    # axis point in each plane (clamped to the segment's planes extended by the caps)
    tk = (s - a[k]) / uk
    tk = np.clip(tk, -R / abs(uk), L + R / abs(uk))
    ci = a[i] + tk * u[i]
    cj = a[j] + tk * u[j]
    Hi = int(math.ceil(R * math.sqrt(max(1.0 - u[j] ** 2, 0.0)) / abs(uk) + R * abs(u[i]) / abs(uk))) + 1
    Hj = int(math.ceil(R * math.sqrt(max(1.0 - u[i] ** 2, 0.0)) / abs(uk) + R * abs(u[j]) / abs(uk))) + 1
    oi = np.arange(-Hi, Hi + 1)
    oj = np.arange(-Hj, Hj + 1)
    # separable evaluation: every quantity is a broadcast sum of (slice, i) and (slice, j) terms
    ii = np.rint(ci).astype(np.int64)[:, None] + oi[None, :]          # (S, I)
    jj = np.rint(cj).astype(np.int64)[:, None] + oj[None, :]          # (S, J)
    dk = (s - a[k])[:, None, None]
    di = (ii - a[i])[:, :, None]
    dj = (jj - a[j])[:, None, :]
    t = dk * u[k] + di * u[i] + dj * u[j]
    w2 = dk * dk + di * di + dj * dj
    rho2 = np.maximum(w2 - t * t, 0.0)
    over = np.maximum(t - L, 0.0) + np.maximum(-t, 0.0)
    keep = (rho2 + over * over) <= R * R
    keep &= ((ii >= 0) & (ii < shape[i]))[:, :, None] & ((jj >= 0) & (jj < shape[j]))[:, None, :]
    si, ai, aj = np.nonzero(keep)
    P = np.empty((len(si), 3), np.int64)
    P[:, k] = s.astype(np.int64)[si]
    P[:, i] = ii[si, ai]
    P[:, j] = jj[si, aj]
    tt = t[keep]
    r2 = rho2[keep]
    ov = over[keep]
    return P, tt, np.sqrt(r2), np.sqrt(r2 + ov * ov)


class _BlockSampler:
    """Trilinear samples of a (smoothed, normalised) block at global (x, y, z) points; NaN outside."""

    def __init__(self, g: np.ndarray, origin_zyx):
        self.g = g
        self.o = np.asarray(origin_zyx, dtype=np.float64)

    def __call__(self, pts):
        pts = np.asarray(pts, dtype=np.float64)
        sh = pts.shape[:-1]
        c = pts.reshape(-1, 3)[:, ::-1].T - self.o[:, None]
        v = ndimage.map_coordinates(self.g, c, order=1, mode="constant", cval=np.nan, output=np.float64)
        return v.reshape(sh)


def _resample(poly: np.ndarray, step: float) -> np.ndarray:
    """The polyline ``poly`` (m, 3) resampled at equal arc-length steps of at most ``step`` voxels
    (its end points kept; a polyline of zero length becomes its first point twice)."""
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 1e-9:
        return poly[:1].repeat(2, 0)
    n = max(2, int(math.ceil(cum[-1] / step)) + 1)
    s = np.linspace(0.0, cum[-1], n)
    return np.stack([np.interp(s, cum, poly[:, j]) for j in range(3)], 1)


# voxel sizes (read by the volume files and by segmentation alike)

def parse_voxel_size(voxel_size) -> tuple[float, float, float]:
    """One edge length or three (z, y, x, the array order) -> (dz, dy, dx); positive and finite."""
    if voxel_size is None:
        return (1.0, 1.0, 1.0)
    v = np.atleast_1d(np.asarray(voxel_size, dtype=object))
    try:
        vals = [float(x) for x in v.ravel()]
    except (TypeError, ValueError):
        raise _fail(f"voxel size must be numbers, got {voxel_size!r}") from None
    if len(vals) == 1:
        vals = vals * 3
    if len(vals) != 3:
        raise _fail(f"voxel size takes one value (isotropic) or three (z, y, x), got {len(vals)}: {vals}; "
                    f"pass e.g. --voxel-size 0.05 or --voxel-size 0.1,0.05,0.05")
    if not all(math.isfinite(x) and x > 0 for x in vals):
        raise _fail(f"voxel size must be positive numbers, got {vals}")
    return tuple(vals)


def parse_voxel_size_text(text) -> tuple[float, float, float] | None:
    """``"0.05"`` or ``"0.1,0.05,0.05"`` (z, y, x; commas or spaces) -> (dz, dy, dx); None stays None."""
    if text is None:
        return None
    if isinstance(text, str):
        parts = [t for t in text.replace(",", " ").split() if t]
        try:
            vals = [float(t) for t in parts]
        except ValueError:
            raise RodwarpError(f"--voxel-size must be one number or three (z,y,x), e.g. 0.05 or 0.1,0.05,0.05; "
                               f"got '{text}'") from None
        if not vals:
            raise RodwarpError("--voxel-size is empty; give one number or three (z,y,x)")
        text = vals
    try:
        return parse_voxel_size(text)
    except RodwarpError as e:
        raise RodwarpError(f"--voxel-size: {e}") from None
