"""CT segmentation on the CPU: rod centrelines, radii and contacts from a greyscale volume.

The volume is indexed ``(z, y, x)`` = (slice, row, column); every point this module returns is
``(x, y, z)`` in (working) voxel units with the centre of voxel ``(0, 0, 0)`` at the origin.

Pipeline (:func:`segment_volume`; each stage is timed in ``SegmentResult.timings``):

0. **prepare** (:mod:`rodwarp.segment_prep`) -- field-of-view mask, background trend (cupping,
   rings), dark rods (negated, so that rods are brighter than the background from here on),
   anisotropic voxels resampled onto an isotropic grid.

1. **stats** -- a smoothed, strided sample of the volume gives an Otsu split; the (up to) four
   blocks with the most foreground give the background and foreground levels (medians far
   outside / deep inside the mask) and a coarse radius (median of the distance-transform
   maxima).
2. **detect** -- per chunk (the whole volume unless ``chunk`` is set): Gaussian denoising,
   binarisation at the half level between background and foreground, a 3-D skeleton whose
   junctions (and a ball of about one radius around each) are removed so that branches at
   contacts separate; each remaining branch is a seed.  A seed is fitted by iterative
   intensity-weighted centroid/line fits inside a cylinder of one radius around the current
   axis, then *marched*: the axis is extended block by block while a small disc on the axis
   stays filled, refitting as it grows.  Two rods lying side by side (whose skeleton runs
   between them) are recognised by an elongated cross-section and split; a bundle of three or
   more (a cross-section much shallower than it is wide) is split by fitting k blurred discs
   to its greyscale cross-section (:mod:`rodwarp.segment_bundles`).  Foreground left
   unexplained by the traced rods seeds a second round.  With ``shape="curved"`` (or
   ``"auto"`` when the skeleton's long branches bend smoothly) filaments are traced as
   polylines instead (:mod:`rodwarp.segment_curved`) and stages 3-5 are its own.
3. **merge** -- collinear pieces of one rod (split by contacts, gaps or chunk borders) are
   pasted when the image shows the gap between them filled, and duplicate fits of one rod (an
   axis lying mostly within 0.75 r of another's: distinct rods keep theirs 2 r apart) become
   one.
4. **refine** -- against the raw greyscale: every voxel within ``r + window_margin`` of a rod is
   assigned to the rod whose surface is nearest (touching neighbours then trade equal amounts
   of blurred intensity, so they do not pull the fit); slab-wise intensity centroids
   perpendicular to the axis give a robust straight-line fit; a global blurred-disc fit of the
   radial profile gives the contrast and the blur, and the median intensity mass per unit
   length the radius; each end is fitted to the intensity profile along the axis with the
   profile of a blurred capsule (or flat) end, sub-voxel.  Rounds repeat, for the rods that
   still move, until every end moves less than ``refine_tol``; pieces that converge onto one
   rod are merged between rounds.  With mixed radii (a broad distance-transform ridge, or a
   spread of the rods' own radii) every rod keeps its own radius, in the output, the
   acceptance tests and the contact gaps; the faint test compares a rod's plateau with what a
   rod of its radius shows under the fitted blur, so thin rods are not rejected wholesale.
5. **contacts** -- rod pairs whose surface gap ``|closest axis points| - r_i - r_j`` is below
   ``contact_tolerance`` and whose gap is filled with foreground in the image.

``SegmentResult.quality["flags"]`` says in words when the output should not be trusted.
Scoring helpers for synthetic volumes: :func:`match_rods` and :func:`score_contacts` (and
:func:`rodwarp.segment_score.match_polylines` for curved filaments).

This module must not import warp.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np
from scipy import ndimage
from scipy.special import ndtr

from rodwarp.errors import RodwarpError
from rodwarp.rodset import Contacts, RodSet

__all__ = [
    "SegmentParams", "SegmentResult", "segment_volume",
    "RodMatch", "match_rods", "ContactScore", "score_contacts",
]

_HINT = "check the contrast / pass --diameter"


def _fail(msg: str) -> RodwarpError:
    return RodwarpError(" ".join(str(msg).split()))


# ----------------------------------------------------------------------------------------------
# parameters and result
# ----------------------------------------------------------------------------------------------

@dataclass
class SegmentParams:
    """Every knob of :func:`segment_volume`.  Lengths are in voxels unless marked "x r" (radii).

    Attributes
    ----------
    diameter : float or None
        Rod diameter in voxels.  ``None``: estimated, coarsely from the maxima of the distance
        transform of the binarised foreground, then from the greyscale (median over rods of the
        intensity mass per unit length, with the contrast from a blurred-disc profile fit).
    smooth_sigma : float
        Gaussian denoising before binarisation and skeletonisation (detection only; the
        refinement reads the raw volume).  0 disables it.
    threshold : float or None
        Binarisation threshold in raw intensity units.  ``None``: half-way between the
        estimated background and foreground levels.
    contact_tolerance : float
        Largest surface gap (voxels) reported as a contact.
    contact_min_fill : float
        Image confirmation of a contact: the normalised intensity (0 = background,
        1 = foreground) on the segment joining the two rod surfaces must stay at or above this.
    junction_radius : float
        Skeleton voxels within ``junction_radius * r + 1`` of a junction (a voxel with 3 or more
        skeleton neighbours) are removed before the branches become seeds.
    min_seed_voxels : int
        Shortest skeleton branch (voxels) used as a seed.
    fit_iterations : int
        Iterations of the coarse centroid/line fit of each seed (and after each marching block).
    march_block : int
        Voxels probed at once when marching an axis outward (the line is refitted after every
        full block).
    march_fill : float
        Marching continues while the mean smoothed, normalised intensity in a disc of radius
        ``r / 2`` on the axis is at least this.
    split_anisotropy : float
        A fitted axis whose cross-section second moments differ by more than this times r^2 is
        two rods side by side: it is split into two seeds.
    residual_passes : int
        Rounds of seeding from foreground that no traced rod explains.
    merge_angle : float
        Pieces are pasted / deduplicated when their axes differ by at most this (degrees)...
    merge_distance : float
        ...the shorter one's ends lie within this (x r) of the longer one's axis...
    merge_gap : float
        ...and their extents overlap or leave a gap of at most this (x r) along the axis that
        the image shows filled.  (Independently, a piece whose axis lies for at least half its
        length within 0.75 r of another's is a duplicate of it, whatever the angle.)
    refine_iterations : int
        Most rounds of greyscale refinement (axis, then ends); 0 keeps the coarse fits.
    refine_tol : float
        Refinement stops when no rod end moves more than this (voxels) in a round; a rod is
        refined again only while it or a neighbour still moves.
    window_margin : float
        Voxels beyond the radius that the greyscale refinement reads around each axis (should
        cover about 2.5 blur sigmas).
    end_radius : float
        Radius (voxels) of the disc around the axis whose mean intensity profile locates ends.
    end_model : str
        ``"capsule"`` (rod ends are hemispherical caps, as ``rodwarp phantom`` and the simulator
        model them: the endpoint is the centre of the cap) or ``"flat"`` (the endpoint is the
        flat end face).
    min_length : float
        Rods shorter than this (x r) after refinement are rejected.
    min_fill : float
        Rods whose axis intensity plateau (normalised) is below this are rejected.
    radius_range : tuple of float
        Rods whose own greyscale radius falls outside this range (x the global r) are rejected.
    per_rod_radius : bool or None
        Give each rod its own greyscale radius (sub-voxel, from the intensity mass per unit
        length) in the output, the contact gaps and the acceptance tests, instead of the
        global one.  ``None``: when the radii are mixed (a broad distance-transform ridge, or
        a robust spread of the rods' own radii above ``MIXED_RADIUS_CV``).
    chunk : int or None
        Detection runs on overlapping cubes of this edge (voxels) read one at a time; ``None``
        processes the whole volume at once.  The refinement reads only the voxels around each rod.
    chunk_halo : int or None
        Overlap added on every side of a chunk; ``None``: ``max(4 smooth_sigma + 2, 3 r + 2)``.
    stats_block : int
        Edge of the blocks used for the level and coarse-radius statistics.
    dark : bool or None
        Rods darker than the background (grey values are negated first); ``None`` detects it
        from the histogram (:mod:`rodwarp.segment_prep`).
    fov : bool or None
        Field-of-view mask (a constant outside the reconstruction circle): ``None`` detects
        it, ``False`` never masks.
    background : bool or None
        Removal of the background trend about the rotation axis (cupping, rings): ``None``
        when it exceeds half the noise, ``True`` always, ``False`` never.
    shape : str
        ``"straight"`` (straight rods, two vertices each), ``"curved"`` (filaments traced as
        polylines, :mod:`rodwarp.segment_curved`) or ``"auto"`` (curved when the skeleton's
        branches bend, see :func:`segment_volume`).
    """

    diameter: float | None = None
    smooth_sigma: float = 1.0
    threshold: float | None = None
    contact_tolerance: float = 1.0
    contact_min_fill: float = 0.5
    junction_radius: float = 1.0
    min_seed_voxels: int = 4
    fit_iterations: int = 3
    march_block: int = 12
    march_fill: float = 0.5
    split_anisotropy: float = 0.25
    residual_passes: int = 1
    merge_angle: float = 5.0
    merge_distance: float = 0.5
    merge_gap: float = 2.0
    refine_iterations: int = 8
    refine_tol: float = 0.02
    window_margin: float = 2.5
    end_radius: float = 2.0
    end_model: str = "capsule"
    min_length: float = 4.0
    min_fill: float = 0.6
    radius_range: tuple = (0.6, 1.5)
    per_rod_radius: bool | None = None
    chunk: int | None = None
    chunk_halo: int | None = None
    stats_block: int = 96
    dark: bool | None = None
    fov: bool | None = None
    background: bool | None = None
    shape: str = "auto"

    def validate(self) -> None:
        def pos(name, v, allow_zero=False):
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise _fail(f"segment parameter {name} must be a number, got {v!r}") from None
            if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
                raise _fail(f"segment parameter {name} must be {'>= 0' if allow_zero else '> 0'}, got {v!r}")
        if self.diameter is not None:
            pos("diameter", self.diameter)
            if self.diameter < 1.0:
                raise _fail(f"diameter {self.diameter} voxels is too small to segment; rods need at least 1 voxel")
        pos("smooth_sigma", self.smooth_sigma, True)
        pos("contact_tolerance", self.contact_tolerance, True)
        pos("contact_min_fill", self.contact_min_fill, True)
        pos("junction_radius", self.junction_radius, True)
        pos("march_fill", self.march_fill)
        pos("split_anisotropy", self.split_anisotropy)
        pos("merge_angle", self.merge_angle)
        pos("merge_distance", self.merge_distance)
        pos("merge_gap", self.merge_gap, True)
        pos("window_margin", self.window_margin)
        pos("end_radius", self.end_radius)
        pos("refine_tol", self.refine_tol)
        pos("min_length", self.min_length, True)
        pos("min_fill", self.min_fill, True)
        for name in ("min_seed_voxels", "fit_iterations", "march_block", "residual_passes",
                     "refine_iterations", "stats_block"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < (1 if name in ("march_block", "stats_block",
                                                                         "fit_iterations", "min_seed_voxels") else 0):
                raise _fail(f"segment parameter {name} must be a positive integer, got {v!r}")
        if self.end_model not in ("capsule", "flat"):
            raise _fail(f"end_model must be 'capsule' or 'flat', got {self.end_model!r}")
        if self.chunk is not None and (not isinstance(self.chunk, (int, np.integer)) or self.chunk < 16):
            raise _fail(f"chunk must be an integer >= 16 voxels or None, got {self.chunk!r}")
        if self.chunk_halo is not None and (not isinstance(self.chunk_halo, (int, np.integer)) or self.chunk_halo < 0):
            raise _fail(f"chunk_halo must be a non-negative integer or None, got {self.chunk_halo!r}")
        if self.shape not in ("straight", "curved", "auto"):
            raise _fail(f"shape must be 'straight', 'curved' or 'auto', got {self.shape!r}")
        for name in ("dark", "fov", "background"):
            if getattr(self, name) not in (None, True, False):
                raise _fail(f"segment parameter {name} must be true, false or None (detect), got {getattr(self, name)!r}")
        lo, hi = self.radius_range
        if not (0 <= lo < hi):
            raise _fail(f"radius_range must be (low, high) with 0 <= low < high, got {self.radius_range!r}")


@dataclass
class SegmentResult:
    """What :func:`segment_volume` found.

    Attributes
    ----------
    rods : RodSet
        Straight rods in voxel units (2 vertices each, ``(x, y, z)``), one radius per rod;
        ``rods.contacts`` is ``contacts``.
    contacts : Contacts
        Contacts in voxel units (point = midpoint of the two closest axis points; gap = surface gap).
    diameter : float
        Rod diameter in voxels (estimated or given).
    timings : dict
        Seconds per stage (``stats``, ``detect``, ``merge``, ``refine``, ``contacts``, ``total``).
    quality : dict
        Fit and detection figures (see :func:`segment_volume`); ``quality["flags"]`` lists, in
        words, what makes the output untrustworthy (empty when nothing does).
    spacing : float
        Edge of the working voxel in the units of the ``voxel_size`` given (1 without one):
        physical coordinates are ``rods.points * spacing``.
    """

    rods: RodSet
    contacts: Contacts
    diameter: float
    timings: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    spacing: float = 1.0


# ----------------------------------------------------------------------------------------------
# volume access
# ----------------------------------------------------------------------------------------------

class _Reader:
    """Uniform read access to an ndarray or a lazy array-like (numpy slicing) volume."""

    def __init__(self, volume):
        shape = getattr(volume, "shape", None)
        if shape is None:
            try:
                volume = np.asarray(volume)
            except Exception as e:  # pragma: no cover - exotic inputs
                raise _fail(f"volume must be an array (z, y, x): {e}") from None
            shape = volume.shape
        shape = tuple(int(s) for s in shape)
        if len(shape) != 3:
            raise _fail(f"volume must be 3-D (z, y, x), got {len(shape)}-D shape {shape}; "
                        f"pass a stack of slices")
        if min(shape) == 0:
            raise _fail(f"volume is empty (shape {shape})")
        dtype = np.dtype(getattr(volume, "dtype", np.float32))
        if dtype.kind not in "biuf":
            raise _fail(f"volume must be numeric, got dtype {dtype}")
        self.vol = volume
        self.shape = shape
        self.in_memory = isinstance(volume, np.ndarray)
        # lazy volumes: gathers go through an LRU cache of blocks (the array's own chunks
        # when it has them), so that refining many rods does not re-read or re-decompress
        ch = getattr(volume, "chunks", None)
        try:
            ch = tuple(int(c) for c in ch) if ch is not None and len(ch) == 3 else None
        except TypeError:
            ch = None
        self.block = tuple(min(s, max(16, min(c, 128))) for s, c in zip(shape, ch or (64, 64, 64)))
        self.cache_bytes = 512 << 20
        self._cache: dict = {}

    def read(self, lo, hi) -> np.ndarray:
        """float32 copy of ``vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]`` (zyx, clamped)."""
        lo = [max(0, int(a)) for a in lo]
        hi = [min(s, int(b)) for s, b in zip(self.shape, hi)]
        a = np.asarray(self.vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
        a = a.astype(np.float32, copy=True)
        if a.size and not np.all(np.isfinite(a)):
            raise _fail("volume contains NaN or inf values; replace them before segmenting")
        return a

    def strided(self, step: int) -> np.ndarray:
        if step <= 1:
            return self.read((0, 0, 0), self.shape)
        try:
            a = np.asarray(self.vol[::step, ::step, ::step])
        except Exception:
            a = np.stack([np.asarray(self.vol[z])[::step, ::step] for z in range(0, self.shape[0], step)])
        a = a.astype(np.float32)
        if a.size and not np.all(np.isfinite(a)):
            raise _fail("volume contains NaN or inf values; replace them before segmenting")
        return a

    def minmax(self) -> tuple[float, float]:
        lo, hi = np.inf, -np.inf
        step = max(1, int(4e6 // max(1, self.shape[1] * self.shape[2])))
        for z in range(0, self.shape[0], step):
            a = self.read((z, 0, 0), (z + step, self.shape[1], self.shape[2]))
            lo, hi = min(lo, float(a.min())), max(hi, float(a.max()))
        return lo, hi

    def gather(self, zyx: np.ndarray) -> np.ndarray:
        """Raw values (float64) at integer voxel coordinates ``zyx`` (n, 3), all inside the volume."""
        if len(zyx) == 0:
            return np.zeros(0)
        if self.in_memory:
            return self.vol[zyx[:, 0], zyx[:, 1], zyx[:, 2]].astype(np.float64)
        out = np.empty(len(zyx))
        bz, by, bx = self.block
        bid = zyx // np.array(self.block)
        key = (bid[:, 0] * ((self.shape[1] + by - 1) // by) + bid[:, 1]) * ((self.shape[2] + bx - 1) // bx) + bid[:, 2]
        order = np.argsort(key, kind="stable")
        ks = key[order]
        cut = np.flatnonzero(np.diff(ks)) + 1
        for grp in np.split(order, cut):
            b = tuple(int(v) for v in bid[grp[0]])
            blk = self._block(b)
            q = zyx[grp] - np.array(b) * np.array(self.block)
            out[grp] = blk[q[:, 0], q[:, 1], q[:, 2]]
        return out

    def _block(self, b):
        blk = self._cache.pop(b, None)
        if blk is None:
            lo = [i * n for i, n in zip(b, self.block)]
            hi = [min(s, l + n) for s, l, n in zip(self.shape, lo, self.block)]
            blk = np.asarray(self.vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
            used = sum(v.nbytes for v in self._cache.values())
            while self._cache and used + blk.nbytes > self.cache_bytes:
                old = next(iter(self._cache))  # least recently used
                used -= self._cache.pop(old).nbytes
        self._cache[b] = blk  # (re)inserted last: most recently used
        return blk

    def trilinear(self, xyz: np.ndarray) -> np.ndarray:
        """Raw values (float64) interpolated at points (n, 3) given as (x, y, z); NaN outside."""
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        zyx = xyz[:, ::-1]
        hi = np.asarray(self.shape) - 1
        inside = np.all((zyx >= 0) & (zyx <= hi), axis=1)
        out = np.full(len(zyx), np.nan)
        if not inside.any():
            return out
        q = zyx[inside]
        lo = np.minimum(np.floor(q).astype(np.int64), np.maximum(hi - 1, 0))
        f = q - lo
        val = np.zeros(len(q))
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    w = (f[:, 0] if dz else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1]) * \
                        (f[:, 2] if dx else 1 - f[:, 2])
                    idx = np.minimum(lo + np.array([dz, dy, dx]), hi)
                    val += w * self.gather(idx)
        out[inside] = val
        return out


# ----------------------------------------------------------------------------------------------
# small geometry helpers
# ----------------------------------------------------------------------------------------------

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


# ----------------------------------------------------------------------------------------------
# blurred cylinder / capsule model (radial profile, end offsets)
# ----------------------------------------------------------------------------------------------

def _blur_model(t, rho, r, sigma, capsule=True, n_r=40, n_th=48):
    """Gaussian-blurred semi-infinite rod (unit contrast) at axial position t, radial distance rho.

    The rod occupies ``t' <= 0, rho' <= r`` plus, for ``capsule``, a hemispherical cap of radius
    r beyond ``t' = 0``.  ``t = -inf`` gives the blurred disc profile.  Quadrature over the rod's
    cross-section; the axial integral is exact (normal CDF).
    """
    t = np.asarray(t, dtype=np.float64)
    rho = np.asarray(rho, dtype=np.float64)
    t, rho = np.broadcast_arrays(t, rho)
    sigma = max(float(sigma), 1e-3)
    xr, wr = np.polynomial.legendre.leggauss(n_r)
    q = (xr + 1.0) * 0.5 * r
    wq = wr * 0.5 * r
    th = (np.arange(n_th) + 0.5) * (2.0 * np.pi / n_th)
    d2 = rho[..., None, None] ** 2 + q[:, None] ** 2 - 2.0 * rho[..., None, None] * q[:, None] * np.cos(th)
    g = np.exp(-d2 / (2.0 * sigma * sigma)) / (2.0 * np.pi * sigma * sigma)
    if np.all(np.isneginf(t)):
        f = 1.0
    else:
        tcap = np.sqrt(np.maximum(r * r - q * q, 0.0)) if capsule else np.zeros_like(q)
        f = ndtr((tcap[:, None] - t[..., None, None]) / sigma)
    return (g * f * (q * wq)[:, None]).sum(axis=(-1, -2)) * (2.0 * np.pi / n_th)


def _end_weight(rho, rho_e):
    """Smooth radial weight of the end-profile disc: (1 - (rho/rho_e)^2)^2 inside, 0 outside."""
    q = np.clip(1.0 - (np.asarray(rho, dtype=np.float64) / rho_e) ** 2, 0.0, None)
    return q * q


def _fit_radial_profile(rho, v, r0, r_fixed=None):
    """Fit ``C * blurred_disc(rho; r, sigma)`` to binned (rho, v); returns (C, r, sigma)."""
    from scipy.optimize import least_squares

    bins = np.arange(0.0, rho.max() + 0.25, 0.25)
    idx = np.digitize(rho, bins) - 1
    cnt = np.bincount(idx, minlength=len(bins))
    s = np.bincount(idx, weights=v, minlength=len(bins))
    ok = cnt >= 20
    x = (bins + 0.125)[ok]
    y = s[ok] / cnt[ok]
    wts = np.sqrt(cnt[ok])

    def model(p):
        C, r, sg = p[0], (r_fixed if r_fixed is not None else p[1]), p[-1]
        return C * _blur_model(-np.inf, x, r, sg, n_r=24, n_th=32)

    if r_fixed is None:
        p0 = [1.0, r0, 1.0]
        lb, ub = [0.2, 0.3, 0.05], [3.0, 3.0 * r0 + 5, 0.6 * r0 + 5]
    else:
        p0 = [1.0, 1.0]
        lb, ub = [0.2, 0.05], [3.0, 0.6 * r_fixed + 5]
    sol = least_squares(lambda p: (model(p) - y) * wts, p0, bounds=(lb, ub), x_scale="jac")
    if r_fixed is None:
        C, r, sg = sol.x
    else:
        (C, sg), r = sol.x, r_fixed
    return float(C), float(r), float(sg)


# ----------------------------------------------------------------------------------------------
# stage 1: global statistics
# ----------------------------------------------------------------------------------------------

@dataclass
class _Stats:
    bg: float           # background level (raw)
    fg: float           # rod plateau (raw)
    fg_smooth: float    # rod plateau in the smoothed image (detection)
    threshold: float    # binarisation level of the smoothed image
    r0: float
    noise: float
    mixed: bool = False  # radii spread widely (the distance-transform ridge is broad)


def _otsu(values: np.ndarray) -> float:
    from skimage.filters import threshold_otsu
    return float(threshold_otsu(values))


RIDGE_BIAS = 0.55
#: interquartile range of the distance-transform ridge, relative to its median, above which
#: the scan holds mixed radii (one radius: 0.06-0.11 on phantoms of radius 1.5-3; radii 2-5: 0.41)
MIXED_RIDGE_SPREAD = 0.3


def _global_stats(reader: _Reader, P: SegmentParams) -> _Stats:
    shape = reader.shape
    n = float(np.prod(shape))
    step = max(1, int(math.ceil((n / 2.0e6) ** (1.0 / 3.0))))
    sub = reader.strided(step)
    vmin, vmax = float(sub.min()), float(sub.max())
    if vmin == vmax:
        lo, hi = reader.minmax()
        if lo == hi:
            raise _fail(f"volume is constant (every voxel is {lo:g}); nothing to segment")
        sub = reader.read((0, 0, 0), shape) if n <= 3e7 else sub
    # Otsu on a smoothed sample: on raw data a small foreground class (one rod in a big
    # volume) loses to a split of the background noise
    sub = ndimage.gaussian_filter(sub, max(P.smooth_sigma, 1.0))
    T = _otsu(sub.ravel())
    # Otsu also fails when the rods are a tiny fraction of the volume: keep the split above
    # the background noise (the histogram mode plus 5 sigma of its lower half)
    lo_v, hi_v = np.percentile(sub, [0.1, 99.9])
    if hi_v > lo_v:
        hist, edges = np.histogram(sub, bins=512, range=(lo_v, hi_v))
        mode = float(0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1]))
        below = sub[sub < mode]
        if mode < T and below.size > 100:
            sd = math.sqrt(float(np.mean((below - mode) ** 2)))
            if mode + 5.0 * sd < float(sub.max()):
                T = max(T, mode + 5.0 * sd)
    bright = sub > T
    if not bright.any():
        raise _fail(f"no rods found: no voxel brighter than the Otsu threshold {T:g}; {_HINT}")

    # blocks with the most foreground (chosen from the strided sample: same in any chunking)
    B = [min(P.stats_block, s) for s in shape]
    starts = []
    for s, b in zip(shape, B):
        k = int(math.ceil(s / b))
        starts.append(sorted(set(int(round(x)) for x in np.linspace(0, s - b, k))))
    cands = []
    for z0 in starts[0]:
        for y0 in starts[1]:
            for x0 in starts[2]:
                sl = bright[z0 // step:(z0 + B[0]) // step + 1, y0 // step:(y0 + B[1]) // step + 1,
                            x0 // step:(x0 + B[2]) // step + 1]
                cands.append((-float(sl.mean()) if sl.size else 0.0, z0, y0, x0))
    cands.sort()
    blocks = [c[1:] for c in cands[:4] if c[0] < 0]
    data = []
    for z0, y0, x0 in blocks:
        raw = reader.read((z0, y0, x0), (z0 + B[0], y0 + B[1], x0 + B[2]))
        sm = ndimage.gaussian_filter(raw, P.smooth_sigma) if P.smooth_sigma > 0 else raw
        data.append((raw, sm))

    def analyse(level, ridge_too):
        """Raw and smoothed values deep inside, raw values far outside the mask sm > level
        (and, with ``ridge_too``, the distance-transform values at its local maxima)."""
        ridge, inner, inner_s, outer = [], [], [], []
        for raw, sm in data:
            m = sm > level
            if not m.any():
                continue
            outer.append(raw[ndimage.binary_erosion(~m, iterations=4, border_value=1)])
            if not ridge_too:  # the brightest quarter of the mask (smoothed): near the axes
                deep = m & (sm >= np.percentile(sm[m], 75))
            else:
                # the ridge: local maxima of the distance transform (the axes of the rods;
                # unlike a skeleton it does not run along the waist between two rods side by side)
                ein = ndimage.distance_transform_edt(m)
                rg = ein[m & (ein >= 1.0) & (ein >= ndimage.maximum_filter(ein, size=3))]
                if len(rg) == 0:
                    continue
                rg = rg[rg >= 0.5 * np.percentile(rg, 90)]  # not the bumps of a noisy surface
                ridge.append(rg)
                deep = ein >= max(1.0, 0.75 * float(np.median(rg)))
            inner.append(raw[deep])
            inner_s.append(sm[deep])
        if ridge_too and not ridge:
            raise _fail(f"no rods found: the foreground is nowhere thicker than a voxel; {_HINT}")
        cat = (lambda xs: np.concatenate(xs) if xs else np.zeros(0))
        return cat(ridge), cat(inner), cat(inner_s), cat(outer)

    # pass 1 at the Otsu split gives the levels; pass 2 at the half level gives the radius.
    # Detection works on the smoothed image, whose plateau on thin rods is lower than the raw
    # one: its threshold is half-way to the smoothed plateau.
    ridge, inner, inner_s, outer = analyse(T, False)
    fg = float(np.median(inner)) if inner.size >= 50 else float(np.median(sub[bright]))
    fg_s = float(np.median(inner_s)) if inner_s.size >= 50 else fg
    bg = float(np.median(outer)) if outer.size >= 50 else float(np.median(sub[~bright]))
    if not (fg > bg and fg_s > bg):
        raise _fail(f"no rods found: foreground level {fg:g} is not above background {bg:g}; {_HINT}")
    thr = float(P.threshold) if P.threshold is not None else bg + 0.5 * (fg_s - bg)
    ridge, inner, inner_s, outer = analyse(thr, True)
    if inner.size >= 50:
        fg = float(np.median(inner))
        fg_s = float(np.median(inner_s))
    if outer.size >= 50:
        bg = float(np.median(outer))
        noise = 1.4826 * float(np.median(np.abs(outer - bg)))
    else:
        noise = float(np.std(sub[~bright])) if (~bright).any() else 0.0
    if not (fg > bg and fg_s > bg):
        raise _fail(f"no rods found: foreground level {fg:g} is not above background {bg:g}; {_HINT}")
    if P.threshold is None:
        thr = bg + 0.5 * (fg_s - bg)
    if P.diameter is not None:
        r0 = 0.5 * float(P.diameter)
    else:
        # the EDT measures to the nearest outside voxel centre (about half a voxel short) and
        # the half-level surface of the blurred, smoothed rod lies about sigma^2 / 2r inside
        # it (coarse: calibrated on phantoms of radius 3 to 20, blur 1, smoothing 1 and 2)
        m = float(np.median(ridge))
        q25, q75 = (float(v) for v in np.percentile(ridge, [25, 75]))
        # one radius: the ridge spreads by about a voxel's aliasing (< 0.15 of the median);
        # mixed radii: the coarse radius is the lower quartile's, so the thinner rods still
        # fill the fitting discs
        mixed = (q75 - q25) > MIXED_RIDGE_SPREAD * m
        if mixed:
            m = q25
        r0 = max(0.75, m + RIDGE_BIAS - 0.7 * (1.0 + P.smooth_sigma ** 2) / max(m, 1.0))
    return _Stats(bg=bg, fg=fg, fg_smooth=fg_s, threshold=thr, r0=r0, noise=noise,
                  mixed=bool(P.diameter is None and mixed))


# ----------------------------------------------------------------------------------------------
# stage 2: detection in one block
# ----------------------------------------------------------------------------------------------

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


def _dp_split(q: np.ndarray, tol: float) -> list[tuple[int, int]]:
    """Douglas-Peucker: index ranges [a, b] of an ordered polyline whose points stay within tol of the chord."""
    out = []
    stack = [(0, len(q) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            out.append((a, b))
            continue
        d = q[b] - q[a]
        L = float(np.linalg.norm(d))
        w = q[a + 1:b] - q[a]
        if L > 0:
            dist = np.linalg.norm(w - np.outer(w @ d / (L * L), d), axis=1)
        else:
            dist = np.linalg.norm(w, axis=1)
        i = int(np.argmax(dist))
        if dist[i] <= tol:
            out.append((a, b))
        else:
            m = a + 1 + i
            stack.append((m, b))
            stack.append((a, m))
    out.sort()
    return out


def _skeleton_seeds(mask: np.ndarray, r0: float, P: SegmentParams, cut_faces=None, quality=None):
    """Straight skeleton pieces, junction neighbourhoods removed: [(centre, dir, t0, t1, n)] (block xyz).

    ``cut_faces``: per axis (z, y, x) a pair of flags, True where the block face is interior to
    the volume (a chunk border): the skeleton bends along such faces, so voxels near them are
    dropped (the neighbouring chunk sees those parts of the rods).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components
    from scipy.spatial import cKDTree
    from skimage.morphology import skeletonize

    sk = skeletonize(mask)
    idx = np.argwhere(sk)
    if len(idx) == 0:
        return [], 0, 0
    tree = cKDTree(idx)
    nb = tree.query_ball_point(idx, 1.75, return_length=True) - 1
    junc = idx[nb >= 3]
    keep = np.ones(len(idx), bool)
    if len(junc):
        jt = cKDTree(junc)
        d, _ = jt.query(idx, distance_upper_bound=P.junction_radius * r0 + 1.0 + 1e-6)
        keep = ~np.isfinite(d)
    if cut_faces is not None:
        m = r0 + 1.0
        for ax in range(3):
            lo_cut, hi_cut = cut_faces[ax]
            if lo_cut:
                keep &= idx[:, ax] >= m
            if hi_cut:
                keep &= idx[:, ax] <= mask.shape[ax] - 1 - m
    pts = idx[keep]
    if len(pts) == 0:
        return [], len(idx), len(junc)
    pairs = cKDTree(pts).query_pairs(1.75, output_type="ndarray")
    n = len(pts)
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) else \
        coo_matrix((n, n))
    ncomp, lab = connected_components(g, directed=False)
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(ncomp + 1))
    csr = g.tocsr()
    csr = csr + csr.T
    deg = np.diff(csr.indptr)
    tol = max(1.5, 0.5 * r0)
    seeds = []
    bend_stats = [0, 0, 0]
    for k in range(ncomp):
        mem = order[bounds[k]:bounds[k + 1]]
        if len(mem) < P.min_seed_voxels:
            continue
        q = pts[mem][:, ::-1].astype(np.float64)  # xyz
        pieces = [np.arange(len(mem))]
        if len(mem) > 2 * P.min_seed_voxels:
            # a branch may run from one rod into another without a junction (an end touching a
            # side, a block face): order it along the path and split it where it bends
            start = mem[np.lexsort((mem, deg[mem]))[0]]
            path = breadth_first_order(csr, start, directed=False, return_predecessors=False)
            pos = {int(v): i for i, v in enumerate(mem)}
            ordered = np.array([pos[int(v)] for v in path if int(v) in pos])
            pieces = [ordered[a:b + 1] for a, b in _dp_split(q[ordered], tol)]
        if len(mem) >= 8.0 * r0:  # for shape="auto": how much of the skeleton bends
            # (a tolerance of a radius, at least 2 voxels: noise and thin rods wiggle less)
            bend_stats[0] += len(mem)
            pc2 = _dp_split(q[ordered], max(2.0, r0)) if len(pieces) > 1 else []
            if len(pc2) > 1:
                # a skeleton path from one straight rod into another (a crossing, an end on a
                # side) is two chords meeting at a sharp corner; a curve needs more chords, or
                # turns gently between two
                d = np.array([q[ordered[b]] - q[ordered[a]] for a, b in pc2])
                d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
                turn = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", d[1:], d[:-1]), -1.0, 1.0)))
                if len(pc2) >= 3 or turn.max() < 20.0:
                    bend_stats[1] += len(mem)
                    bend_stats[2] += 1
        for idx_p in pieces:
            if len(idx_p) < P.min_seed_voxels:
                continue
            qq = q[idx_p]
            c = qq.mean(0)
            _, _, vt = np.linalg.svd(qq - c, full_matrices=False)
            u = _canonical(vt[0])
            t = (qq - c) @ u
            seeds.append((c, u, float(t.min()), float(t.max()), len(idx_p)))
    # longest first; ties broken by position (deterministic)
    seeds.sort(key=lambda s: (-(s[3] - s[2]), -s[4], tuple(np.round(s[0], 6))))
    if quality is not None:
        quality["_branch_voxels"] = quality.get("_branch_voxels", 0) + bend_stats[0]
        quality["_bent_voxels"] = quality.get("_bent_voxels", 0) + bend_stats[1]
        quality["_bent_branches"] = quality.get("_bent_branches", 0) + bend_stats[2]
    return seeds, len(idx), len(junc)


