"""Vectorised NumPy geometry on the host (segment distances), for checks and packing."""

from __future__ import annotations

import numpy as np


def segment_closest_params(p0, p1, q0, q1):
    """Closest-point parameters (s, t) in [0, 1] of segments p0-p1 and q0-q1 (broadcasting).

    Parallel pairs take the middle of their overlap, as the Warp narrowphase does.
    """
    p0, p1, q0, q1 = (np.asarray(a, dtype=np.float64) for a in (p0, p1, q0, q1))
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = np.einsum("...i,...i", d1, d1)
    e = np.einsum("...i,...i", d2, d2)
    f = np.einsum("...i,...i", d2, r)
    c = np.einsum("...i,...i", d1, r)
    b = np.einsum("...i,...i", d1, d2)
    den = a * e - b * b
    tiny = 1e-300
    par = den <= 1e-12 * a * e
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(par | (a <= tiny), 0.0, np.clip((b * f - c * e) / np.where(den > 0, den, 1.0), 0.0, 1.0))
        # parallel: project q's ends on p, take the middle of the overlap
        sq0 = np.where(a > tiny, -c / np.where(a > tiny, a, 1.0), 0.0)
        sq1 = np.where(a > tiny, (b - c) / np.where(a > tiny, a, 1.0), 0.0)
        lo = np.clip(np.minimum(sq0, sq1), 0.0, 1.0)
        hi = np.clip(np.maximum(sq0, sq1), 0.0, 1.0)
        s = np.where(par & (a > tiny), 0.5 * (lo + hi), s)
        t = np.where(e > tiny, (b * s + f) / np.where(e > tiny, e, 1.0), 0.0)
        t_cl = np.clip(t, 0.0, 1.0)
        s = np.where((t != t_cl) & (a > tiny), np.clip((b * t_cl - c) / np.where(a > tiny, a, 1.0), 0.0, 1.0), s)
    return s, t_cl


def segment_distance(p0, p1, q0, q1):
    """Distance between segments p0-p1 and q0-q1 (broadcasting over leading axes)."""
    s, t = segment_closest_params(p0, p1, q0, q1)
    p0, p1, q0, q1 = (np.asarray(a, dtype=np.float64) for a in (p0, p1, q0, q1))
    pa = p0 + s[..., None] * (p1 - p0)
    pb = q0 + t[..., None] * (q1 - q0)
    return np.linalg.norm(pa - pb, axis=-1)
