"""Scan preparation before segmentation: field-of-view mask, background trend, dark rods, voxels.

Real reconstructions differ from the clean scans the rod tracer assumes in four ways that this
module removes before any level is measured (:func:`prepare_volume`):

* **field of view** -- cone- and fan-beam reconstructions hold a constant (usually 0) outside
  the reconstruction circle.  The circle is found from the slices' corners (every corner voxel
  of the sampled slices holds one value, the centre does not); its inside is kept, the
  outside is filled with the background level and excluded from every statistic.
* **background trend** -- cupping (beam hardening) and rings are functions of the distance
  from the rotation axis (the slice centre, or the field of view's centre).  The background
  level B(rho) is measured in bins of a quarter voxel in rho over sampled slices (a median
  that drops the rods: values more than 2.5 robust sigmas from a first median); its smooth
  part S(rho) (a polynomial in rho^2) is treated as a gain (cupping multiplies the signal) and
  the rest B - S as an offset (rings add to it): ``v' = (v - (B - S)) S_ref / S``.  Applied
  only when the trend exceeds half the noise sigma, so a clean scan passes unchanged.
* **dark rods** -- rods darker than the background (a low-density filament in a denser
  matrix, an inverted display) are detected from the tails of the histogram about its mode
  (or forced with ``dark=True``) and the grey values negated.
* **anisotropic voxels** -- a scan whose voxels differ in size along z, y, x is resampled
  (linear interpolation) onto an isotropic grid of the smallest voxel edge; coordinates of the
  result are in units of that edge, with voxel (0, 0, 0) at the same place.

A **binarised** stack (exactly two grey levels: bool, 0/1, 0/255, any two values) has none of
the first three: it is recognised first (:mod:`rodwarp.ct.segment._binary`), replaced by the rods' mask
(1.0 rods, 0.0 background; the brighter level is the rods unless ``dark=True``) and only
resampled; a stack of one level or of a handful (a label image) is refused there.

Corrections are per pixel of a slice (2-D gain, offset and mask maps), so they are applied
lazily, chunk by chunk, to a volume that does not fit in memory; resampling loads the volume.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from rodwarp._util import one_line_error as _fail
from rodwarp.ct._voxels import parse_voxel_size

__all__ = ["Prepared", "prepare_volume", "parse_voxel_size"]


@dataclass
class Prepared:
    """A volume ready for the tracer and what was done to it.

    Attributes
    ----------
    volume : array-like (z, y, x)
        The corrected volume (lazy wrapper, resampled array, or the input itself).
    spacing : float
        Edge of the (isotropic) working voxel, in the units of the given voxel size.
    zoom : tuple of float
        Working voxels per input voxel along (z, y, x).
    dark : bool
        Grey values were negated (rods darker than the background).
    fov : dict or None
        ``{"centre_yx": [y, x], "radius": r, "value": v}`` of a detected field-of-view mask.
    trend : dict or None
        The background trend removed: amplitudes of the smooth part and of the rings.
    mask2d : ndarray (Y, X) bool or None
        Pixels of a slice inside the field of view (working grid).
    binarised : dict or None
        ``{"levels": [lo, hi], "rod_level": v, "rod_fraction": f}`` of a binarised stack, whose
        ``volume`` is then the rods' mask (:meth:`rodwarp.ct.segment._binary.Binarised.info`).
    """

    volume: object
    spacing: float = 1.0
    zoom: tuple = (1.0, 1.0, 1.0)
    dark: bool = False
    fov: dict | None = None
    trend: dict | None = None
    mask2d: np.ndarray | None = None
    notes: dict = field(default_factory=dict)
    binarised: dict | None = None

    def info(self) -> dict:
        """What preparation did, as ``SegmentResult.quality`` lists it (a new dict each call)."""
        return {"spacing": self.spacing, "zoom": list(self.zoom), "dark_rods": self.dark, "fov": self.fov,
                "background_trend": self.trend, "binarised": self.binarised}


class _Corrected:
    """Lazy, read-only view of a volume with per-pixel corrections: ``sign (v - off) gain``,
    outside the field of view ``fill``.  Basic slicing only (what the segmenter uses)."""

    def __init__(self, vol, gain=None, off=None, inside=None, fill=0.0, sign=1.0):
        self.vol = vol
        self.shape = tuple(int(s) for s in vol.shape)
        self.dtype = np.dtype(np.float32)
        self.ndim = 3
        self.chunks = getattr(vol, "chunks", None)
        self.gain, self.off, self.inside = gain, off, inside
        self.fill = np.float32(fill)
        self.sign = np.float32(sign)

    def __array__(self, dtype=None, copy=None):
        a = self[:, :, :]
        return a.astype(dtype) if dtype is not None else a

    def __getitem__(self, idx):
        if not isinstance(idx, tuple):
            idx = (idx,)
        idx = idx + (slice(None),) * (3 - len(idx))
        a = np.asarray(self.vol[idx]).astype(np.float32)
        yx = idx[1:]
        squeeze_z = not isinstance(idx[0], slice)
        if squeeze_z:
            a = a[None]
        if self.off is not None:
            a -= self.off[yx][None]
        if self.gain is not None:
            a *= self.gain[yx][None]
        if self.inside is not None:
            a[:, ~self.inside[yx]] = self.fill
        if self.sign != 1:
            a *= self.sign
        return a[0] if squeeze_z else a


def _sample_slices(vol, n=9):
    nz = vol.shape[0]
    zs = sorted({int(round(v)) for v in np.linspace(0.1 * (nz - 1), 0.9 * (nz - 1), min(n, nz))})
    return zs, np.stack([np.asarray(vol[z]).astype(np.float32) for z in zs])


def _detect_fov(sl: np.ndarray):
    """(centre_yx, radius, value) of a constant outside a circle in the slices ``sl`` (k, Y, X), or None."""
    k, ny, nx = sl.shape
    c = max(2, min(ny, nx) // 40)
    corners = np.concatenate([sl[:, :c, :c].ravel(), sl[:, :c, -c:].ravel(), sl[:, -c:, :c].ravel(),
                              sl[:, -c:, -c:].ravel()])
    vals, cnt = np.unique(corners, return_counts=True)
    v0 = float(vals[np.argmax(cnt)])
    if cnt.max() < 0.95 * corners.size:
        return None
    const = np.all(sl == np.float32(v0), axis=0)
    if const.mean() > 0.9 or const.mean() < 0.01:
        return None
    # the inside: the largest component of non-constant pixels, filled
    inside = ndimage.binary_fill_holes(~const)
    lab, nl = ndimage.label(inside)
    if nl == 0:
        return None
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    inside = lab == int(np.argmax(sizes))
    cy, cx = (float(v) for v in ndimage.center_of_mass(inside))
    radius = math.sqrt(float(inside.sum()) / math.pi)
    return (cy, cx), radius, v0


def _radius_map(shape_yx, centre_yx):
    y = np.arange(shape_yx[0], dtype=np.float32) - np.float32(centre_yx[0])
    x = np.arange(shape_yx[1], dtype=np.float32) - np.float32(centre_yx[1])
    return np.sqrt(y[:, None] ** 2 + x[None, :] ** 2)


def _robust_bins(rho_idx, v, nb):
    """Per-bin median after dropping values beyond 2.5 robust sigmas of a first median; also the sigma."""
    order = np.argsort(rho_idx, kind="stable")
    ri, vv = rho_idx[order], v[order]
    cut = np.searchsorted(ri, np.arange(nb + 1))
    med = np.full(nb, np.nan)
    sig = np.full(nb, np.nan)
    for b in range(nb):
        x = vv[cut[b]:cut[b + 1]]
        if x.size < 30:
            continue
        m = np.median(x)
        s = 1.4826 * np.median(np.abs(x - m))
        if s > 0:
            x = x[np.abs(x - m) <= 2.5 * s]
        med[b] = np.median(x)
        sig[b] = s
    return med, sig


def _trend(sl, inside, centre_yx, step=0.25):
    """Background B(rho), smooth part S(rho), noise sigma, on bins of ``step`` voxels."""
    rho = _radius_map(sl.shape[1:], centre_yx)
    sel = inside if inside is not None else np.ones(rho.shape, bool)
    nb = int(rho[sel].max() / step) + 2
    ridx = np.broadcast_to((rho / step).astype(np.int64), sl.shape)[:, sel].ravel()
    med, sig = _robust_bins(ridx, sl[:, sel].ravel(), nb)
    r_c = (np.arange(nb) + 0.5) * step
    ok = np.isfinite(med)
    if ok.sum() < 10:
        return None
    # smooth part: a weighted polynomial in (rho / rho_max)^2 (cupping is even in rho)
    q = (r_c / r_c[ok].max()) ** 2
    w = np.sqrt(np.maximum(r_c, step))  # bins far out hold more pixels
    coef = np.polynomial.polynomial.polyfit(q[ok], med[ok], 3, w=w[ok])
    S = np.polynomial.polynomial.polyval(q, coef)
    B = np.where(ok, med, S)
    noise = float(np.nanmedian(sig[ok]))
    return rho, r_c, B, S, noise


def prepare_volume(volume, voxel_size=None, *, dark=None, fov=None, background=None) -> Prepared:
    """Prepare a scan for :func:`rodwarp.ct.segment_volume` (see the module docstring).

    Parameters
    ----------
    volume : ndarray or array-like (z, y, x)
        The scan as read.
    voxel_size : float or sequence of 3 floats, optional
        Voxel edge length (one value) or lengths along (z, y, x), any unit; default isotropic.
    dark : bool or None
        Rods darker than the background: ``None`` detects it, ``True``/``False`` forces it (of
        a binarised stack: the rods are its lower level; otherwise its higher).
    fov : bool or None
        Field-of-view mask: ``None`` detects it, ``False`` never masks.
    background : bool or None
        Background-trend (cupping, rings) removal: ``None`` applies it when the trend exceeds
        half the noise, ``True`` always, ``False`` never.

    Returns
    -------
    Prepared

    Raises
    ------
    RodwarpError
        One line: not 3-D, empty, NaN or inf values, or a stack of discrete levels segmentation
        cannot read (:func:`rodwarp.ct.segment._binary.read_binarised`).
    """
    from rodwarp.ct.segment._binary import mask_of, read_binarised

    dz, dy, dx = parse_voxel_size(voxel_size)
    shape = tuple(int(s) for s in volume.shape)
    if len(shape) != 3:
        raise _fail(f"volume must be 3-D (z, y, x), got {len(shape)}-D shape {shape}; pass a stack of slices")
    if min(shape) == 0:
        raise _fail(f"volume is empty (shape {shape})")
    out = Prepared(volume=volume)
    notes: dict = {}
    zs, sl = _sample_slices(volume)
    if not np.all(np.isfinite(sl)):
        raise _fail("volume contains NaN or inf values; replace them before segmenting")
    binarised = read_binarised(volume, dark)
    if binarised is not None:  # a mask: no field of view, trend or noise to correct, polarity known
        out.volume, out.dark, out.binarised = mask_of(volume, binarised), binarised.rods_dark, binarised.info()
        return _isotropic(out, (dz, dy, dx), None)
    inside = None
    centre = ((shape[1] - 1) / 2.0, (shape[2] - 1) / 2.0)
    fill = None
    if fov is not False:
        got = _detect_fov(sl)
        if got is not None:
            (cy, cx), radius, v0 = got
            centre = (cy, cx)
            # the reconstruction's last pixels before the mask are unreliable: keep a margin
            rmap = _radius_map(shape[1:], centre)
            inside = rmap <= radius - 2.0
            out.fov = {"centre_yx": [cy, cx], "radius": radius, "value": v0}
    gain = off = None
    tr = None
    if background is not False and min(shape[1:]) >= 16:
        tr = _trend(sl, inside, centre)
    if tr is not None:
        rho, r_c, B, S, noise = tr
        inner = (r_c <= (out.fov["radius"] - 2.0 if out.fov else r_c.max()))
        ring = B - S
        amp_s = float(np.nanmax(S[inner]) - np.nanmin(S[inner]))
        amp_r = float(np.sqrt(np.nanmean(ring[inner] ** 2)))
        do = background is True or (noise > 0 and (amp_s > 0.5 * noise or amp_r > 0.25 * noise))
        if do:
            ref = float(np.median(S[inner][: max(4, int(inner.sum() // 4))]))  # the level near the axis
            Smap = np.interp(rho, r_c, S).astype(np.float32)
            Rmap = np.interp(rho, r_c, ring).astype(np.float32)
            if np.all(S[inner] > 0) and ref > 0:
                gain = (ref / np.maximum(Smap, 1e-6 * ref)).astype(np.float32)
                off = Rmap
                kind = "gain"
            else:  # no positive level to scale by: the whole trend is an offset
                off = (Rmap + Smap - np.float32(ref)).astype(np.float32)
                kind = "offset"
            fill = ref
            out.trend = {"model": kind, "smooth_amplitude": amp_s, "ring_rms": amp_r, "noise": noise,
                         "centre_yx": list(centre)}
        else:
            fill = float(np.median(S[inner]))
        notes["noise"] = noise
    if inside is not None and fill is None:
        fill = float(np.median(sl[:, inside]))
    sign = 1.0
    # dark rods: the histogram tail below the mode outweighs the tail above it
    probe = _Corrected(volume, gain, off, inside, fill if fill is not None else 0.0)
    if dark is None:
        s2 = np.stack([probe[z] for z in zs])
        s2 = ndimage.gaussian_filter(s2, (0, 1.0, 1.0))
        vals = s2[:, inside] if inside is not None else s2.reshape(len(zs), -1)
        vals = vals.ravel()
        lo_p, hi_p = np.percentile(vals, [0.5, 99.5])
        if hi_p > lo_p:
            hist, edges = np.histogram(vals, bins=256, range=(lo_p, hi_p))
            mode = 0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])
            mad = 1.4826 * float(np.median(np.abs(vals - mode)))
            up = float(np.mean(vals > mode + 4 * mad))
            down = float(np.mean(vals < mode - 4 * mad))
            notes["tail_above"], notes["tail_below"] = up, down
            dark = down > 3.0 * up and down > 1e-3
        else:
            dark = False
    if dark:
        sign = -1.0
    out.dark = bool(dark)
    if gain is not None or off is not None or inside is not None or sign != 1.0:
        out.volume = _Corrected(volume, gain, off, inside, fill if fill is not None else 0.0, sign)
        out.mask2d = inside
    out.notes = notes
    return _isotropic(out, (dz, dy, dx), inside)


def _isotropic(out: Prepared, d_zyx, inside) -> Prepared:
    """``out`` with its volume resampled (linearly; a mask through its signed distance) onto an
    isotropic grid of the smallest voxel edge ``d_zyx`` (z, y, x) when the edges differ, and its
    field-of-view mask ``inside`` with it."""
    dz, dy, dx = d_zyx
    shape = tuple(int(s) for s in out.volume.shape)
    h = min(dz, dy, dx)
    if max(dz, dy, dx) > h * (1 + 1e-6):
        src = np.asarray(out.volume[:, :, :] if isinstance(out.volume, _Corrected) else out.volume, dtype=np.float32)
        d = np.array([dz, dy, dx]) / h
        new_shape = tuple(int(math.floor((n - 1) * f + 1e-9)) + 1 for n, f in zip(shape, d))
        # output voxel i sits at input coordinate i / f: voxel (0, 0, 0) stays in place
        if out.binarised is not None:
            from rodwarp.ct.segment._binary import resample_mask

            res = resample_mask(src > 0.5, d, new_shape)
        else:
            res = ndimage.affine_transform(src, 1.0 / d, output_shape=new_shape, order=1, mode="nearest")
        out.volume = res.astype(np.float32, copy=False)
        out.zoom = tuple(float(v) for v in d)
        if inside is not None:
            out.mask2d = ndimage.affine_transform(inside.astype(np.float32), 1.0 / d[1:], output_shape=new_shape[1:],
                                                  order=0, mode="nearest") > 0.5
    out.spacing = float(h)
    return out
