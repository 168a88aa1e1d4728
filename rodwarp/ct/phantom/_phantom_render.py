"""Rendering a rod set as a synthetic CT volume: partial-volume occupancy and the image model.

:func:`occupancy` is the exact-enough fraction of each voxel inside the union of the rods'
capsules (supersampled in a thin shell around the surface); :func:`render_phantom` turns it
into a 16-bit CT-like volume with cupping, Gaussian point-spread blur, ring artefacts, metal
streaks and Gaussian noise at a chosen contrast-to-noise ratio. The ground truth, the files and
the ``rodwarp phantom`` command are in :mod:`rodwarp.ct.phantom._phantom`.

Volumes are indexed ``(z, y, x)`` = (slice, row, column); a point in voxel units has
``x = column``, ``y = row``, ``z = slice`` and the centre of voxel ``(0, 0, 0)`` is the origin.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.rodset import RodSet

__all__ = ["render_phantom", "occupancy", "capsule_volume"]

#: Half the diagonal of a unit voxel: a voxel whose centre is farther than this from the surface is
#: entirely inside or entirely outside.
_HALF_DIAG = 0.87


def capsule_volume(radius: float, length: float) -> float:
    """Volume of a capsule (cylinder of ``length`` with hemispherical caps): pi r^2 L + 4/3 pi r^3."""
    return math.pi * radius ** 2 * length + 4.0 / 3.0 * math.pi * radius ** 3


def _check_shape(shape) -> tuple[int, int, int]:
    try:
        s = tuple(int(v) for v in shape)
    except (TypeError, ValueError):
        raise _fail(f"shape must be three positive integers (Z, Y, X), got {shape!r}") from None
    if len(s) != 3 or any(v <= 0 for v in s) or any(float(a) != float(b) for a, b in zip(s, shape)):
        raise _fail(f"shape must be three positive integers (Z, Y, X), got {tuple(shape)!r}")
    return s


def _to_voxels(rods: RodSet, voxel_size) -> RodSet:
    if not isinstance(rods, RodSet):
        raise _fail(f"rods must be a RodSet, got {type(rods).__name__}")
    if rods.units == "voxel":
        return rods
    if voxel_size is None:
        raise _fail(f"rods are in {rods.units!r}; pass voxel_size (metres per voxel) to place them in the volume")
    return rods.to_units("voxel", voxel_size=voxel_size)


# ----------------------------------------------------------------------------------------------
# occupancy (partial-volume fraction of each voxel inside the union of capsules)
# ----------------------------------------------------------------------------------------------

def _pieces(rods: RodSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split every segment into pieces about as long as the rod is wide (compact bounding boxes)."""
    p0, p1, rod = rods.segments()
    r = rods.radii[rod]
    seg_len = np.linalg.norm(p1 - p0, axis=1)
    piece_len = np.maximum(2.0 * r + 2.0, 4.0)
    n_sub = np.maximum(1, np.ceil(seg_len / piece_len).astype(np.int64))
    idx = np.repeat(np.arange(len(p0)), n_sub)
    first = np.repeat(np.cumsum(n_sub) - n_sub, n_sub)
    k = np.arange(idx.size) - first
    f0 = (k / n_sub[idx])[:, None]
    f1 = ((k + 1) / n_sub[idx])[:, None]
    d = p1[idx] - p0[idx]
    return p0[idx] + f0 * d, p0[idx] + f1 * d, r[idx]


def _box(a, b, reach, shape_xyz):
    """Inclusive integer voxel box (x, y, z order) around segment a-b dilated by ``reach``, clipped."""
    lo = np.floor(np.minimum(a, b) - reach).astype(np.int64)
    hi = np.ceil(np.maximum(a, b) + reach).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, np.asarray(shape_xyz) - 1)
    if np.any(hi < lo):
        return None
    return lo, hi


