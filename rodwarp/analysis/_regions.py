"""A packing's own core and rim, found from its fields alone, and e per rod pair ball by ball.

The same rule applies to a simulated packing and to a CT packing, so that their statistics can be
compared region for region (docs/experiments.md, "The fields against the authors' CT, like for
like").  It needs nothing but the rods-per-ball field ``n`` on its grid: the packing is where a
ball holds a rod (the authors' published fields mark the outside with ``n == 0``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rodwarp.errors import RodwarpError

__all__ = ["PackingRegions", "packing_regions", "pair_entanglement"]

#: the core: within this share of the packing's radius of its axis ...
CORE_RADIUS = 0.55
#: ... between these shares of its height above its bottom layer
CORE_HEIGHT = (0.15, 0.70)
#: a layer belongs to the packing's body where it holds at least this share of the median layer's area
BODY_AREA = 0.5


@dataclass
class PackingRegions:
    """A packing's axis, radius and height, and its core and rim masks (from :func:`packing_regions`).

    Attributes
    ----------
    axis : (float, float)
        The packing's vertical axis (x, y), the centroid of its occupied balls in the core's
        height band (length).
    radius : float
        The radius of the circle of the median body layer's occupied area (length).
    bottom, top : float
        The lowest and highest body layers' centres (length).
    core, rim : ndarray of bool (nz, ny, nx)
        Occupied balls of the height band within ``CORE_RADIUS`` of the radius of the axis, and
        beyond it.
    band : ndarray of bool (nz, ny, nx)
        Occupied balls of the height band (core and rim).
    r, zeta : ndarray (nz, ny, nx)
        Each ball's distance from the axis over the radius, and its height above ``bottom``
        over ``top - bottom``.
    """

    axis: tuple
    radius: float
    bottom: float
    top: float
    core: np.ndarray = field(repr=False)
    rim: np.ndarray = field(repr=False)
    band: np.ndarray = field(repr=False)
    r: np.ndarray = field(repr=False)
    zeta: np.ndarray = field(repr=False)

    def as_dict(self) -> dict:
        """The scalars (for summary files)."""
        return {"axis": [float(v) for v in self.axis], "radius": float(self.radius), "bottom": float(self.bottom),
                "top": float(self.top), "core_balls": int(self.core.sum()), "rim_balls": int(self.rim.sum())}


def packing_regions(n, x, y, z, *, core_radius: float = CORE_RADIUS,
                    core_height: tuple = CORE_HEIGHT) -> PackingRegions:
    """The core and rim of a packing standing on a plate, from the rods-per-ball field.

    The rule, the same for any packing: the occupied balls are those with ``n > 0``; a layer
    is part of the body when its occupied area is at least half the median layer's (the thin
    layers of the rough top are not); ``bottom`` and ``top`` are the lowest and highest body
    layers; the radius is that of the circle of the median body layer's occupied area; the axis
    is the centroid of the occupied balls of the height band. The core is the band's balls
    within ``core_radius`` of the radius of the axis, the rim the band's others.

    Parameters
    ----------
    n : array_like (nz, ny, nx)
        Rods per ball (NaN or 0 outside the packing).
    x, y, z : array_like
        Ball-centre coordinates (length, any unit; the results are in it).
    core_radius : float
        The core's radius over the packing's (default 0.55).
    core_height : (float, float)
        The band's lower and upper height over the packing's (default 0.15 to 0.70).

    Returns
    -------
    PackingRegions

    Raises
    ------
    RodwarpError
        When no ball holds a rod, or the shapes disagree.
    """
    n = np.asarray(n, dtype=np.float64)
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    if n.shape != (len(z), len(y), len(x)):
        raise RodwarpError(f"n has shape {n.shape}, the grid (len(z), len(y), len(x)) = "
                           f"{(len(z), len(y), len(x))}; give the field with its own coordinates")
    if not (0 < core_radius and 0 <= core_height[0] < core_height[1] <= 1):
        raise RodwarpError(f"core_radius must be > 0 and core_height 0 <= low < high <= 1, got {core_radius}, "
                           f"{core_height}")
    occ = np.nan_to_num(n, nan=0.0) > 0
    area = occ.sum(axis=(1, 2))
    if not area.any():
        raise RodwarpError("no ball holds a rod: the field has no packing to find a core in")
    body = np.flatnonzero(area >= BODY_AREA * np.median(area[area > 0]))
    bottom, top = float(z[body[0]]), float(z[body[-1]])
    span = max(top - bottom, 1e-300)
    zeta = (z - bottom) / span
    h2 = abs((x[1] - x[0]) * (y[1] - y[0])) if len(x) > 1 and len(y) > 1 else 1.0
    radius = float(np.sqrt(np.median(area[body]) * h2 / np.pi))
    # a layer on a band's edge is in it whatever the unit's rounding
    in_band = (zeta >= core_height[0] - 1e-9) & (zeta <= core_height[1] + 1e-9)
    band = occ & in_band[:, None, None]
    if not band.any():
        band = occ
    _, iy, ix = np.nonzero(band)
    axis = (float(x[ix].mean()), float(y[iy].mean()))
    rr = np.hypot(x[None, None, :] - axis[0], y[None, :, None] - axis[1]) / radius
    rr = np.broadcast_to(rr, n.shape)
    core = band & (rr < core_radius)
    rim = band & ~core
    return PackingRegions(axis=axis, radius=radius, bottom=bottom, top=top, core=core, rim=rim, band=band,
                          r=np.array(rr), zeta=np.broadcast_to(zeta[:, None, None], n.shape).copy())


def pair_entanglement(e, n) -> np.ndarray:
    """Each ball's entanglement per rod pair, e / (n (n - 1) / 2), NaN where fewer than 2 rods.

    A ratio per ball, not the ratio of the means: mean e over the pairs at the mean n weighs the
    crowded balls' pairs more where n is widely spread.

    Parameters
    ----------
    e, n : array_like
        Entanglement and rods per ball, of one shape (under one convention: the authors' e
        counts every pair twice, docs/fields.md).

    Returns
    -------
    ndarray
        Same shape, dimensionless.
    """
    e = np.asarray(e, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    if e.shape != n.shape:
        raise RodwarpError(f"e and n must have one shape, got {e.shape} and {n.shape}")
    pairs = n * (n - 1) / 2.0
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(pairs >= 1, e / np.where(pairs >= 1, pairs, 1.0), np.nan)