class _Tracer:
    """Coarse fits and marching on one block's smoothed, normalised image."""

    def __init__(self, g, origin_zyx, r0, P: SegmentParams):
        self.S = _BlockSampler(g, origin_zyx)
        self.r0 = r0
        self.P = P
        self.fit_offs = _disc_offsets(max(r0, 1.0))
        self.probe_offs = _disc_offsets(max(0.5 * r0, 0.75))
        self.mom_offs = _disc_offsets(1.6 * r0 + 1.0)

    mixed = False

    def _slices(self, c, u, ts, offs):
        e1, e2 = _basis(u)
        return (c + ts[:, None, None] * u + offs[None, :, 0, None] * e1 + offs[None, :, 1, None] * e2)

    def fit(self, c, u, t0, t1, n_iter, avoid=None):
        """Centroid/line fit on [t0, t1]; returns (c, u, t0, t1, fill) or None.

        ``avoid``: segments [(p0, p1)] of neighbours; samples nearer to one of them than to
        this axis are ignored (keeps two rods side by side apart).
        """
        offs = self.fit_offs
        rad = np.hypot(offs[:, 0], offs[:, 1])
        for _ in range(n_iter):
            if t1 - t0 < 1.0:
                mid = 0.5 * (t0 + t1)
                t0, t1 = mid - 0.5, mid + 0.5
            ts = np.arange(t0, t1 + 1e-9, 1.0)
            e1, e2 = _basis(u)
            pts = c + ts[:, None, None] * u + offs[None, :, 0, None] * e1 + offs[None, :, 1, None] * e2
            w = self.S(pts)
            w = np.where(np.isfinite(w), np.clip(w, 0.0, 1.0), 0.0)
            for q0, q1 in (avoid or ()):
                d = _point_segment_distance(pts.reshape(-1, 3), q0, q1).reshape(w.shape)
                w = np.where(d < rad[None, :], 0.0, w)
            m = w.sum(1)
            ok = m > 0.25 * len(offs)
            if ok.sum() < 2:
                return None
            a = (w[ok] * offs[:, 0]).sum(1) / m[ok]
            b = (w[ok] * offs[:, 1]).sum(1) / m[ok]
            tt = ts[ok]
            ww = m[ok]
            tm = (ww * tt).sum() / ww.sum()
            dt = tt - tm
            den = (ww * dt * dt).sum()
            am, bm = (ww * a).sum() / ww.sum(), (ww * b).sum() / ww.sum()
            sa = (ww * dt * (a - am)).sum() / den if den > 0 else 0.0
            sb = (ww * dt * (b - bm)).sum() / den if den > 0 else 0.0
            p0, p1 = c + t0 * u, c + t1 * u
            c_new = c + tm * u + am * e1 + bm * e2
            u_new = _unit(u + sa * e1 + sb * e2)
            t0, t1 = (p0 - c_new) @ u_new, (p1 - c_new) @ u_new
            c, u = c_new, u_new
        fill = float(m.sum() / (len(ts) * len(offs)))
        return c, u, float(t0), float(t1), fill

    def march(self, c, u, t0, t1, max_len, avoid=None):
        P = self.P
        B = int(P.march_block)
        for side in (1.0, -1.0):
            while True:
                tend = t1 if side > 0 else t0
                ts = tend + side * np.arange(1, B + 1, dtype=np.float64)
                pts = self._slices(c, u, ts, self.probe_offs)
                v = self.S(pts)
                fill = np.where(np.all(np.isfinite(v), axis=1), v.mean(1), -1.0)
                bad = np.nonzero(fill < P.march_fill)[0]
                k = int(bad[0]) if len(bad) else B
                if side > 0:
                    t1 += k
                else:
                    t0 -= k
                if k < B or (t1 - t0) > max_len:
                    break
                res = self.fit(c, u, t0, t1, 1, avoid)
                if res is None:
                    break
                c, u, t0, t1, _ = res
        return c, u, t0, t1

    def moments(self, c, u, t0, t1):
        """Median over slices of the cross-section second moments (2x2) about the axis."""
        ts = np.arange(t0, t1 + 1e-9, 1.0)
        pts = self._slices(c, u, ts, self.mom_offs)
        w = self.S(pts)
        w = np.where(np.isfinite(w), np.clip(w, 0.0, 1.0), 0.0)
        m = w.sum(1)
        ok = m > 0.25 * len(self.fit_offs)
        if ok.sum() < 1:
            return None
        w, m = w[ok], m[ok]
        o = self.mom_offs
        mx = (w * o[:, 0]).sum(1) / m
        my = (w * o[:, 1]).sum(1) / m
        sxx = (w * o[:, 0] ** 2).sum(1) / m
        syy = (w * o[:, 1] ** 2).sum(1) / m
        sxy = (w * o[:, 0] * o[:, 1]).sum(1) / m
        return np.array([[np.median(sxx), np.median(sxy)], [np.median(sxy), np.median(syy)]]), \
            np.array([np.median(mx), np.median(my)])

    def trace(self, c, u, t0, t1, max_len, avoid=None):
        P = self.P
        res = self.fit(c, u, t0, t1, P.fit_iterations, avoid)
        if res is None:
            return None
        c, u, t0, t1, fill = res
        # a thinner rod fills less of the fitting disc: with mixed radii accept down to a
        # quarter (a rod of half the coarse radius)
        if fill < (0.25 if self.mixed else 0.4):
            return None
        c, u, t0, t1 = self.march(c, u, t0, t1, max_len, avoid)
        res = self.fit(c, u, t0, t1, P.fit_iterations, avoid)
        if res is None:
            return None
        return res