def _box_signed_distance(a, b, r, lo, hi):
    """Distance from the voxel centres of a box (z, y, x array) to capsule a-b of radius r, minus r."""
    u = (b - a).astype(np.float32)
    uu = float(u @ u)
    wx = (np.arange(lo[0], hi[0] + 1, dtype=np.float32) - np.float32(a[0]))[None, None, :]
    wy = (np.arange(lo[1], hi[1] + 1, dtype=np.float32) - np.float32(a[1]))[None, :, None]
    wz = (np.arange(lo[2], hi[2] + 1, dtype=np.float32) - np.float32(a[2]))[:, None, None]
    if uu > 0:
        t = (wx * u[0] + wy * u[1]) + wz * u[2]
        t *= np.float32(1.0 / uu)
        np.clip(t, 0.0, 1.0, out=t)
        dx = wx - t * u[0]
        dx *= dx
        dy = wy - t * u[1]
        dy *= dy
        dx += dy
        dy = wz - t * u[2]
        dy *= dy
        dx += dy
    else:
        dx = (wx * wx + wy * wy) + wz * wz
    np.sqrt(dx, out=dx)
    dx -= np.float32(r)
    return dx


def _near_capsules(A, B, R, boxes, progress, done: int, total: int):
    """Each capsule piece i whose box reaches the volume: (i, slices of the box (zyx), its lower
    corner (xyz), the signed distance to the capsule in it); progress every 256 pieces."""
    n = len(boxes)
    for i, bx in enumerate(boxes):
        if bx is not None:
            lo, hi = bx
            sl = (slice(lo[2], hi[2] + 1), slice(lo[1], hi[1] + 1), slice(lo[0], hi[0] + 1))
            yield i, sl, lo, _box_signed_distance(A[i], B[i], R[i], lo, hi)
        if progress is not None and (i % 256 == 0 or i == n - 1):
            progress(done + i + 1, total)


def occupancy(rods: RodSet, shape, *, voxel_size: float | None = None, supersample: int = 3,
              progress: Callable[[int, int], None] | None = None) -> np.ndarray:
    """Fraction of each voxel inside the union of the rods' capsules, float32 ``(z, y, x)``.

    Voxels whose centre is more than 0.87 voxel (half the diagonal) inside a capsule count 1,
    more than 0.87 voxel outside all capsules count 0; voxels in the shell between are sampled
    at ``supersample**3`` evenly spaced sub-points. Work is done per segment piece inside its
    bounding box, never over the whole volume in Python.

    Parameters
    ----------
    rods : RodSet
        Rods in voxel units, or metric units with ``voxel_size`` (metres per voxel).
    shape : (Z, Y, X)
        Volume shape.
    supersample : int
        Sub-points per voxel edge in the surface shell (>= 1).
    progress : callable(done, total), optional
        Called as pieces are processed.
    """
    shape = _check_shape(shape)
    rods = _to_voxels(rods, voxel_size)
    s = int(supersample)
    if s < 1 or s != supersample:
        raise _fail(f"supersample must be a positive integer, got {supersample!r}")
    shape_xyz = (shape[2], shape[1], shape[0])
    A, B, R = _pieces(rods)
    n = len(A)
    total = 2 * n
    boxes = [_box(A[i], B[i], R[i] + _HALF_DIAG + 0.5, shape_xyz) for i in range(n)]

    # pass 1: signed distance (min over capsules of distance - r), only near the rods
    far = np.float32(_HALF_DIAG + 1.0)
    D = np.full(shape, far, dtype=np.float32)
    for i, sl, lo, sd in _near_capsules(A, B, R, boxes, progress, 0, total):
        np.minimum(D[sl], sd, out=D[sl])

    occ = (D < -_HALF_DIAG).astype(np.float32)
    shell = np.abs(D) <= _HALF_DIAG
    del D
    shell_flat = np.flatnonzero(shell)
    if shell_flat.size == 0:
        if progress is not None:
            progress(total, total)
        return occ
    # sub-point offsets within a voxel, (s^3, 3) in x, y, z order
    g = (np.arange(s, dtype=np.float32) + 0.5) / s - 0.5
    oz, oy, ox = np.meshgrid(g, g, g, indexing="ij")
    sub = np.stack([ox.ravel(), oy.ravel(), oz.ravel()], axis=1)
    bits = np.zeros((shell_flat.size, sub.shape[0]), dtype=bool)
    strides = np.array([1, shape[2], shape[1] * shape[2]], dtype=np.int64)  # x, y, z

    # pass 2: supersample the shell voxels each capsule piece can reach
    for i, sl, lo, sd in _near_capsules(A, B, R, boxes, progress, n, total):
        sel = shell[sl] & (sd <= _HALF_DIAG)
        kz, ky, kx = np.nonzero(sel)
        if kz.size:
            vox = np.stack([kx + lo[0], ky + lo[1], kz + lo[2]], axis=1)  # (M, 3) xyz
            flat = vox @ strides
            idx = np.searchsorted(shell_flat, flat)
            a = A[i].astype(np.float32)
            u = (B[i] - A[i]).astype(np.float32)
            uu = float(u @ u)
            w = (vox.astype(np.float32) - a)[:, None, :] + sub[None, :, :]  # (M, s^3, 3)
            if uu > 0:
                t = np.clip((w @ u) / np.float32(uu), 0.0, 1.0)
                w -= t[..., None] * u
            inside = np.einsum("mkj,mkj->mk", w, w) <= np.float32(R[i]) ** 2
            bits[idx] |= inside
    occ.ravel()[shell_flat] = bits.mean(axis=1, dtype=np.float32)
    return occ


