"""Stage ``stats`` of segmentation, levels and binarisation: background, rod plateau, threshold, coarse radius.

A smoothed, strided sample of the volume gives an Otsu split (kept above the background noise
when the rods are a tiny fraction of the volume); the (up to) four blocks with the most
foreground give the background and foreground levels (medians far outside and deep inside the
mask) and the binarisation threshold half-way between them; the local maxima of the distance
transform (the rods' axes) give a coarse radius, and their spread says whether the radii are
mixed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from rodwarp._util import one_line_error as _fail
from rodwarp.ct.segment._params import _HINT, SegmentParams
from rodwarp.ct.segment._reader import _Reader


@dataclass
class _Levels:
    """What stage ``stats`` measured: grey levels (raw intensity units) and a coarse radius (voxels)."""

    bg: float           # background level (raw)
    fg: float           # rod plateau (raw)
    fg_smooth: float    # rod plateau in the smoothed image (detection)
    threshold: float    # binarisation level of the smoothed image
    r0: float           # coarse rod radius (voxels)
    noise: float        # robust sigma of the background (raw)
    mixed: bool = False  # radii spread widely (the distance-transform ridge is broad)
    binary: bool = False  # the volume is the rods' mask, 0 and 1 (a binarised stack: ``_binary``)


def _otsu(values: np.ndarray) -> float:
    from skimage.filters import threshold_otsu
    return float(threshold_otsu(values))


RIDGE_BIAS = 0.55


#: interquartile range of the distance-transform ridge, relative to its median, above which
#: the scan holds mixed radii (one radius: 0.06-0.11 on phantoms of radius 1.5-3; radii 2-5: 0.41)
MIXED_RIDGE_SPREAD = 0.3


#: robust coefficient of variation of the rods' own radii above which radii are per rod
#: (one radius at CNR 2-5: below 0.05)
MIXED_RADIUS_CV = 0.1


def _densest_blocks(reader: _Reader, bright: np.ndarray, step: int, block: int) -> list[np.ndarray]:
    """The (up to) four blocks of edge ``block`` with the most foreground, read whole (float32).

    ``bright`` is the foreground of the volume strided by ``step`` (the choice is the same in
    any chunking)."""
    shape = reader.shape
    B = [min(block, s) for s in shape]
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
    return [reader.read((z0, y0, x0), (z0 + B[0], y0 + B[1], x0 + B[2])) for z0, y0, x0 in blocks]


def _sample_step(shape) -> int:
    """Stride of the sample that stage ``stats`` reads (about 2 million voxels)."""
    return max(1, int(math.ceil((float(np.prod(shape)) / 2.0e6) ** (1.0 / 3.0))))


def _measure_levels(reader: _Reader, P: SegmentParams) -> _Levels:
    """Background and rod levels, the binarisation threshold and a coarse radius of a volume
    (the module docstring says how); raises a one-line error when no rods stand out."""
    shape = reader.shape
    n = float(np.prod(shape))
    step = _sample_step(shape)
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

    data = []
    for raw in _densest_blocks(reader, bright, step, P.stats_block):
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
    return _Levels(bg=bg, fg=fg, fg_smooth=fg_s, threshold=thr, r0=r0, noise=noise,
                  mixed=bool(P.diameter is None and mixed))