def _lines_cover(lines, pt, radius):
    """True if pt lies within ``radius`` of one of the segments in lines [(p0, p1), ...]."""
    if not lines:
        return False
    A = np.array([l[0] for l in lines])
    Bp = np.array([l[1] for l in lines])
    d = Bp - A
    L2 = np.maximum((d * d).sum(1), 1e-300)
    t = np.clip(((pt - A) * d).sum(1) / L2, 0.0, 1.0)
    dist = np.linalg.norm(pt - A - t[:, None] * d, axis=1)
    return bool(np.any(dist < radius))


def _rasterize(lines, shape_zyx, origin_zyx, radius):
    """Boolean block mask of voxels within ``radius`` (one value, or one per segment) of any segment."""
    cov = np.zeros(shape_zyx, bool)
    o = np.asarray(origin_zyx)
    rad = np.broadcast_to(np.asarray(radius, float), (len(lines),))
    for (p0, p1), R in zip(lines, rad):
        zyx, _, _, _ = _window_voxels(p0[::-1] - o, p1[::-1] - o, float(R), shape_zyx)
        if len(zyx):
            cov[zyx[:, 0], zyx[:, 1], zyx[:, 2]] = True
    return cov


def _detect_block(raw: np.ndarray, origin_zyx, st: _Stats, P: SegmentParams, quality: dict,
                  volume_shape=None):
    """Trace rods in one block; returns a list of (p0, p1) in global xyz."""
    g = ndimage.gaussian_filter(raw, P.smooth_sigma) if P.smooth_sigma > 0 else raw
    scale = 1.0 / (st.fg_smooth - st.bg)  # the smoothed rod plateau is 1
    g = (g - np.float32(st.bg)) * np.float32(scale)
    level = (st.threshold - st.bg) * scale
    mask = g > level
    r0 = st.r0
    tr = _Tracer(g, origin_zyx, r0, P)
    tr.mixed = st.mixed
    max_len = float(np.linalg.norm(raw.shape)) + 2.0
    lines: list[tuple[np.ndarray, np.ndarray]] = []
    cut = None
    if volume_shape is not None:
        cut = [(origin_zyx[a] > 0, origin_zyx[a] + raw.shape[a] < volume_shape[a]) for a in range(3)]
    seeds, n_sk, n_j = _skeleton_seeds(mask, r0, P, cut, quality)
    quality["skeleton_voxels"] = quality.get("skeleton_voxels", 0) + n_sk
    quality["skeleton_junctions"] = quality.get("skeleton_junctions", 0) + n_j
    quality["seeds"] = quality.get("seeds", 0) + len(seeds)
    o_xyz = np.asarray(origin_zyx, float)[::-1]
    raw_s = []
    r_kid = r0
    kid_r: dict[int, float] = {}  # lines traced as rods of a bundle: their own radius

    def cover_radius():
        # a bundle's rods cover only themselves, so that one the fit missed is seeded again
        return np.array([kid_r.get(i, r0) + 1.5 for i in range(len(lines))])

    def _bundle_offsets(c, u, t0, t1):
        """Offsets (k >= 3, 2) of the rods of a bundle around axis c, u, or None."""
        nonlocal r_kid
        from rodwarp.segment_bundles import cross_section, fit_discs, looks_bundled

        if not raw_s:  # the raw block, normalised, sampled only once a bundle is suspected
            raw_s.append(_BlockSampler((raw - np.float32(st.bg)) * np.float32(1.0 / (st.fg - st.bg)), origin_zyx))
        e1, e2 = _basis(u)
        img, g1 = cross_section(raw_s[0], c, u, e1, e2, t0, t1, 2.5 * r0 + 2.0, h=1.0)
        if img is None or not looks_bundled(img, 1.0):
            return None
        fit = fit_discs(img, g1)
        if fit is None or len(fit[0]) < 3:
            return None
        # the kids' own radius (a bundle's binarised outline inflates the coarse one)
        r_kid = min(r0, max(0.75, fit[1]))
        return fit[0]

    def run(seed_list):
        for c, u, t0, t1, _ in seed_list:
            if _lines_cover(lines, c, 0.75 * r0):
                continue
            res = tr.trace(c, u, t0, t1, max_len)
            if res is None:
                continue
            c2, u2, a, b, fill = res
            if b - a < 3.0 * r0:  # a rod crossed sideways is about 2 r long
                continue
            kids_xy = _bundle_offsets(c2, u2, a, b)
            if kids_xy is not None:
                # a bundle: one child per rod, fitted alternately, each ignoring its siblings
                e1, e2 = _basis(u2)
                kids = [(c2 + x * e1 + y * e2, u2, a, b) for x, y in kids_xy]

                def kseg(kd):
                    return (kd[0] + kd[2] * kd[1], kd[0] + kd[3] * kd[1])

                def sibs(i_k):
                    return [kseg(kd) for j, kd in enumerate(kids) if j != i_k and kd is not None]

                # the children are traced with discs of their own radius
                tk = _Tracer(g, origin_zyx, r_kid, P)
                for rnd in range(2):
                    for i_k in range(len(kids)):
                        if kids[i_k] is not None:
                            fk = tk.fit(*kids[i_k], P.fit_iterations, sibs(i_k))
                            kids[i_k] = None if fk is None else fk[:4]
                got = covered = 0
                for i_k in range(len(kids)):
                    if kids[i_k] is None:
                        continue
                    if _lines_cover(lines, kids[i_k][0], 0.75 * r_kid):
                        covered += 1
                        continue
                    ch = tk.trace(*kids[i_k], max_len, sibs(i_k))
                    if ch is None or ch[3] - ch[2] < 3.0 * r_kid or _lines_cover(lines, ch[0], 0.75 * r_kid):
                        continue
                    kids[i_k] = ch[:4]
                    lines.append(kseg(kids[i_k]))
                    kid_r[len(lines) - 1] = r_kid
                    got += 1
                if got:
                    quality["bundles_split"] = quality.get("bundles_split", 0) + 1
                    quality["bundle_rods"] = quality.get("bundle_rods", 0) + got
                    continue
                if covered:  # a bundle traced before, seen again: its middle is no rod
                    continue
            mom = tr.moments(c2, u2, a, b)
            if mom is not None:
                ev, evec = np.linalg.eigh(mom[0])
                if ev[1] - ev[0] > P.split_anisotropy * r0 * r0:
                    # two rods side by side: trace a child on each side (children are not split)
                    e1, e2 = _basis(u2)
                    d2 = evec[0, 1] * e1 + evec[1, 1] * e2
                    off = max(math.sqrt(ev[1] - ev[0]), r0)
                    # the two children are fitted alternately, each ignoring the voxels
                    # nearer to its sibling
                    kids = [(c2 + off * d2, u2, a, b), (c2 - off * d2, u2, a, b)]

                    def seg(kd):
                        return (kd[0] + kd[2] * kd[1], kd[0] + kd[3] * kd[1])

                    for rnd in range(2):
                        for i_k in (0, 1):
                            if kids[i_k] is None or kids[1 - i_k] is None:
                                continue
                            fk = tr.fit(*kids[i_k], P.fit_iterations, [seg(kids[1 - i_k])])
                            kids[i_k] = None if fk is None else fk[:4]
                    got = 0
                    for i_k in (0, 1):
                        if kids[i_k] is None:
                            continue
                        sib = [seg(kids[1 - i_k])] if kids[1 - i_k] is not None else None
                        if _lines_cover(lines, kids[i_k][0], 0.75 * r0):
                            continue
                        ch = tr.trace(*kids[i_k], max_len, sib)
                        if ch is None or ch[3] - ch[2] < 3.0 * r0 or _lines_cover(lines, ch[0], 0.75 * r0):
                            continue
                        kids[i_k] = ch[:4]
                        lines.append(seg(kids[i_k]))
                        got += 1
                    if got:
                        quality["split"] = quality.get("split", 0) + 1
                        continue
            lines.append((c2 + a * u2, c2 + b * u2))

    run([(s[0] + o_xyz, s[1], s[2], s[3], s[4]) for s in seeds])
    for _ in range(P.residual_passes):
        cov = _rasterize(lines, mask.shape, origin_zyx, cover_radius())
        resid = mask & ~cov
        resid = ndimage.binary_erosion(resid, iterations=1)
        lab, nlab = ndimage.label(resid, structure=np.ones((3, 3, 3)))
        if nlab == 0:
            break
        sizes = np.bincount(lab.ravel())
        min_vox = max(10, int(0.5 * math.pi * max(r0 - 1, 0.5) ** 2 * 4 * r0))
        new = []
        objs = ndimage.find_objects(lab)
        for k in range(1, nlab + 1):
            if sizes[k] < min_vox:
                continue
            sl = objs[k - 1]
            q = np.argwhere(lab[sl] == k) + np.array([s.start for s in sl])
            q = q[:, ::-1].astype(np.float64) + o_xyz
            c = q.mean(0)
            _, _, vt = np.linalg.svd(q - c, full_matrices=False)
            u = _canonical(vt[0])
            t = (q - c) @ u
            new.append((c, u, float(t.min()), float(t.max()), len(q)))
        if not new:
            break
        new.sort(key=lambda s: (-(s[3] - s[2]), -s[4], tuple(np.round(s[0], 6))))
        quality["residual_seeds"] = quality.get("residual_seeds", 0) + len(new)
        run(new)
    cov = _rasterize(lines, mask.shape, origin_zyx, cover_radius())
    quality["_fg"] = quality.get("_fg", 0) + int(mask.sum())
    quality["_fg_explained"] = quality.get("_fg_explained", 0) + int((mask & cov).sum())
    return lines


