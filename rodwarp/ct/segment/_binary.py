"""Binarised stacks: a scan already thresholded to two grey levels, segmented from its mask.

Many CT stacks are shared binarised (bool, 0/1, 0/255 or any two values).  Such a stack has
no blur, no noise and no trend, and the corrections and fits of a greyscale scan misread it
(the constant corners look like a field-of-view mask, the profile fits see a blur of a
fraction of a voxel).  This module recognises it and gives the stages what they need:

* :func:`read_binarised` counts the stack's distinct values: a strided sample first (a
  greyscale scan shows thousands and is passed on at once), then every voxel.  Exactly two
  values make a binarised stack, the brighter one the rods unless ``dark``; one value, a
  handful (a label image), or a rod level that holds almost nothing or almost everything is
  refused with a one-line error that says what to pass instead.
* :func:`mask_of` is the stack as the rods' mask (1.0 rods, 0.0 background, float32; lazy
  for a lazy stack): preparation has nothing to correct, and resamples anisotropic voxels
  through the mask's signed distance (:func:`resample_mask`).
* :func:`mask_levels` is stage ``stats`` for a mask: the levels are known (0 and 1, no noise); the
  coarse radius comes from the mask's distance transform, the tracer's threshold from the
  smoothed mask, so detection runs as for a greyscale scan.
* :class:`SurfaceDistance` and :func:`surface_radius` give the refinement a rod's radius from
  the distance transforms of the mask and of its complement instead of the blurred-profile
  fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from rodwarp._util import one_line_error as _fail

__all__ = ["Binarised", "read_binarised", "mask_of", "resample_mask", "mask_levels", "SurfaceDistance",
           "surface_radius", "MASK_EDGE_SIGMA", "MAX_LABEL_LEVELS"]

#: most distinct values a stack may hold and still be read as discrete levels: a label image
#: or a posterised scan holds a handful, a greyscale scan (noise on every voxel) thousands
MAX_LABEL_LEVELS = 8

#: fewest voxels the rods' level must hold: one rod of radius 1 voxel and the shortest length
#: segmentation keeps (4 radii, ``SegmentParams.min_length``, plus two caps) takes about 25
MIN_ROD_VOXELS = 25

#: largest share of the volume the rods' level may fill: beyond it no background is left to
#: tell rods apart (dense packings of straight rods stay well below; a mask saved the other
#: way round, rods 0 and background 1, is far above)
MAX_ROD_FRACTION = 0.9

#: share above which the rods' level more likely is the background: a warning, not a refusal
LIKELY_INVERTED_FRACTION = 0.5

#: blur (voxels) that stands in for a mask's edge where the stages model one (end profiles,
#: the faint test, contact confirmation): a step sampled on unit voxels spreads like a uniform
#: kernel one voxel wide, whose standard deviation is 1 / sqrt(12)
MASK_EDGE_SIGMA = 1.0 / math.sqrt(12.0)

#: voxels per read while counting the levels of a stack
_SLAB_VOXELS = 4_000_000

#: voxels the strided sample holds (a greyscale scan shows more than MAX_LABEL_LEVELS values)
_SAMPLE_VOXELS = 1_000_000


def _plain(v) -> int | float:
    """A level as JSON shows it: an integer when it is one (bool, integer dtypes, 0.0/1.0)."""
    f = float(v)
    return int(f) if f.is_integer() else f


def _fmt(v) -> str:
    return f"{_plain(v)}"


@dataclass(frozen=True)
class Binarised:
    """A stack of exactly two grey levels and which of them is the rods.

    Attributes
    ----------
    levels : (float, float)
        The two values as stored (lower, higher; bool as 0 and 1).
    rods_dark : bool
        The rods are the lower level (``--dark-rods``); otherwise the higher.
    rod_fraction : float
        Share of the voxels at the rods' level (0 to 1).
    """

    levels: tuple
    rods_dark: bool
    rod_fraction: float

    @property
    def rod_level(self) -> float:
        return self.levels[0] if self.rods_dark else self.levels[1]

    def info(self) -> dict:
        """What ``SegmentResult.quality["binarised"]`` (and ``summary.json``) records."""
        return {"levels": [_plain(v) for v in self.levels], "rod_level": _plain(self.rod_level),
                "rod_fraction": float(self.rod_fraction)}


def _sample(volume, n_voxels: int) -> np.ndarray:
    """Every ``s``-th voxel along each axis (about ``n_voxels``), in the stack's own dtype."""
    shape = tuple(int(s) for s in volume.shape)
    s = max(1, int(math.ceil((float(np.prod(shape)) / n_voxels) ** (1.0 / 3.0))))
    # one slice at a time: every array-like (TIFF pages, zarr, a slice folder) reads a slice
    return np.stack([np.asarray(volume[z])[::s, ::s] for z in range(0, shape[0], s)])