# ----------------------------------------------------------------------------------------------
# artefacts
# ----------------------------------------------------------------------------------------------

def _slice_radius(shape) -> np.ndarray:
    """(Y, X) radial distance of each pixel from the slice centre (the rotation axis)."""
    _, ny, nx = shape
    y = np.arange(ny, dtype=np.float32) - (ny - 1) / 2.0
    x = np.arange(nx, dtype=np.float32) - (nx - 1) / 2.0
    return np.sqrt(y[:, None] ** 2 + x[None, :] ** 2)


def _ring_profile(rho: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random sharp concentric rings as a function of radius, scaled to max |f| = 1."""
    rmax = float(rho.max()) + 1.0
    n_rings = max(3, int(rmax / 6.0))
    centres = rng.uniform(0.0, rmax, n_rings)
    amps = rng.normal(0.0, 1.0, n_rings)
    widths = rng.uniform(0.35, 0.9, n_rings)
    grid = np.linspace(0.0, rmax, int(rmax * 20) + 2)
    prof = np.zeros_like(grid)
    for c, a, w in zip(centres, amps, widths):
        prof += a * np.exp(-0.5 * ((grid - c) / w) ** 2)
    m = np.abs(prof).max()
    if m > 0:
        prof /= m
    return np.interp(rho, grid, prof).astype(np.float32)


def _streak_slice(img: np.ndarray, rng: np.random.Generator, n_spots: int, width: float) -> np.ndarray:
    """Bright-dark streak pattern (unit amplitude) along lines through the brightest spots of a slice."""
    from scipy import ndimage as ndi

    ny, nx = img.shape
    if img.max() <= 0:
        return np.zeros_like(img)
    peaks = (img == ndi.maximum_filter(img, size=9)) & (img >= 0.5 * img.max())
    py, px = np.nonzero(peaks)
    if py.size == 0:
        return np.zeros_like(img)
    order = np.argsort(-img[py, px], kind="stable")
    chosen: list[tuple[float, float]] = []
    for k in order:
        p = (float(py[k]), float(px[k]))
        if all((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 >= 100.0 for q in chosen):
            chosen.append(p)
        if len(chosen) >= n_spots:
            break
    yy = np.arange(ny, dtype=np.float32)[:, None]
    xx = np.arange(nx, dtype=np.float32)[None, :]
    out = np.zeros((ny, nx), dtype=np.float32)
    pairs = [(chosen[i], chosen[j]) for i in range(len(chosen)) for j in range(i + 1, len(chosen))]
    if not pairs:  # one spot: a streak through it at a random angle
        (y0, x0), ang = chosen[0], rng.uniform(0.0, np.pi)
        pairs = [((y0, x0), (y0 + np.sin(ang), x0 + np.cos(ang)))]
    L = float(max(nx, ny))
    for (y0, x0), (y1, x1) in pairs:
        ey, ex = y1 - y0, x1 - x0
        n = math.hypot(ey, ex)
        ey, ex = ey / n, ex / n
        along = (yy - y0) * ey + (xx - x0) * ex  # position along the line, 0 at spot 0
        perp = (yy - y0) * ex - (xx - x0) * ey  # distance from the line
        q = (perp / width) ** 2
        hat = -(1.0 - q) * np.exp(-0.5 * q)  # dark centre, bright flanks
        outside = np.maximum(np.maximum(-along, along - n), 0.0)
        out += hat * np.exp(-outside / (0.25 * L)) * np.float32(rng.uniform(0.7, 1.0))
    return out


# ----------------------------------------------------------------------------------------------
# rendering
# ----------------------------------------------------------------------------------------------

def render_phantom(rods: RodSet, shape, *, voxel_size: float | None = None, blur_sigma: float = 1.0,
                   cnr: float = 10.0, background: float = 20000, foreground: float = 50000,
                   ring: float = 0.0, cupping: float = 0.0, streaks: float = 0.0, seed: int = 0,
                   supersample: int = 3, fov: float | None = None, fov_value: float = 0.0,
                   z_thickness: int = 1,
                   progress: Callable[[int, int], None] | None = None) -> np.ndarray:
    """Render a synthetic 16-bit CT volume of a rod set.

    Parameters
    ----------
    rods : RodSet
        Rods in voxel units (x = column, y = row, z = slice, voxel (0,0,0) centred at the origin),
        or in metric units with ``voxel_size``.
    shape : (Z, Y, X)
        Volume shape.
    voxel_size : float, optional
        Metres per voxel; needed only for rods in metric units.
    blur_sigma : float
        Gaussian point-spread sigma in voxels (0: none).
    cnr : float
        Contrast-to-noise ratio: noise sigma = (foreground - background) / cnr; ``inf`` or None
        gives no noise.
    background, foreground : float
        Grey values of empty space and of rod material.
    ring : float
        Ring-artefact amplitude as a fraction of the contrast (sharp concentric rings about the
        z axis through the slice centre, the same in every slice).
    cupping : float
        Beam-hardening cupping: intensity times ``1 - cupping (rho / rho_max)^2`` in each slice
        (``rho`` the distance from the slice centre, ``rho_max`` its largest value).  Negative
        values (above -1) brighten the rim, as beam hardening does in a reconstruction of a
        wide sample; positive values darken it.
    streaks : float
        Metal-streak amplitude as a fraction of the contrast (bright-dark streak pairs along
        lines through the brightest spots of each slice).
    seed : int
        Seed of the noise and artefacts; the output is deterministic for a seed.
    supersample : int
        Sub-points per voxel edge for the partial-volume shell.
    fov : float, optional
        Radius (voxels) of the reconstruction's field of view about the slice centre: voxels
        outside it are set to ``fov_value`` (cone-beam reconstructions write 0 there).
    fov_value : float
        Grey value outside the field of view.
    z_thickness : int
        Slices ``z_thickness`` times thicker than the voxels are wide (anisotropic voxels): rod
        coordinates stay in units of the voxel width along every axis (z too), with the centre
        of the first thick slice at z = 0; each output slice is the mean of ``z_thickness``
        thin slices of a finer rendering (blur applied isotropically on the fine grid), so the
        output has ``shape`` (Z, Y, X) with voxels of size (z_thickness, 1, 1).
    progress : callable(done, total), optional
        Progress callback.

    Returns
    -------
    numpy.ndarray
        ``uint16`` array of shape ``(Z, Y, X)``.
    """
    from scipy import ndimage as ndi

    shape = _check_shape(shape)
    for name, v in (("blur_sigma", blur_sigma), ("ring", ring), ("streaks", streaks)):
        if not (isinstance(v, (int, float, np.number)) and math.isfinite(v) and v >= 0):
            raise _fail(f"{name} must be a finite number >= 0, got {v!r}")
    if not (isinstance(cupping, (int, float, np.number)) and -1 < cupping < 1):
        raise _fail(f"cupping must lie between -1 and 1 (a fraction of the intensity), got {cupping!r}")
    if fov is not None and not (math.isfinite(fov) and fov > 0):
        raise _fail(f"fov must be a positive radius in voxels, got {fov!r}")
    zt = int(z_thickness)
    if zt < 1 or zt != z_thickness:
        raise _fail(f"z_thickness must be a positive integer, got {z_thickness!r}")
    if cnr is not None and not (cnr > 0):
        raise _fail(f"cnr (contrast-to-noise ratio) must be positive (or inf for no noise), got {cnr!r}")
    if not (math.isfinite(background) and math.isfinite(foreground)):
        raise _fail("background and foreground must be finite grey values")
    steps = 100
    occ_cb = None
    if progress is not None:
        def occ_cb(done, total):
            progress(int(80 * done / max(total, 1)), steps)
    if zt > 1:
        # fine slice j is centred at z = j - (zt - 1) / 2, so thick slice k is centred at z = k zt
        fine = _to_voxels(rods, voxel_size).copy()
        fine.points[:, 2] += 0.5 * (zt - 1)
        occ = occupancy(fine, (shape[0] * zt,) + shape[1:], supersample=supersample, progress=occ_cb)
    else:
        occ = occupancy(rods, shape, voxel_size=voxel_size, supersample=supersample, progress=occ_cb)
    contrast = float(foreground) - float(background)
    img = occ
    img *= np.float32(contrast)
    img += np.float32(background)
    rho = None
    if cupping != 0:
        rho = _slice_radius(shape)
        img *= (1.0 - np.float32(cupping) * (rho / max(float(rho.max()), 1e-12)) ** 2)[None]
    if blur_sigma > 0:
        img = ndi.gaussian_filter(img, sigma=float(blur_sigma), mode="nearest", output=np.float32)
    if zt > 1:
        img = img.reshape(shape[0], zt, shape[1], shape[2]).mean(axis=1, dtype=np.float32)
    if progress is not None:
        progress(88, steps)
    if streaks > 0:  # spots are found in the blurred image (before rings and noise)
        rng_s = np.random.default_rng([int(seed), 2])
        amp = np.float32(streaks * contrast)
        for z in range(shape[0]):
            src = ndi.uniform_filter(img[z] - np.float32(background), size=5)
            img[z] += amp * _streak_slice(src, rng_s, 3, 1.5)
    if ring > 0:
        if rho is None:
            rho = _slice_radius(shape)
        rprof = _ring_profile(rho, np.random.default_rng([int(seed), 1]))
        img += (np.float32(ring * contrast) * rprof)[None]
    if progress is not None:
        progress(94, steps)
    if cnr is not None and math.isfinite(cnr):
        rng = np.random.default_rng(int(seed))
        sigma = abs(contrast) / float(cnr)
        for z in range(shape[0]):  # slice by slice keeps the temporary small
            img[z] += rng.standard_normal(shape[1:], dtype=np.float32) * np.float32(sigma)
    if fov is not None:
        img[:, _slice_radius(shape) > float(fov)] = np.float32(fov_value)
    np.clip(img, 0, 65535, out=img)
    np.rint(img, out=img)
    out = img.astype(np.uint16)
    if progress is not None:
        progress(steps, steps)
    return out