# ----------------------------------------------------------------------------------------------
# voxels around a segment
# ----------------------------------------------------------------------------------------------

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


# ----------------------------------------------------------------------------------------------
# stage 3: merging (pasting and duplicates)
# ----------------------------------------------------------------------------------------------

def _merge_lines(lines, r, angle_deg, dist, gap, dup_radius=0.75, dup_fraction=0.5, filled=None):
    """Union pieces of one rod; returns (merged [(p0, p1)], number of unions, groups).

    Two pieces belong to one rod when either

    * (duplicate) at least ``dup_fraction`` of the shorter one's axis lies within
      ``dup_radius * r`` of the longer one's segment (two distinct rods, even touching ones,
      keep their axes at least 2 r apart), or
    * (pasting) they differ by at most ``angle_deg``, the shorter one's ends lie within
      ``dist`` of the longer one's line, and the gap between their extents along that line is
      at most ``gap`` (and, when there is a gap and ``filled(p, q)`` is given, the image is
      foreground all along it: two collinear rods end to end stay apart).

    A group's line is the principal axis of points spread along all its members (each member
    weighted by its length); its extent covers every member.
    """
    from scipy.spatial import cKDTree

    n = len(lines)
    if n == 0:
        return [], 0, []
    P0 = np.array([l[0] for l in lines], dtype=np.float64)
    P1 = np.array([l[1] for l in lines], dtype=np.float64)
    L = np.linalg.norm(P1 - P0, axis=1)
    U = (P1 - P0) / np.maximum(L, 1e-12)[:, None]
    mid = 0.5 * (P0 + P1)
    parent = np.arange(n)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    nm = 0
    if n > 1:
        from rodwarp.geometry import segment_distance

        reach = float(L.max()) + gap + dist + 2 * r
        pairs = cKDTree(mid).query_pairs(reach, output_type="ndarray")
        if len(pairs):  # only pairs whose segments come close can be one rod
            d = segment_distance(P0[pairs[:, 0]], P1[pairs[:, 0]], P0[pairs[:, 1]], P1[pairs[:, 1]])
            pairs = pairs[d <= max(dist, dup_radius * r, gap) + 1e-9]
        cos_paste = math.cos(math.radians(angle_deg))
        for i, j in pairs:
            c = abs(U[i] @ U[j])
            a, b = (i, j) if (L[i], -i) >= (L[j], -j) else (j, i)
            if np.linalg.norm(mid[a] - mid[b]) > 0.5 * (L[a] + L[b]) + gap + dist + 2 * r:
                continue
            same = False
            ns = max(2, int(math.ceil(L[b])) + 1)
            q = P0[b] + np.linspace(0.0, 1.0, ns)[:, None] * (P1[b] - P0[b])
            # two distinct rods cannot keep their axes within r of each other: coverage decides
            # (whatever the angle: short pieces have unreliable directions)
            dq = _point_segment_distance(q, P0[a], P1[a])
            if np.mean(dq <= dup_radius * r) >= dup_fraction or dq[len(dq) // 2] <= dup_radius * r:
                # (or its middle lies inside the longer one's body: no genuine rod can)
                same = True
            elif c >= cos_paste:
                w = np.stack([P0[b], P1[b]]) - P0[a]
                t = w @ U[a]
                perp = np.linalg.norm(w - t[:, None] * U[a], axis=1)
                if perp.max() <= dist:
                    g = max(t.min() - L[a], -t.max(), 0.0)
                    same = g <= gap
                    if same and g > 0.5 and filled is not None:
                        if t.min() > L[a]:
                            pa, pb = P1[a], np.stack([P0[b], P1[b]])[int(np.argmin(t))]
                        else:
                            pa, pb = P0[a], np.stack([P0[b], P1[b]])[int(np.argmax(t))]
                        same = bool(filled(pa, pb))
            if same:
                ri, rj = find(i), find(j)
                if ri != rj:
                    parent[max(ri, rj)] = min(ri, rj)
                    nm += 1
    groups: dict[int, list[int]] = {}
    for k in range(n):
        groups.setdefault(find(k), []).append(k)
    out, members = [], []
    for root in sorted(groups):
        mem = groups[root]
        members.append(mem)
        if len(mem) == 1:
            out.append((P0[mem[0]].copy(), P1[mem[0]].copy()))
            continue
        # members at an angle to the longest one (junk fitted across the rod, or a fragment
        # with a poor direction) are absorbed without shaping the line
        ref = mem[int(np.argmax(L[mem]))]
        cos_keep = math.cos(math.radians(max(angle_deg, 10.0)))
        mem = [k for k in mem if abs(U[k] @ U[ref]) >= cos_keep]
        pts = np.concatenate([P0[k] + np.linspace(0.0, 1.0, max(2, int(math.ceil(L[k])) + 1))[:, None]
                              * (P1[k] - P0[k]) for k in mem])
        c = pts.mean(0)
        _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
        u = vt[0]
        ends = np.concatenate([P0[mem], P1[mem]])
        t = (ends - c) @ u
        out.append((c + t.min() * u, c + t.max() * u))
    return out, nm, members


# ----------------------------------------------------------------------------------------------
# stage 4: greyscale refinement
# ----------------------------------------------------------------------------------------------

class _Rod:
    __slots__ = ("p0", "p1", "r", "plateau", "resid", "mass", "mass_r", "ok", "why", "prev", "own_r")

    def __init__(self, p0, p1, r):
        self.p0 = np.asarray(p0, float)
        self.p1 = np.asarray(p1, float)
        self.r = float(r)
        self.plateau = np.nan
        self.resid = np.nan
        self.mass = np.nan      # median slab mass per unit length (normalised intensity x voxels^2)
        self.mass_r = np.nan    # radius from the mass: sqrt(mass / (pi C))
        self.ok = True
        self.why = ""
        self.own_r = False

    @property
    def length(self):
        return float(np.linalg.norm(self.p1 - self.p0))


def _inside(o, rod) -> bool:
    """True when the middle of ``o`` lies inside ``rod``'s body: no genuine rod can, so ``o`` is
    a fragment or a fit across ``rod`` and must not take voxels from it."""
    return float(_point_segment_distance((0.5 * (o.p0 + o.p1))[None], rod.p0, rod.p1)[0]) < rod.r


def _neighbours(rods, reach):
    """For each rod, the indices of rods whose segments come within ``reach`` (plus radii)."""
    from scipy.spatial import cKDTree

    from rodwarp.geometry import segment_distance

    n = len(rods)
    nb = [[] for _ in range(n)]
    if n < 2:
        return nb
    P0 = np.array([r.p0 for r in rods])
    P1 = np.array([r.p1 for r in rods])
    R = np.array([r.r for r in rods])
    L = np.linalg.norm(P1 - P0, axis=1)
    mid = 0.5 * (P0 + P1)
    pairs = cKDTree(mid).query_pairs(float(L.max()) + reach + 2 * R.max(), output_type="ndarray")
    if len(pairs) == 0:
        return nb
    i, j = pairs[:, 0], pairs[:, 1]
    d = segment_distance(P0[i], P1[i], P0[j], P1[j])
    hit = d < reach + R[i] + R[j]
    for a, b in zip(i[hit], j[hit]):
        nb[a].append(int(b))
        nb[b].append(int(a))
    return nb


class _Refiner:
    def __init__(self, reader: _Reader, st: _Stats, P: SegmentParams, r_glob: float):
        self.reader = reader
        self.st = st
        self.P = P
        self.C = 1.0          # fitted contrast (plateau) relative to fg - bg
        self.mixed = False    # per-rod radii
        self.sigma = 1.0      # fitted blur
        self.r = r_glob       # global radius
        self.delta = None     # end offset
        self.scale = 1.0 / (st.fg - st.bg)
        # pieces shorter than a rejectable rod do not take voxels from their neighbours
        self.min_len = P.min_length * r_glob

    def _voxels(self, rod: _Rod, ext: float, R: float):
        u = _unit(rod.p1 - rod.p0)
        a = rod.p0 - ext * u
        b = rod.p1 + ext * u
        zyx, t, rho, dist = _window_voxels(a[::-1], b[::-1], R, self.reader.shape)
        t = t - ext
        v = (self.reader.gather(zyx) - self.st.bg) * self.scale
        xyz = zyx[:, ::-1].astype(np.float64)
        return xyz, t, rho, v, u

    def _other_dist(self, rods, nbs, xyz, t, rod, reach):
        """Surface distance to the nearest neighbour, for points whose distance could be below
        ``reach`` (others: inf).  ``t``: the points' axial coordinates along ``rod``."""
        best = np.full(len(xyz), np.inf)
        order = np.argsort(t, kind="stable")
        ts = t[order]
        u = (rod.p1 - rod.p0) / max(rod.length, 1e-12)
        for j in nbs:
            o = rods[j]
            if not o.ok or o.length < self.min_len or _inside(o, rod):
                continue
            # only points whose axial coordinate is near the neighbour's projection can be near it
            tj = ((o.p0 - rod.p0) @ u, (o.p1 - rod.p0) @ u)
            D = reach + o.r
            i0, i1 = np.searchsorted(ts, (min(tj) - D, max(tj) + D))
            if i1 <= i0:
                continue
            sel = order[i0:i1]
            d = _point_segment_distance(xyz[sel], o.p0, o.p1) - o.r
            best[sel] = np.minimum(best[sel], d)
        return best

    def refine_axis(self, rods, k, nbs, collect=None):
        rod = rods[k]
        r = rod.r
        R = r + self.P.window_margin
        xyz, t, rho, v, u = self._voxels(rod, 0.0, R)
        if len(v) == 0:
            rod.ok, rod.why = False, "outside"
            return
        other = self._other_dist(rods, nbs, xyz, t, rod, R)
        own = (rho - r) <= other
        # near a volume face keep only voxels whose mirror image through the axis is inside
        # too, so that the truncated window stays symmetric about the axis
        shp = np.asarray(self.reader.shape[::-1], float)
        pax = rod.p0 + np.clip(t, 0.0, rod.length)[:, None] * u
        mir = 2.0 * pax - xyz
        sym = np.all((mir >= 0.0) & (mir <= shp - 1.0), axis=1)
        own &= sym
        L = rod.length
        # perpendicular slabs of unit width, interior only (away from the caps)
        lo_t, hi_t = 1.0, L - 1.0
        if hi_t - lo_t < 2.0:
            lo_t, hi_t = 0.25 * L, 0.75 * L
        sel = own & (t >= lo_t) & (t <= hi_t)
        vv = np.clip(v, -1.0, 2.0)
        e1, e2 = _basis(u)
        w = xyz - rod.p0
        a = w @ e1
        b = w @ e2
        bins = np.floor(t - lo_t).astype(np.int64)
        nb = int(math.floor(hi_t - lo_t)) + 1
        inside = (t >= lo_t) & (t <= hi_t)
        # slabs whose window disc lies wholly inside the volume (the others give no radius)
        tc = lo_t + np.arange(nb) + 0.5
        pc = rod.p0 + tc[:, None] * u
        full = np.all((pc - R >= -0.5) & (pc + R <= shp - 0.5), axis=1)
        bi = bins[sel]
        ws = vv[sel]
        m = np.bincount(bi, weights=ws, minlength=nb)
        ma = np.bincount(bi, weights=ws * a[sel], minlength=nb)
        mb = np.bincount(bi, weights=ws * b[sel], minlength=nb)
        mt = np.bincount(bi, weights=ws * t[sel], minlength=nb)
        # lattice aliasing: a unit slab holds a varying number of voxels (1 or 2 rows for a
        # rod along a face diagonal); scale each slab's mass by expected / actual voxel count
        n_all = np.bincount(bins[inside & sym], minlength=nb)
        dens = np.where(n_all > 0, math.pi * R * R / np.maximum(n_all, 1), 0.0)
        m_corr = m * dens
        area0 = math.pi * r * r * self.C
        # until a rod has its own radius, a thin one in a scan of mixed radii holds less mass
        # than the global radius promises
        f_min = 0.15 if (self.st.mixed and not getattr(rod, "own_r", False)) else 0.4
        ok = (m_corr > f_min * area0) & (n_all > 0.3 * math.pi * R * R)
        if ok.sum() < 3:
            rod.ok, rod.why = False, "no interior"
            return
        ca, cb, ct, mm = ma[ok] / m[ok], mb[ok] / m[ok], mt[ok] / m[ok], m_corr[ok]
        keep = np.ones(len(ca), bool)
        for _ in range(3):
            W = mm[keep]
            T = ct[keep]
            tm = (W * T).sum() / W.sum()
            dt = T - tm
            den = (W * dt * dt).sum()
            am = (W * ca[keep]).sum() / W.sum()
            bm = (W * cb[keep]).sum() / W.sum()
            sa = (W * dt * (ca[keep] - am)).sum() / den if den > 0 else 0.0
            sb = (W * dt * (cb[keep] - bm)).sum() / den if den > 0 else 0.0
            res = np.hypot(ca - am - sa * (ct - tm), cb - bm - sb * (ct - tm))
            mad = float(np.median(res[keep]))
            new_keep = res <= max(4.0 * 1.4826 * mad, 0.3)
            new_keep &= (mm >= 0.6 * np.median(mm[full[ok]] if full[ok].any() else mm))
            if new_keep.sum() < 3 or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        rod.resid = float(np.sqrt(np.mean(res[keep] ** 2)))
        fk = full[ok][keep]
        rod.mass = max(float(np.median(mm[keep][fk] if fk.any() else mm[keep])), 0.0)
        rod.mass_r = math.sqrt(rod.mass / (math.pi * self.C))
        c = rod.p0 + tm * u + am * e1 + bm * e2
        u_new = _unit(u + sa * e1 + sb * e2)
        t0 = (rod.p0 - c) @ u_new
        t1 = (rod.p1 - c) @ u_new
        rod.p0, rod.p1 = c + t0 * u_new, c + t1 * u_new
        if collect is not None:  # radial profile about the updated axis
            s2 = own & inside
            w2 = xyz[s2] - c
            tt = w2 @ u_new
            rn = np.sqrt(np.maximum(np.einsum("ij,ij->i", w2, w2) - tt * tt, 0.0))
            collect.append((rn, v[s2]))

    def set_end_model(self, r, sigma, capsule):
        """Tabulate the disc-mean axial profile of a blurred rod end (plateau 1, s outward from
        the end: cap centre or flat face) and its half-level offset."""
        rho_e = min(self.P.end_radius, max(0.5, 0.8 * r))
        rr = (np.arange(12) + 0.5) / 12 * rho_e
        w = rr * _end_weight(rr, rho_e)
        w = w / w.sum()
        plateau = float((_blur_model(-np.inf, rr, r, sigma, capsule) * w).sum())
        s_grid = np.linspace(-r - 4.0 * sigma - 2.0, r + 4.0 * sigma + 2.0, 241)
        prof = (_blur_model(s_grid[:, None], rr[None, :], r, sigma, capsule) * w).sum(1) / plateau
        self.end_s, self.end_m = s_grid, prof
        i = int(np.argmax(prof < 0.5))
        f = (prof[i - 1] - 0.5) / (prof[i - 1] - prof[i]) if i > 0 else 0.0
        self.delta = float(s_grid[i - 1] + f * (s_grid[i] - s_grid[i - 1])) if i > 0 else 0.0
        self.end_half_width = r + 3.0 * sigma + 1.0

    def _fit_end(self, centres, prof, weight, plateau, t_guess, side):
        """Least-squares end position: observed bins against the tabulated end profile."""
        from scipy.optimize import minimize_scalar

        sel = np.isfinite(prof) & (weight > 0) & (np.abs(centres - t_guess) <= self.end_half_width)
        if sel.sum() < 4 or not (plateau > 0):
            return t_guess
        c, y, w = centres[sel], prof[sel], weight[sel]

        def cost(te):
            m = np.interp(side * (c - te), self.end_s, self.end_m)
            return float((w * (y - plateau * m) ** 2).sum())

        res = minimize_scalar(cost, bounds=(t_guess - 1.5, t_guess + 1.5), method="bounded",
                              options={"xatol": 1e-4})
        return float(res.x) if res.success else t_guess

    def refine_ends(self, rods, k, nbs):
        rod = rods[k]
        r = rod.r
        rho_e = min(self.P.end_radius, max(0.5, 0.8 * r))
        ext = r + 3.0 * self.sigma + 3.0
        shp = np.asarray(self.reader.shape[::-1], float)
        for attempt in range(6):
            xyz, t, rho, v, u = self._voxels(rod, ext, rho_e)
            L = rod.length
            # inside another rod's body: not ours (ends touching a neighbour's side)
            excl = np.zeros(len(t), bool)
            order = np.argsort(t, kind="stable")
            ts = t[order]
            for j in nbs:
                o = rods[j]
                if not o.ok or o.length < self.min_len or _inside(o, rod):
                    continue
                uo = (o.p1 - o.p0) / o.length
                if abs(float(uo @ u)) > 0.985 and _point_segment_distance(
                        np.stack([o.p0, o.p1]), rod.p0 - 1e3 * u, rod.p1 + 1e3 * u).max() < r:
                    continue  # a collinear piece of this very rod: merged later, not a body
                tj = ((o.p0 - rod.p0) @ u, (o.p1 - rod.p0) @ u)
                D = o.r + 0.5
                i0, i1 = np.searchsorted(ts, (min(tj) - D, max(tj) + D))
                if i1 > i0:
                    sel = order[i0:i1]
                    excl[sel] |= _point_segment_distance(xyz[sel], o.p0, o.p1) < o.r + 0.5
            # unit bins anchored at the foot of the perpendicular from the origin, so that the
            # binning does not depend on where the ends currently are; smooth radial weights
            # and linear (cloud-in-cell) binning make the profile a smooth function of the
            # axis, so that the refinement converges to a reproducible fixed point
            tF = -float(rod.p0 @ u)
            b0 = int(math.floor(-ext - tF))
            nb = int(math.floor(L + ext - tF)) - b0 + 2
            x = t - tF - b0 - 0.5
            k0 = np.floor(x).astype(np.int64)
            f = x - k0
            wr = _end_weight(rho, rho_e)
            cnt = np.zeros(nb)
            cg = np.zeros(nb)
            sv = np.zeros(nb)
            own = (~excl).astype(np.float64)
            for kk, wb in ((k0, 1.0 - f), (k0 + 1, f)):
                inr = (kk >= 0) & (kk < nb)
                kk, ww = kk[inr], (wb * wr)[inr]
                cnt += np.bincount(kk, weights=ww, minlength=nb)
                cg += np.bincount(kk, weights=ww * own[inr], minlength=nb)
                sv += np.bincount(kk, weights=ww * own[inr] * v[inr], minlength=nb)
            mine = cg > 0.2 * np.maximum(cnt, 1e-12)
            prof = np.where(mine, sv / np.maximum(cg, 1e-12), 0.0)
            cg = np.where(mine, cg, 0.0)
            centres = b0 + np.arange(nb) + 0.5 + tF
            # the axis leaves the volume: the rod is cut by the field of view there
            pc = rod.p0 + centres[:, None] * u
            outside = np.any((pc < -0.5) | (pc > shp - 0.5), axis=1) | (cnt <= 0)
            prof = np.where(outside, np.nan, prof)
            inner = (centres > 0.2 * L) & (centres < 0.8 * L) & np.isfinite(prof)
            if inner.sum() < 1:
                inner = (centres > 0) & (centres < L) & np.isfinite(prof)
            if inner.sum() < 1:
                rod.ok, rod.why = False, "no profile"
                return
            plateau = float(np.median(prof[inner]))
            rod.plateau = plateau
            level = 0.5 * plateau
            mid = int(np.argmin(np.abs(centres - 0.5 * L)))
            new_t = []
            extend = False
            for side in (-1, 1):
                i = mid
                found = None
                while 0 <= i + side < nb:
                    j = i + side
                    if not np.isfinite(prof[j]):
                        found = centres[i]  # volume boundary: end at the last voxel inside
                        break
                    nxt = j + side
                    dip = (prof[j] < level and cg[j] > 0 and 0 <= nxt < nb and np.isfinite(prof[nxt])
                           and prof[nxt] >= level)
                    if prof[j] < level and not dip:  # (a single low bin inside a rod is noise)
                        f = (prof[i] - level) / (prof[i] - prof[j]) if prof[i] != prof[j] else 0.5
                        guess = centres[i] + side * f - side * self.delta
                        found = self._fit_end(centres, np.where(cg > 0, prof, np.nan), cg, plateau, guess, side)
                        break
                    i = j
                if found is None:
                    extend = True
                    found = centres[i]
                new_t.append(found)
            t0, t1 = new_t
            if t1 - t0 < 0.5:
                rod.ok, rod.why = False, "collapsed"
                return
            p0 = rod.p0 + t0 * u
            p1 = rod.p0 + t1 * u
            rod.p0, rod.p1 = p0, p1
            if not extend:
                return
            ext *= 2.0

    def contrast_fit(self, collect, r_fixed):
        rho = np.concatenate([c[0] for c in collect]) if collect else np.zeros(0)
        v = np.concatenate([c[1] for c in collect]) if collect else np.zeros(0)
        if len(rho) < 200:
            return
        if len(rho) > 3_000_000:
            sel = np.linspace(0, len(rho) - 1, 3_000_000).astype(np.int64)
            rho, v = rho[sel], v[sel]
        C, r, sg = _fit_radial_profile(rho, v, self.r, r_fixed)
        self.C, self.r, self.sigma = C, r, sg


def _dedupe_rods(rods, P, reasons, filled=None):
    """Drop failed rods (counting reasons) and union duplicates / collinear pieces among the rest."""
    good = []
    for rod in rods:
        if rod.ok:
            good.append(rod)
        else:
            reasons[rod.why] = reasons.get(rod.why, 0) + 1
    if len(good) < 2:
        return good, 0
    r = float(np.median([g.r for g in good]))
    merged, nm, groups = _merge_lines([(g.p0, g.p1) for g in good], r, P.merge_angle,
                                      P.merge_distance * r, P.merge_gap * r, filled=filled)
    if nm == 0:
        return good, 0
    out = []
    for (p0, p1), mem in zip(merged, groups):
        if len(mem) == 1:
            out.append(good[mem[0]])
        else:
            out.append(_Rod(p0, p1, good[mem[0]].r))
    reasons["duplicate"] = reasons.get("duplicate", 0) + nm
    return out, nm


def _gap_filler(reader, st, r):
    """filled(p, q): True when the normalised intensity, averaged over a small disc, stays at
    or above one half all along the segment p-q (a rod continues there)."""
    disc = _disc_offsets(min(1.5, 0.5 * r), 0.5)
    scale = 1.0 / (st.fg - st.bg)

    def filled(p, q):
        d = q - p
        L = float(np.linalg.norm(d))
        if L < 1e-9:
            return True
        u = d / L
        e1, e2 = _basis(u)
        ss = np.linspace(0.0, L, max(2, int(math.ceil(L / 0.5)) + 1))
        pts = p + ss[:, None, None] * u + disc[None, :, 0, None] * e1 + disc[None, :, 1, None] * e2
        v = (reader.trilinear(pts.reshape(-1, 3)) - st.bg) * scale
        v = v.reshape(len(ss), len(disc))
        ok = np.all(np.isfinite(v), axis=1)
        if not ok.any():
            return False
        return bool(np.nanmean(v[ok], axis=1).min() >= 0.5)

    return filled


_LEVELS: dict = {}


def _axis_level(r, sigma, rho_e):
    """Mean of a unit-contrast blurred disc profile over the end-profile disc (the plateau a
    rod of radius r shows under blur sigma; about 1 for thick rods, well below for thin ones)."""
    key = (round(float(r), 2), round(float(sigma), 2), round(float(rho_e), 2))
    if key not in _LEVELS:
        rr = (np.arange(12) + 0.5) / 12 * rho_e
        w = rr * _end_weight(rr, rho_e)
        _LEVELS[key] = float((_blur_model(-np.inf, rr, r, sigma, n_r=24, n_th=32) * w).sum() / w.sum())
    return _LEVELS[key]


def _check_rod(rod, r_glob, C, P, sigma=None, mixed=False):
    """Mark a rod as failed when it is too short, too faint or of the wrong thickness.

    The faint test compares the axis plateau with what a rod of this radius shows under the
    fitted blur (``min_fill`` of it), so thin rods are judged by their own standard, not by
    the plateau of thick ones.  With mixed radii the length and radius tests use the rod's
    own radius and a wide range (0.3 to 3 times the median radius).
    """
    lo_r, hi_r = P.radius_range if not mixed else (min(P.radius_range[0], 0.3), max(P.radius_range[1], 3.0))
    r_own = rod.r if mixed else r_glob
    if rod.ok and rod.length < P.min_length * r_own:
        rod.ok, rod.why = False, "short"
    expect = C
    if sigma is not None:
        expect = C * _axis_level(r_own, sigma, min(P.end_radius, max(0.5, 0.8 * r_own)))
    if rod.ok and np.isfinite(rod.plateau) and rod.plateau < P.min_fill * expect:
        rod.ok, rod.why = False, "faint"
    if rod.ok and np.isfinite(rod.mass) and not (lo_r * r_glob <= math.sqrt(rod.mass / (math.pi * C)) <= hi_r * r_glob):
        rod.ok, rod.why = False, "radius"


def _refine(reader, st, P, lines, progress, quality, reasons):
    """Greyscale refinement until every rod moves less than ``refine_tol`` (at most
    ``refine_iterations`` rounds; a rod is refined again only while it or a neighbour moves)."""
    r_given = 0.5 * P.diameter if P.diameter is not None else None
    rods = [_Rod(a, b, st.r0) for a, b in lines]
    ref = _Refiner(reader, st, P, st.r0)
    cap = P.end_model == "capsule"
    ref.set_end_model(st.r0, 1.0, cap)
    filled = _gap_filler(reader, st, st.r0)
    n_it = P.refine_iterations
    fit_it = 0
    active = set(range(len(rods)))
    n_refined = 0
    it = 0
    for it in range(n_it):
        if progress is not None:
            progress("refine", it, n_it)
        for rod in rods:
            rod.prev = (rod.p0.copy(), rod.p1.copy())
        nbl = _neighbours(rods, 2.0 * P.window_margin + 1.0)
        fit_now = it == fit_it
        if fit_now:
            active = set(range(len(rods)))
        collect = [] if fit_now else None
        for k in sorted(active):
            if rods[k].ok:
                ref.refine_axis(rods, k, nbl[k], collect)
        if fit_now:
            ref.contrast_fit(collect, r_given)
            quality["radius_profile_fit"] = ref.r
            # the radius from the mass per unit length is unbiased by touching neighbours
            # (the nearest-surface partition trades equal leaks); the profile shape is not
            masses = [rod.mass for rod in rods if rod.ok and np.isfinite(rod.mass)]
            if r_given is None and masses:
                ref.r = math.sqrt(float(np.median(masses)) / (math.pi * ref.C))
            ref.min_len = P.min_length * ref.r
            # mixed radii: detected from the ridge, or from the spread of the rods' own radii
            own = np.array([math.sqrt(rod.mass / (math.pi * ref.C)) for rod in rods
                            if rod.ok and np.isfinite(rod.mass) and rod.mass > 0])
            cv = 1.4826 * float(np.median(np.abs(own - np.median(own)))) / float(np.median(own)) if own.size >= 3 \
                else 0.0
            quality["radius_cv"] = cv
            if P.per_rod_radius is None:
                ref.mixed = r_given is None and (st.mixed or cv > MIXED_RADIUS_CV)
            else:
                ref.mixed = bool(P.per_rod_radius) and r_given is None
            for rod in rods:
                rod.r = ref.r
                if ref.mixed and np.isfinite(rod.mass) and rod.mass > 0:
                    rod.r = float(np.clip(math.sqrt(rod.mass / (math.pi * ref.C)), 0.5, 3.0 * ref.r))
                    rod.own_r = True
            ref.set_end_model(ref.r, ref.sigma, cap)
        nbl = _neighbours(rods, 2.0 * P.window_margin + 1.0)
        for k in sorted(active):
            if rods[k].ok:
                ref.refine_ends(rods, k, nbl[k])
        n_refined += len(active)
        if it >= fit_it:
            for k in active:
                _check_rod(rods[k], ref.r, ref.C, P, ref.sigma, ref.mixed)
                if ref.mixed and rods[k].ok and np.isfinite(rods[k].mass) and rods[k].mass > 0:
                    rods[k].r = float(np.clip(math.sqrt(rods[k].mass / (math.pi * ref.C)), 0.5, 3.0 * ref.r))
                    rods[k].own_r = True
        moved = {}
        for k, rod in enumerate(rods):
            if k in active:
                moved[id(rod)] = max(float(np.linalg.norm(rod.p0 - rod.prev[0])),
                                     float(np.linalg.norm(rod.p1 - rod.prev[1])))
        old_ids = {id(rod) for rod in rods}
        rods, nm = _dedupe_rods(rods, P, reasons, filled)
        # next round: rods that moved, new (merged) rods, and the neighbours of either
        hot = [k for k, rod in enumerate(rods)
               if id(rod) not in old_ids or moved.get(id(rod), 0.0) > P.refine_tol]
        if it + 1 < n_it and hot:
            nbl = _neighbours(rods, 2.0 * P.window_margin + 1.0)
            active = set(hot)
            for k in hot:
                active.update(nbl[k])
        elif it >= fit_it + 1 and not hot:
            break
        else:
            active = set(range(len(rods)))
    if progress is not None:
        progress("refine", n_it, n_it)
    quality["refine_rounds"] = it + 1
    quality["rod_refinements"] = n_refined
    quality["contrast_fit"] = ref.C
    quality["blur_sigma"] = ref.sigma
    quality["end_offset"] = ref.delta
    return rods, ref


# ----------------------------------------------------------------------------------------------
# stage 5: contacts
# ----------------------------------------------------------------------------------------------

def _contacts(rods_out: RodSet, reader: _Reader, st: _Stats, C: float, P: SegmentParams, sigma=None):
    from rodwarp.geometry import detect_contacts, segment_closest_params

    cand = detect_contacts(rods_out, tolerance=P.contact_tolerance)
    if len(cand) == 0:
        return cand, 0
    keep = np.zeros(len(cand), bool)
    scale = 1.0 / ((st.fg - st.bg) * C)
    disc = _disc_offsets(1.0, 0.5)
    for k in range(len(cand)):
        i, j = int(cand.rod_i[k]), int(cand.rod_j[k])
        a0, a1 = rods_out.rod(i)[0], rods_out.rod(i)[-1]
        b0, b1 = rods_out.rod(j)[0], rods_out.rod(j)[-1]
        s, t = segment_closest_params(a0, a1, b0, b1)
        pa = a0 + float(s) * (a1 - a0)
        pb = b0 + float(t) * (b1 - b0)
        d = pb - pa
        dist = float(np.linalg.norm(d))
        if dist < 1e-9:
            keep[k] = True
            continue
        n = d / dist
        ri, rj = rods_out.radii[i], rods_out.radii[j]
        # positions between the two surfaces (at least the midpoint)
        s0, s1 = min(ri, dist - rj), max(ri, dist - rj)
        ss = np.unique(np.concatenate([np.arange(s0, s1 + 1e-9, 0.5), [0.5 * (s0 + s1)]]))
        e1, e2 = _basis(n)
        pts = pa + ss[:, None, None] * n + disc[None, :, 0, None] * e1 + disc[None, :, 1, None] * e2
        val = reader.trilinear(pts.reshape(-1, 3))
        if not np.all(np.isfinite(val)):
            keep[k] = True  # at the border: trust geometry
            continue
        val = (val - st.bg) * scale
        prof = val.reshape(len(ss), len(disc)).mean(1)
        # thin rods are dimmer under blur, and so is the contact between two of them
        lv = 1.0 if sigma is None else min(1.0, _axis_level(min(ri, rj), sigma, min(P.end_radius, max(0.5, 0.8 * min(ri, rj)))))
        keep[k] = bool(prof.min() >= P.contact_min_fill * lv)
    rejected = int((~keep).sum())
    return Contacts(cand.rod_i[keep], cand.rod_j[keep], cand.point[keep], cand.gap[keep]), rejected


# ----------------------------------------------------------------------------------------------
# driver
# ----------------------------------------------------------------------------------------------

def _chunks(shape, chunk, halo):
    if chunk is None:
        yield (0, 0, 0), tuple(shape), (0, 0, 0), tuple(shape)
        return
    starts = [list(range(0, s, chunk)) for s in shape]
    for z in starts[0]:
        for y in starts[1]:
            for x in starts[2]:
                clo = (z, y, x)
                chi = tuple(min(s, a + chunk) for s, a in zip(shape, clo))
                blo = tuple(max(0, a - halo) for a in clo)
                bhi = tuple(min(s, b + halo) for s, b in zip(shape, chi))
                yield clo, chi, blo, bhi


def segment_volume(volume, params: SegmentParams | None = None,
                   progress: Callable[[str, int, int], None] | None = None, *,
                   voxel_size=None) -> SegmentResult:
    """Segment straight rods and their contacts from a greyscale CT volume.

    Parameters
    ----------
    volume : ndarray or array-like (z, y, x)
        Any numeric dtype; bright rods on a darker background.  Array-likes (zarr, a lazy TIFF
        stack) need ``.shape`` and NumPy slicing; with ``params.chunk`` set they are read one
        chunk (and later one rod neighbourhood) at a time.
    params : SegmentParams, optional
        Knobs; defaults meet the phantom targets (radius 3, blur 1, contrast-to-noise >= 5).
    progress : callable(stage, done, total), optional
        Called as stages advance (``"stats"``, ``"detect"``, ``"merge"``, ``"refine"``,
        ``"contacts"``).
    voxel_size : float or sequence of 3 floats, optional
        Voxel edge (one value) or edges along (z, y, x), any unit.  Anisotropic volumes are
        resampled onto an isotropic grid of the smallest edge first
        (:mod:`rodwarp.segment_prep`); the result's coordinates are in units of that edge
        (``SegmentResult.spacing``), with voxel (0, 0, 0) at the origin.

    Returns
    -------
    SegmentResult
        ``quality`` holds: ``fit_residual`` (mean RMS of slab centroids about the fitted axes,
        voxels), ``foreground_explained`` (fraction of binarised foreground within r + 1.5 of a
        traced rod), ``rods_rejected`` (by reason), ``candidates``, ``merged``, ``seeds``,
        ``skeleton_junctions``, ``background``/``foreground`` levels, ``cnr`` (estimated),
        ``contrast_fit``, ``blur_sigma``, ``radius_spread`` (std of per-rod radii),
        ``contacts_rejected_by_image``.

    Raises
    ------
    RodwarpError
        One line: not 3-D, empty, constant, non-finite, or no rods found.
    """
    P = params if params is not None else SegmentParams()
    if not isinstance(P, SegmentParams):
        raise _fail(f"params must be a SegmentParams, got {type(P).__name__}")
    P.validate()
    t_all = time.perf_counter()
    timings: dict[str, float] = {}
    quality: dict = {}

    def note(stage, done, total):
        if progress is not None:
            progress(stage, done, total)

    from rodwarp.segment_prep import _Corrected, prepare_volume

    tic = time.perf_counter()
    _Reader(volume)  # shape and dtype checks first, with their own messages
    prep = prepare_volume(volume, voxel_size, dark=P.dark, fov=P.fov, background=P.background, quality=quality)
    vol = prep.volume
    if isinstance(vol, _Corrected) and isinstance(volume, np.ndarray):
        vol = vol[:, :, :]  # in memory anyway: gathers from an array are much faster
    reader = _Reader(vol)
    timings["prepare"] = time.perf_counter() - tic
    tic = time.perf_counter()
    note("stats", 0, 1)
    st = _global_stats(reader, P)
    note("stats", 1, 1)
    timings["stats"] = time.perf_counter() - tic
    noise = prep.notes.get("noise") or st.noise
    quality.update(background=st.bg, foreground=st.fg, threshold=st.threshold,
                   cnr=(st.fg - st.bg) / noise if noise > 0 else float("inf"),
                   coarse_radius=st.r0)
    if P.shape == "curved":
        return _finish_curved(reader, st, P, quality, timings, t_all, prep, progress)

    # detection
    tic = time.perf_counter()
    halo = P.chunk_halo if P.chunk_halo is not None else \
        int(max(math.ceil(4 * P.smooth_sigma) + 2, math.ceil(3 * st.r0) + 2))
    chunks = list(_chunks(reader.shape, P.chunk, halo))
    lines = []
    for ci, (clo, chi, blo, bhi) in enumerate(chunks):
        raw = reader.read(blo, bhi)
        got = _detect_block(raw, blo, st, P, quality, reader.shape)
        lines.extend(got)
        note("detect", ci + 1, len(chunks))
    timings["detect"] = time.perf_counter() - tic
    fg_tot = quality.pop("_fg", 0)
    quality["foreground_explained"] = quality.pop("_fg_explained", 0) / fg_tot if fg_tot else 0.0
    quality["candidates"] = len(lines)
    bv = quality.pop("_branch_voxels", 0)
    quality["bend_fraction"] = quality.pop("_bent_voxels", 0) / bv if bv else 0.0
    quality["bent_branches"] = quality.pop("_bent_branches", 0)
    # (below a contrast-to-noise of 1.5 the skeleton of the noise itself bends: stay straight)
    if P.shape == "auto" and quality["bend_fraction"] > AUTO_BEND_FRACTION and quality["bent_branches"] >= 3 \
            and quality["cnr"] >= 1.5:
        quality["shape"] = "curved"
        return _finish_curved(reader, st, P, quality, timings, t_all, prep, progress)
    quality["shape"] = "straight"
    if not lines:
        raise _fail(f"no rods found: {quality.get('seeds', 0)} skeleton seeds gave no rod-like "
                    f"fit (coarse radius {st.r0:.2f} voxels); {_HINT}")

    # merge
    tic = time.perf_counter()
    lines, nm, _ = _merge_lines(lines, st.r0, P.merge_angle, P.merge_distance * st.r0, P.merge_gap * st.r0,
                                filled=_gap_filler(reader, st, st.r0))
    quality["merged"] = nm
    note("merge", 1, 1)
    timings["merge"] = time.perf_counter() - tic

    # refine
    tic = time.perf_counter()
    reasons: dict[str, int] = {}
    if P.refine_iterations > 0:
        rods, ref = _refine(reader, st, P, lines, progress, quality, reasons)
        r_glob = ref.r
        C = ref.C
        sigma_fit, mixed = ref.sigma, ref.mixed
    else:
        rods = [_Rod(a, b, st.r0) for a, b in lines]
        r_glob, C = st.r0, 1.0
        sigma_fit, mixed = None, False
        for rod in rods:  # coarse ends run out to the half level of a cap: pull them back
            if P.end_model == "capsule":  # (0.55 r measured on phantoms, blur 1, smoothing 1)
                u = _unit(rod.p1 - rod.p0)
                if rod.length > 2 * r_glob:
                    rod.p0, rod.p1 = rod.p0 + 0.55 * r_glob * u, rod.p1 - 0.55 * r_glob * u
    quality["per_rod_radius"] = bool(mixed)
    for rod in rods:
        _check_rod(rod, r_glob, C, P, sigma_fit, mixed)
        if not rod.ok:
            reasons[rod.why] = reasons.get(rod.why, 0) + 1
    good = [r for r in rods if r.ok]
    timings["refine"] = time.perf_counter() - tic
    quality["rods_rejected"] = reasons
    if not good:
        why = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items()))
        raise _fail(f"no rods found: all {quality['candidates']} candidate(s) rejected ({why}); {_HINT}")

    # output rod set (deterministic order and orientation)
    polys, radii, res, mr = [], [], [], []
    for rod in good:
        u = rod.p1 - rod.p0
        if _canonical(u) is not u:
            rod.p0, rod.p1 = rod.p1, rod.p0
    good.sort(key=lambda r: tuple(np.round(0.5 * (r.p0 + r.p1), 3)[::-1]))
    for rod in good:
        rod.mass_r = math.sqrt(rod.mass / (math.pi * C)) if np.isfinite(rod.mass) else np.nan
        polys.append(np.stack([rod.p0, rod.p1]))
        radii.append(rod.mass_r if (mixed and np.isfinite(rod.mass_r)) else r_glob)
        res.append(rod.resid)
        mr.append(rod.mass_r)
    out = RodSet.from_polylines(polys, np.asarray(radii), units="voxel")
    quality["fit_residual"] = float(np.nanmean(res)) if np.any(np.isfinite(res)) else float("nan")
    quality["radius_spread"] = float(np.nanstd(mr)) if np.any(np.isfinite(mr)) else float("nan")

    tic = time.perf_counter()
    contacts, rej = _contacts(out, reader, st, C, P, sigma_fit)
    out.contacts = contacts
    quality["contacts_rejected_by_image"] = rej
    note("contacts", 1, 1)
    timings["contacts"] = time.perf_counter() - tic
    timings["total"] = time.perf_counter() - t_all
    out.attrs = {"source": "rodwarp.segment", "diameter_voxels": 2 * r_glob,
                 "params": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(P).items()}}
    _flags(quality, "straight")
    return SegmentResult(rods=out, contacts=contacts, diameter=2.0 * r_glob, timings=timings, quality=quality,
                         spacing=prep.spacing)