def _count_levels(volume, limit: int) -> dict | None:
    """{value: voxel count} of a stack, or None as soon as it holds more than ``limit`` values.

    The values a strided sample shows are counted by comparison, slab by slab; only a slab
    holding others is sorted for them, so a two-level stack costs one read and a few compares.
    """
    sample = _sample(volume, _SAMPLE_VOXELS)
    values = np.unique(sample)
    if len(values) > limit:
        return None
    counts = {v.item(): 0 for v in values}
    shape = tuple(int(s) for s in volume.shape)
    step = max(1, _SLAB_VOXELS // max(1, shape[1] * shape[2]))
    for z in range(0, shape[0], step):
        a = np.asarray(volume[z:z + step])
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise _fail("volume contains NaN or inf values; replace them before segmenting")
        seen = 0
        for v in list(counts):
            n = int(np.count_nonzero(a == v))
            counts[v] += n
            seen += n
        if seen < a.size:
            known = np.fromiter(counts, dtype=a.dtype, count=len(counts))
            new, cnt = np.unique(a[~np.isin(a, known)], return_counts=True)
            for v, c in zip(new, cnt):
                counts[v.item()] = int(c)
            if len(counts) > limit:
                return None
    return counts


def read_binarised(volume, dark=None) -> Binarised | None:
    """The two levels of a binarised stack, or None for a greyscale scan.

    Parameters
    ----------
    volume : ndarray or array-like (z, y, x)
        The stack as read (any numeric or bool dtype).
    dark : bool or None
        The rods are the lower level; ``None`` or ``False``: the higher.

    Returns
    -------
    Binarised or None
        None when the stack holds more than :data:`MAX_LABEL_LEVELS` distinct values.

    Raises
    ------
    RodwarpError
        One line: the stack is constant, holds 3 to :data:`MAX_LABEL_LEVELS` values (a label
        image), or its rods' level holds fewer than :data:`MIN_ROD_VOXELS` voxels or more
        than :data:`MAX_ROD_FRACTION` of them.
    """
    counts = _count_levels(volume, MAX_LABEL_LEVELS)
    if counts is None:
        return None
    values = sorted(counts)
    if len(values) == 1:
        raise _fail(f"volume is constant (every voxel is {_fmt(values[0])}): nothing to segment; pass the CT "
                    f"scan, or a mask whose rods and background hold two different values")
    if len(values) > 2:
        raise _fail(f"volume holds only {len(values)} distinct values ({', '.join(_fmt(v) for v in values)}): "
                    f"a label image or a posterised scan, which segmentation cannot read; pass the greyscale "
                    f"scan, or the rods' mask saved with two values (e.g. labels > 0 as 0/1)")
    lo, hi = values
    rods_dark = bool(dark)
    rod, other = (lo, hi) if rods_dark else (hi, lo)
    n_rod, n = counts[rod], counts[lo] + counts[hi]
    swap = "--bright-rods" if rods_dark else "--dark-rods"
    if n_rod < MIN_ROD_VOXELS:
        raise _fail(f"binarised stack (levels {_fmt(lo)}/{_fmt(hi)}): the rods' level {_fmt(rod)} holds only "
                    f"{n_rod} voxels, fewer than one rod takes ({MIN_ROD_VOXELS}); check the thresholding, or "
                    f"pass {swap} if the rods are the {_fmt(other)} voxels")
    if n_rod > MAX_ROD_FRACTION * n:
        raise _fail(f"binarised stack (levels {_fmt(lo)}/{_fmt(hi)}): the rods' level {_fmt(rod)} fills "
                    f"{100.0 * n_rod / n:.1f}% of the volume, leaving no background to tell rods apart; pass "
                    f"{swap} if the rods are the {_fmt(other)} voxels, else check the thresholding")
    return Binarised(levels=(float(lo), float(hi)), rods_dark=rods_dark, rod_fraction=n_rod / n)


class _MaskView:
    """Lazy, read-only view of a stack as the rods' mask: 1.0 at the rods' level, else 0.0
    (float32).  Basic slicing only (what the segmenter uses)."""

    def __init__(self, vol, level):
        self.vol = vol
        self.level = level
        self.shape = tuple(int(s) for s in vol.shape)
        self.dtype = np.dtype(np.float32)
        self.ndim = 3
        self.chunks = getattr(vol, "chunks", None)

    def __array__(self, dtype=None, copy=None):
        a = self[:, :, :]
        return a.astype(dtype) if dtype is not None else a

    def __getitem__(self, idx):
        return (np.asarray(self.vol[idx]) == self.level).astype(np.float32)


def mask_of(volume, b: Binarised):
    """The rods' mask of a binarised stack, float32 1.0 / 0.0: an array for an array, a lazy
    view for a lazy stack (the segmenter then reads it chunk by chunk)."""
    level = np.dtype(volume.dtype).type(b.rod_level)  # (bool: True for 1.0)
    if isinstance(volume, np.ndarray):
        return (volume == level).astype(np.float32)
    return _MaskView(volume, level)


def resample_mask(mask: np.ndarray, zoom, shape) -> np.ndarray:
    """A mask on anisotropic voxels resampled onto an isotropic grid, float32 1.0 / 0.0.

    Parameters
    ----------
    mask : ndarray (z, y, x) bool
        The rods' mask on the input grid.
    zoom : (float, float, float)
        Voxel edges along (z, y, x) over the smallest one (output voxels per input voxel).
    shape : tuple of int
        Shape of the output grid; output voxel ``i`` sits at input coordinate ``i / zoom``.

    The signed distance to the mask's surface (distance transforms with the voxel's edges,
    positive inside) is interpolated linearly and cut at 0.  Interpolating the mask itself
    would put every output voxel half-way between a voxel in and a voxel out at exactly 0.5,
    and a cut at 0.5 would then drop them all (rods 20% thin at a 2:1 aspect) or keep them all;
    the distance field also carries where the surface lies from the neighbouring columns.
    """
    zoom = np.asarray(zoom, float)
    if mask.all() or not mask.any():
        return np.full(shape, float(mask.flat[0]), np.float32)
    sd = np.where(mask, ndimage.distance_transform_edt(mask, sampling=zoom),
                  -ndimage.distance_transform_edt(~mask, sampling=zoom)).astype(np.float32)
    res = ndimage.affine_transform(sd, 1.0 / zoom, output_shape=shape, order=1, mode="nearest")
    return (res >= 0.0).astype(np.float32)


#: a mask's distance-transform ridge (its local maxima, along the rods' axes) lies about this
#: far inside the radius (voxels; digitised cylinders of radius 1.5 to 10 at random
#: orientations: 0 to 0.2)
MASK_RIDGE_BIAS = 0.15


def _without_specks(m: np.ndarray) -> np.ndarray:
    """``m`` without its connected pieces smaller than a rod (:data:`MIN_ROD_VOXELS`): the
    isolated voxels a noisy scan's threshold leaves would otherwise be most of the ridge."""
    lab, n = ndimage.label(m)
    if n == 0:
        return m
    keep = np.bincount(lab.ravel()) >= MIN_ROD_VOXELS
    keep[0] = False
    return keep[lab]


def _ridge(m: np.ndarray) -> np.ndarray:
    """Distance-transform values (voxels) at the local maxima of a mask's distance transform (the
    rods' axes), those below half the 90th percentile (bumps of a rough surface) left out."""
    ein = ndimage.distance_transform_edt(m)
    rg = ein[m & (ein >= 1.0) & (ein >= ndimage.maximum_filter(ein, size=3))]
    return rg[rg >= 0.5 * np.percentile(rg, 90)] if len(rg) else rg


def mask_levels(reader, P):
    """Stage ``stats`` for a mask (:func:`rodwarp.ct.segment._levels._measure_levels` for a greyscale scan).

    The background and rod levels are known, 0 and 1, and a mask has no noise.  In the (up to)
    four blocks with the most rod voxels (specks of a noisy threshold left out), the smoothed
    mask near the rods' axes gives the plateau that the tracer's threshold halves; the local
    maxima of the distance transform of what the tracer then sees (the smoothed mask cut at
    that threshold) give the coarse radius and say whether the radii are mixed, as for a
    greyscale scan.  ``P.threshold`` (a grey level) does not apply.

    Returns
    -------
    rodwarp.ct.segment._levels._Levels
        With ``binary=True``.

    Raises
    ------
    RodwarpError
        One line: no rod voxel is thicker than one voxel.
    """
    from rodwarp.ct.segment._levels import MIXED_RIDGE_SPREAD, _densest_blocks, _Levels, _sample_step
    from rodwarp.ct.segment._params import _HINT

    step = _sample_step(reader.shape)
    blocks = []
    for raw in _densest_blocks(reader, reader.strided(step) > 0.5, step, P.stats_block):
        m = _without_specks(raw > 0.5)
        blocks.append((m, ndimage.gaussian_filter(raw, P.smooth_sigma) if P.smooth_sigma > 0 else raw))
    # the plateau of the smoothed mask near the rods' axes, which the tracer's threshold halves
    deep = [sm[ndimage.distance_transform_edt(m) >= max(1.0, 0.75 * float(np.median(rg)))]
            for m, sm in blocks for rg in [_ridge(m)] if rg.size]
    if not deep:
        raise _fail(f"no rods found: the rods' mask is nowhere thicker than a voxel; {_HINT}")
    fg_s = float(np.median(np.concatenate(deep)))
    # the ridge of what the tracer sees (the smoothed mask cut at half its plateau): in a bundle
    # of touching rods smoothing fills the creases between them, as the blur of a scan does
    ridge = [_ridge(_without_specks(sm > 0.5 * fg_s)) for m, sm in blocks]
    ridge = np.concatenate(ridge) if ridge else np.zeros(0)
    if ridge.size == 0:
        raise _fail(f"no rods found: the rods' mask is nowhere thicker than a voxel; {_HINT}")
    med = float(np.median(ridge))
    q25, q75 = (float(v) for v in np.percentile(ridge, [25, 75]))
    # mixed radii: the coarse radius is the lower quartile's, so thin rods still fill the fits
    mixed = P.diameter is None and (q75 - q25) > MIXED_RIDGE_SPREAD * med
    if P.diameter is not None:
        r0 = 0.5 * float(P.diameter)
    else:
        # (coarse: the smoothed mask's half level also lies a little inside the mask's surface,
        # but bundles of touching rods are split best from the ridge as it is; the refinement
        # measures the radius)
        r0 = max(0.75, (q25 if mixed else med) + MASK_RIDGE_BIAS)
    return _Levels(bg=0.0, fg=1.0, fg_smooth=fg_s, threshold=0.5 * fg_s, r0=r0, noise=0.0, mixed=bool(mixed),
                   binary=True)


class SurfaceDistance:
    """Lazy signed distance (voxels) of each voxel centre to the surface of a mask.

    Positive inside (``volume > 0.5``), negative outside: the Euclidean distance transform of
    the mask (inside) or of its complement (outside), less half a voxel, so that the surface
    lies half-way between the last voxel in and the first voxel out.  Values are exact within
    ``HALO - 0.5`` voxels of the surface and clipped beyond it (each block is computed with a
    halo of ``HALO`` voxels); the faces of the volume are no surface.  Basic slicing only.
    """

    HALO = 3

    def __init__(self, vol):
        self.vol = vol
        self.shape = tuple(int(s) for s in vol.shape)
        self.dtype = np.dtype(np.float32)
        self.ndim = 3
        self.chunks = getattr(vol, "chunks", None)

    def __getitem__(self, idx):
        if not isinstance(idx, tuple):
            idx = (idx,)
        idx = idx + (slice(None),) * (3 - len(idx))
        lo, hi = [], []
        for sl, n in zip(idx, self.shape):
            a, b, _ = sl.indices(n)
            lo.append(a)
            hi.append(b)
        glo = [max(0, a - self.HALO) for a in lo]
        ghi = [min(n, b + self.HALO) for b, n in zip(hi, self.shape)]
        m = np.asarray(self.vol[glo[0]:ghi[0], glo[1]:ghi[1], glo[2]:ghi[2]]) > 0.5
        cap = self.HALO - 0.5
        if m.all() or not m.any():  # no surface within reach
            phi = np.full(m.shape, cap if m.all() else -cap, np.float32)
        else:
            phi = np.where(m, ndimage.distance_transform_edt(m) - 0.5,
                           0.5 - ndimage.distance_transform_edt(~m))
            phi = np.clip(phi, -cap, cap).astype(np.float32)
        return phi[tuple(slice(a - g, b - g) for a, b, g in zip(lo, hi, glo))]


#: voxels within this signed distance of a mask's surface estimate a rod's radius
SURFACE_BAND = 1.0


def surface_radius(phi: np.ndarray, rho: np.ndarray) -> float:
    """A rod's radius from the voxels near its surface (NaN with fewer than 10 of them).

    Parameters
    ----------
    phi : ndarray (n,)
        Signed distance to the mask's surface (:class:`SurfaceDistance`) of voxels that belong
        to the rod, away from its ends (voxels).
    rho : ndarray (n,)
        Their distances to the rod's axis (voxels).

    Returns
    -------
    float
        Median of ``rho + phi`` over the voxels within :data:`SURFACE_BAND` of the surface:
        each places the surface along its own radial line, so the median is the radius.  On
        digitised cylinders of radius 1.5 to 10 voxels at random orientations it lies within
        0.03 voxel of the true radius, where the distance transform at the axis alone falls
        0.1 to 0.3 voxel short.
    """
    band = np.abs(phi) <= SURFACE_BAND
    if int(band.sum()) < 10:
        return float("nan")
    return float(np.median(rho[band] + phi[band]))