#: ``shape="auto"`` traces filaments when more than this share of the long skeleton branches
#: (and at least 3 of them) bends smoothly away from its chord (straight packings: below 0.1,
#: arcs and wires: above 0.5)
AUTO_BEND_FRACTION = 0.3
#: robust coefficient of variation of the rods' own radii above which radii are per rod
#: (one radius at CNR 2-5: below 0.05)
MIXED_RADIUS_CV = 0.1


def _finish_curved(reader, st, P, quality, timings, t_all, prep, progress):
    """The curved-filament path of :func:`segment_volume` (polylines, per-filament radii)."""
    from rodwarp.geometry import detect_contacts
    from rodwarp.segment_curved import _resample, trace_filaments

    quality["shape"] = "curved"
    tic = time.perf_counter()
    raw = reader.read((0, 0, 0), reader.shape)
    polys, radii = trace_filaments(raw, st, P, quality, progress)
    timings["detect"] = timings.get("detect", 0.0) + time.perf_counter() - tic
    if not polys:
        raise _fail(f"no filaments found: {quality.get('branches', 0)} skeleton branches gave no filament longer "
                    f"than {P.min_length:g} radii (coarse radius {st.r0:.2f} voxels); {_HINT}")
    tic = time.perf_counter()
    # vertices every 2 voxels (or the radius): enough for the curvature a skeleton resolves
    step = max(2.0, 0.75 * st.r0)
    polys = [_resample(p, step) for p in polys]
    key = [tuple(np.round(p.mean(0), 3)[::-1]) for p in polys]
    order = sorted(range(len(polys)), key=lambda k: key[k])
    polys = [polys[k] for k in order]
    radii = np.asarray(radii)[order]
    out = RodSet.from_polylines(polys, radii, units="voxel")
    contacts = detect_contacts(out, tolerance=P.contact_tolerance)
    out.contacts = contacts
    r_glob = float(np.median(radii))
    quality["radius_spread"] = float(np.std(radii))
    timings["contacts"] = time.perf_counter() - tic
    timings["total"] = time.perf_counter() - t_all
    out.attrs = {"source": "rodwarp.segment", "shape": "curved", "diameter_voxels": 2 * r_glob,
                 "params": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(P).items()}}
    _flags(quality, "curved")
    return SegmentResult(rods=out, contacts=contacts, diameter=2.0 * r_glob, timings=timings, quality=quality,
                         spacing=prep.spacing)


def _flags(quality: dict, shape: str) -> None:
    """Quality flags: short sentences naming what makes the output untrustworthy (empty: none)."""
    flags = []
    fe = quality.get("foreground_explained")
    if fe is not None and fe < 0.9:
        flags.append(f"only {100 * fe:.0f}% of the foreground lies near a traced rod: rods may be missing "
                     f"(bundles, curved filaments: try --shape curved) or the background is uneven")
    res = quality.get("fit_residual")
    if res is not None and np.isfinite(res) and res > 0.75:
        flags.append(f"mean fit residual {res:.2f} voxels: axes do not follow the image (curved rods? "
                     f"try --shape curved)")
    rej = quality.get("rods_rejected") or {}
    n_rej = sum(v for k, v in rej.items() if k != "duplicate")
    cand = quality.get("candidates") or 0
    if cand and n_rej > 0.3 * cand:
        why = ", ".join(f"{k} {v}" for k, v in sorted(rej.items()) if k != "duplicate")
        flags.append(f"{n_rej} of {cand} candidates rejected ({why}): check --diameter and the contrast")
    if shape == "straight" and quality.get("bend_fraction", 0.0) > 0.15:
        flags.append(f"{100 * quality['bend_fraction']:.0f}% of the skeleton bends: the rods may be curved "
                     f"(--shape curved)")
    cnr = quality.get("cnr")
    if cnr is not None and np.isfinite(cnr) and cnr < 1.5:
        flags.append(f"contrast-to-noise {cnr:.1f} is below 1.5: expect missed rods and false contacts")
    quality["flags"] = flags


# ----------------------------------------------------------------------------------------------
# scoring against a ground truth
# ----------------------------------------------------------------------------------------------

@dataclass
class RodMatch:
    """One-to-one matching of found rods to true rods (see :func:`match_rods`).

    Attributes
    ----------
    pairs : (M, 2) int
        ``(found index, true index)`` of every match.
    mean_distance : (M,) float
        Mean distance of the found centreline to the true axis, per match (voxels or the sets'
        unit).
    angle_deg : (M,) float
        Angle between the found and true axes, per match.
    endpoint_error : (M,) float
        Larger of the two endpoint distances (ends paired to minimise it), per match.
    precision, recall, f1 : float
        Rod detection scores.
    """

    pairs: np.ndarray
    mean_distance: np.ndarray
    angle_deg: np.ndarray
    endpoint_error: np.ndarray
    n_found: int
    n_true: int
    precision: float
    recall: float
    f1: float

    def mapping(self) -> dict[int, int]:
        """found index -> true index."""
        return {int(a): int(b) for a, b in self.pairs}


def _ends(rods: RodSet):
    o = rods.offsets
    return rods.points[o[:-1]], rods.points[o[1:] - 1]


def _polyline_samples(poly, s):
    """Points at arc-length fractions s (in [0, 1]) along a polyline."""
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 0:
        return np.repeat(poly[:1], len(s), axis=0)
    q = np.interp(s * cum[-1], cum, np.arange(len(poly), dtype=np.float64))
    k = np.minimum(q.astype(int), len(poly) - 2)
    f = (q - k)[:, None]
    return poly[k] * (1 - f) + poly[k + 1] * f


def _dist_to_polyline(pts, poly):
    """Distance from points (n,3) to a polyline (m,3)."""
    best = np.full(len(pts), np.inf)
    for a, b in zip(poly[:-1], poly[1:]):
        np.minimum(best, _point_segment_distance(pts, a, b), out=best)
    return best


def match_rods(found: RodSet, truth: RodSet, max_mean_distance: float = 2.0,
               max_angle_deg: float = 5.0, n_samples: int = 21) -> RodMatch:
    """Match found rods to true rods one-to-one.

    A found rod may match a true rod when the mean distance of ``n_samples`` points spread
    evenly along the found centreline to the true centreline (polyline) is at most
    ``max_mean_distance`` and the angle between their end-to-end axes is at most
    ``max_angle_deg``.  Among admissible pairs the assignment (Hungarian algorithm) minimises
    the total of the symmetric mean distance (found-to-true and true-to-found averaged), so a
    whole rod is preferred to a fragment of it.  ``mean_distance`` reports found-to-true.
    Both sets must be in the same units.
    """
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    nf, nt = found.n_rods, truth.n_rods
    fa, fb = _ends(found)
    ta, tb = _ends(truth)
    fu = fb - fa
    tu = tb - ta
    fL = np.linalg.norm(fu, axis=1)
    tL = np.linalg.norm(tu, axis=1)
    fmid, tmid = 0.5 * (fa + fb), 0.5 * (ta + tb)
    s = np.linspace(0.0, 1.0, n_samples)
    cost = np.full((nf, nt), np.inf)
    both = np.full((nf, nt), np.inf)
    ang = np.full((nf, nt), np.inf)
    tpts = [_polyline_samples(truth.rod(j), s) for j in range(nt)]
    tree = cKDTree(tmid)
    reach = 0.5 * (fL.max() + tL.max()) + max_mean_distance + 1e-9 if nf and nt else 0.0
    for i in range(nf):
        poly_f = found.rod(i)
        pts = _polyline_samples(poly_f, s)
        for j in sorted(tree.query_ball_point(fmid[i], reach)):
            c = abs(fu[i] @ tu[j]) / max(fL[i] * tL[j], 1e-300)
            a = math.degrees(math.acos(min(1.0, c)))
            if a > max_angle_deg:
                continue
            d = float(_dist_to_polyline(pts, truth.rod(j)).mean())
            if d <= max_mean_distance:
                cost[i, j] = d
                ang[i, j] = a
                # the assignment also weighs how much of the true rod is covered, so that a
                # whole rod beats a short fragment of it
                both[i, j] = 0.5 * (d + float(_dist_to_polyline(tpts[j], poly_f).mean()))
    big = 1e9
    cm = np.where(np.isfinite(both), both, big)
    if nf and nt:
        ri, ci = linear_sum_assignment(cm)
        ok = np.isfinite(cost[ri, ci])
        ri, ci = ri[ok], ci[ok]
    else:
        ri = ci = np.zeros(0, int)
    pairs = np.stack([ri, ci], 1).astype(np.int64) if len(ri) else np.zeros((0, 2), np.int64)
    e1 = np.maximum(np.linalg.norm(fa[ri] - ta[ci], axis=1), np.linalg.norm(fb[ri] - tb[ci], axis=1))
    e2 = np.maximum(np.linalg.norm(fa[ri] - tb[ci], axis=1), np.linalg.norm(fb[ri] - ta[ci], axis=1))
    m = len(pairs)
    prec = m / nf if nf else 0.0
    rec = m / nt if nt else 0.0
    f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
    return RodMatch(pairs=pairs, mean_distance=cost[ri, ci], angle_deg=ang[ri, ci],
                    endpoint_error=np.minimum(e1, e2), n_found=nf, n_true=nt,
                    precision=prec, recall=rec, f1=f1)


@dataclass
class ContactScore:
    """Contact detection scores (see :func:`score_contacts`)."""

    tp: int
    fp: int
    fn: int
    ignored: int
    precision: float
    recall: float
    f1: float


def score_contacts(found_contacts: Contacts, truth: RodSet, match: RodMatch,
                   truth_contacts: Contacts | None = None, touch_tol: float = 1e-3,
                   ambiguous: tuple = (0.0, 1.0)) -> ContactScore:
    """Score found contacts against the true contacts through a rod matching.

    True contacts are the true rod pairs with surface gap <= ``touch_tol`` (from
    ``truth_contacts``, else ``truth.contacts``, else computed from the true geometry).  Pairs
    whose true gap lies in the open interval ``ambiguous`` (default (0, 1) voxel: unresolvable)
    are scored apart: a found contact there is neither a hit nor a false alarm.  A found contact
    on a rod that matched no true rod is a false positive; a true contact on an unmatched true
    rod is a miss.
    """
    from rodwarp.geometry import detect_contacts

    tc = truth_contacts if truth_contacts is not None else truth.contacts
    geo = detect_contacts(truth, tolerance=max(ambiguous[1], touch_tol) + 1e-9)
    if tc is None:
        tc = geo
    true_pairs = {(int(a), int(b)) for a, b, g in zip(tc.rod_i, tc.rod_j, tc.gap) if g <= touch_tol}
    amb = {(int(a), int(b)) for a, b, g in zip(geo.rod_i, geo.rod_j, geo.gap)
           if ambiguous[0] < g < ambiguous[1] and g > touch_tol}
    amb -= true_pairs
    mp = match.mapping()
    tp = fp = ign = 0
    hit = set()
    for a, b in zip(found_contacts.rod_i, found_contacts.rod_j):
        a, b = int(a), int(b)
        if a not in mp or b not in mp:
            fp += 1
            continue
        p = (min(mp[a], mp[b]), max(mp[a], mp[b]))
        if p in true_pairs:
            if p not in hit:
                tp += 1
                hit.add(p)
        elif p in amb:
            ign += 1
        else:
            fp += 1
    fn = len(true_pairs) - len(hit)
    prec = tp / (tp + fp) if tp + fp else (1.0 if not true_pairs else 0.0)
    rec = tp / (tp + fn) if tp + fn else 1.0
    f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
    return ContactScore(tp=tp, fp=fp, fn=fn, ignored=ign, precision=prec, recall=rec, f1=f1)
