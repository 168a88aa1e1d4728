"""Synthetic CT phantoms of rod sets, with ground truth, for validating segmentation.

Volumes are indexed ``(z, y, x)`` = (slice, row, column); a point in voxel units has
``x = column``, ``y = row``, ``z = slice`` and the centre of voxel ``(0, 0, 0)`` is the origin.
Physical coordinates are voxel coordinates times the voxel size.

:func:`render_phantom` turns a rod set into a 16-bit CT-like volume: exact-enough partial-volume
occupancy of the union of the rods' capsules (supersampled in a thin shell around the surface),
cupping, Gaussian point-spread blur, ring artefacts, metal streaks and Gaussian noise at a chosen
contrast-to-noise ratio. The ``scene_*`` builders make the test scenes of issue 5 with their truth
contacts; :func:`write_phantom` writes a TIFF stack plus ``<stem>_truth.npz`` and
``<stem>_truth.json`` beside it.

This module does not import warp.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable

import numpy as np

from rodwarp.errors import RodwarpError
from rodwarp.rodset import Contacts, RodSet

__all__ = [
    "render_phantom", "occupancy", "phantom_truth", "write_phantom",
    "scene_isolated", "scene_crossing_pair", "scene_parallel_pair", "scene_random_packing",
    "scene_bundles", "scene_arcs", "scene_wire_tangle",
    "capsule_volume", "DEFAULT_TOLERANCE_VOXELS",
]

#: Largest surface gap (voxels) counted as a true contact. Scenes make gaps of exactly 0 or >= 2.
DEFAULT_TOLERANCE_VOXELS = 0.5
#: Half the diagonal of a unit voxel: a voxel whose centre is farther than this from the surface is
#: entirely inside or entirely outside.
_HALF_DIAG = 0.87
#: Margin (voxels) between the rods' surfaces and the volume faces in the scenes.
_MARGIN = 2.0


def _fail(msg: str) -> RodwarpError:
    return RodwarpError(" ".join(str(msg).split()))


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
    for i in range(n):
        bx = boxes[i]
        if bx is not None:
            lo, hi = bx
            sl = (slice(lo[2], hi[2] + 1), slice(lo[1], hi[1] + 1), slice(lo[0], hi[0] + 1))
            sd = _box_signed_distance(A[i], B[i], R[i], lo, hi)
            np.minimum(D[sl], sd, out=D[sl])
        if progress is not None and (i % 256 == 0 or i == n - 1):
            progress(i + 1, total)

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
    for i in range(n):
        bx = boxes[i]
        if bx is not None:
            lo, hi = bx
            sl = (slice(lo[2], hi[2] + 1), slice(lo[1], hi[1] + 1), slice(lo[0], hi[0] + 1))
            sd = _box_signed_distance(A[i], B[i], R[i], lo, hi)
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
        if progress is not None and (i % 256 == 0 or i == n - 1):
            progress(n + i + 1, total)
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


# ----------------------------------------------------------------------------------------------
# truth
# ----------------------------------------------------------------------------------------------

def phantom_truth(rods: RodSet, tolerance_voxels: float = DEFAULT_TOLERANCE_VOXELS, *,
                  voxel_size: float | None = None) -> Contacts:
    """Ground-truth contacts: rod pairs whose surfaces come within ``tolerance_voxels``.

    For rods in metric units pass ``voxel_size`` (metres per voxel) to convert the tolerance.
    Contact points and gaps are in the rods' units.
    """
    from rodwarp.geometry import detect_contacts

    if not isinstance(rods, RodSet):
        raise _fail(f"rods must be a RodSet, got {type(rods).__name__}")
    tol = float(tolerance_voxels)
    if rods.units != "voxel":
        if voxel_size is None:
            raise _fail(f"rods are in {rods.units!r}; pass voxel_size (metres per voxel) to convert the tolerance")
        from rodwarp.rodset import UNITS
        tol = tol * float(voxel_size) / UNITS[rods.units]
    return detect_contacts(rods, tol)


# ----------------------------------------------------------------------------------------------
# scenes (voxel units, straight rods)
# ----------------------------------------------------------------------------------------------

def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _random_direction(rng: np.random.Generator) -> np.ndarray:
    while True:
        v = rng.normal(size=3)
        n = np.linalg.norm(v)
        if n > 1e-8:
            return v / n


def _centre_range(direction, length, radius, shape_xyz, margin=_MARGIN):
    """Allowed centre box (lo, hi) so the capsule stays ``margin`` voxels inside the volume faces."""
    half = 0.5 * length * np.abs(direction) + radius + margin
    lo = -0.5 + half
    hi = np.asarray(shape_xyz, dtype=np.float64) - 0.5 - half
    return lo, hi


def _finish(rods: RodSet, tolerance=DEFAULT_TOLERANCE_VOXELS, **attrs) -> RodSet:
    rods.contacts = phantom_truth(rods, tolerance)
    rods.attrs.update(attrs)
    return rods


def scene_isolated(shape, radius: float = 3.0, length: float | None = None, seed: int = 0) -> RodSet:
    """One straight rod at a random orientation, fully inside the volume (2-voxel margin).

    ``length`` (axis length, voxels) defaults to 0.6 of the smallest volume side.
    """
    shape = _check_shape(shape)
    shape_xyz = shape[::-1]
    rng = np.random.default_rng(seed)
    L = 0.6 * min(shape) if length is None else float(length)
    for _ in range(1000):
        d = _random_direction(rng)
        lo, hi = _centre_range(d, L, radius, shape_xyz)
        if np.all(hi >= lo):
            c = rng.uniform(lo, hi)
            rods = RodSet.from_straight(c[None], d[None], L, radius, n_vertices=2, units="voxel")
            return _finish(rods, scene="isolated", seed=int(seed))
    raise _fail(f"a rod of length {L} and radius {radius} does not fit in a volume of shape {shape}; "
                f"shorten it or enlarge the volume")


def _pair_length(shape, radius, offset, length):
    rfit = (min(shape) - 1) / 2.0 - radius - _MARGIN
    if length is not None:
        return float(length)
    if rfit <= abs(offset) + radius:
        raise _fail(f"the volume of shape {shape} is too small for two rods of radius {radius}")
    return 2.0 * math.sqrt(rfit ** 2 - offset ** 2)


def _rotate_about_centre(centres, dirs, shape, seed):
    if seed is None:
        return centres, dirs
    rng = np.random.default_rng(seed)
    # random rotation matrix via QR of a Gaussian matrix
    m = rng.normal(size=(3, 3))
    Q, Rm = np.linalg.qr(m)
    Q = Q * np.sign(np.diag(Rm))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    mid = (np.asarray(shape[::-1], dtype=np.float64) - 1) / 2.0
    return (centres - mid) @ Q.T + mid, dirs @ Q.T


def _check_inside(rods: RodSet, shape) -> None:
    bb = rods.bounding_box()
    if np.any(bb[0] < -0.5) or np.any(bb[1] > np.asarray(shape[::-1]) - 0.5):
        raise _fail(f"the rods do not fit inside a volume of shape {tuple(shape)}; shorten them or enlarge the volume")


def scene_crossing_pair(shape, angle_deg: float = 90.0, radius: float = 3.0, gap: float = 0.0,
                        length: float | None = None, seed: int | None = None) -> RodSet:
    """Two straight rods crossing at ``angle_deg`` with a surface gap of ``gap`` voxels (0 = touching).

    Both rods pass over the volume centre in planes normal to z (rotated rigidly by a random
    rotation about the centre if ``seed`` is given); their axes are ``2 radius + gap`` apart along
    the common normal, at the middle of each rod. ``length`` defaults to the longest that fits
    in any orientation.
    """
    shape = _check_shape(shape)
    a = math.radians(float(angle_deg))
    if not (0 < a < math.pi):
        raise _fail(f"angle_deg must be between 0 and 180 (exclusive), got {angle_deg!r}")
    if gap < 0:
        raise _fail(f"gap must be >= 0 voxels, got {gap!r}")
    off = radius + 0.5 * gap
    L = _pair_length(shape, radius, off, length)
    mid = (np.asarray(shape[::-1], dtype=np.float64) - 1) / 2.0
    d0 = np.array([math.cos(-a / 2), math.sin(-a / 2), 0.0])
    d1 = np.array([math.cos(a / 2), math.sin(a / 2), 0.0])
    n = np.array([0.0, 0.0, 1.0])
    centres = np.stack([mid - off * n, mid + off * n])
    dirs = np.stack([d0, d1])
    centres, dirs = _rotate_about_centre(centres, dirs, shape, seed)
    rods = RodSet.from_straight(centres, dirs, L, radius, n_vertices=2, units="voxel")
    _check_inside(rods, shape)
    return _finish(rods, scene="crossing_pair", angle_deg=float(angle_deg), gap=float(gap),
                   seed=None if seed is None else int(seed))


def scene_parallel_pair(shape, radius: float = 3.0, gap: float = 0.0, length: float | None = None,
                        seed: int | None = None) -> RodSet:
    """Two parallel straight rods along x, side by side in y with a surface gap of ``gap`` voxels.

    Rotated rigidly about the volume centre by a random rotation if ``seed`` is given.
    """
    shape = _check_shape(shape)
    if gap < 0:
        raise _fail(f"gap must be >= 0 voxels, got {gap!r}")
    off = radius + 0.5 * gap
    L = _pair_length(shape, radius, off, length)
    mid = (np.asarray(shape[::-1], dtype=np.float64) - 1) / 2.0
    centres = np.stack([mid - [0, off, 0], mid + [0, off, 0]])
    dirs = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    centres, dirs = _rotate_about_centre(centres, dirs, shape, seed)
    rods = RodSet.from_straight(centres, dirs, L, radius, n_vertices=2, units="voxel")
    _check_inside(rods, shape)
    return _finish(rods, scene="parallel_pair", gap=float(gap), seed=None if seed is None else int(seed))


def _seg_dist(a, b, A, B):
    """(K, N) distances between K candidate segments a-b and N placed segments A-B."""
    from rodwarp.geometry import segment_distance

    return segment_distance(a[:, None], b[:, None], A[None], B[None])


def scene_random_packing(shape, n_rods: int = 100, radius=3.0, aspect: float = 30.0,
                         touching_fraction: float = 0.5, seed: int = 0, max_attempts: int = 20000,
                         fov_radius: float | None = None) -> RodSet:
    """Random straight rods, fully inside the volume, with about ``touching_fraction`` touching.

    Rods have axis length ``aspect * 2 radius`` and random orientations; every rod keeps a
    2-voxel margin to the volume faces. Pairs either touch exactly (surface gap 0: the new rod's
    axis is placed at distance 2r from a point on an existing rod, along the common normal) or
    are at least 2 voxels apart, so contact scoring is unambiguous. No rods overlap. Rods are
    single segments (2 vertices); ``rods.contacts`` holds the truth contacts (gap 0).

    Random sequential placement saturates: 200 rods of aspect 30 and radius 3 (length 180) in
    256^3 is close to the limit (about 5 s); raise ``max_attempts`` or lower the count if it fails.

    ``radius`` may be a pair ``(low, high)``: each rod then draws its own radius uniformly from
    that range (mixed radii; the length is ``aspect`` times the mean diameter for every rod).
    ``fov_radius`` (voxels) keeps every rod inside the cylinder of that radius about the slice
    centre (the field of view of a reconstruction, see ``render_phantom(fov=...)``).

    Raises
    ------
    RodwarpError
        If the rods cannot be placed (volume too crowded, or rods too long for it).
    """
    shape = _check_shape(shape)
    n_rods = int(n_rods)
    if n_rods < 1:
        raise _fail(f"n_rods must be >= 1, got {n_rods}")
    if not (0.0 <= touching_fraction <= 1.0):
        raise _fail(f"touching_fraction must be in [0, 1], got {touching_fraction!r}")
    if np.ndim(radius) == 0:
        r_lo = r_hi = float(radius)
    else:
        r_lo, r_hi = (float(v) for v in radius)
    if not (0 < r_lo <= r_hi):
        raise _fail(f"radius must be positive (or a range low <= high), got {radius!r}")
    L = float(aspect) * (r_lo + r_hi)
    if not L > 0:
        raise _fail(f"aspect must be positive, got aspect={aspect!r}")
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    A = np.zeros((0, 3))
    B = np.zeros((0, 3))
    RR = np.zeros(0)
    touching = np.zeros(0, dtype=bool)
    K = 64  # candidates per batch
    r = r_hi
    centre_xy = 0.5 * (shape_xyz[:2] - 1.0)

    def random_dirs(k):
        v = rng.normal(size=(k, 3))
        return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)

    def in_fov(a, b):
        if fov_radius is None:
            return np.ones(len(a), bool)
        lim = float(fov_radius) - r - _MARGIN  # the cylinder is convex: both ends inside suffice
        return (np.linalg.norm(a[:, :2] - centre_xy, axis=1) <= lim) & \
            (np.linalg.norm(b[:, :2] - centre_xy, axis=1) <= lim)

    def inside(a, b):
        lo = np.minimum(a, b) - r - _MARGIN
        hi = np.maximum(a, b) + r + _MARGIN
        return np.all(lo >= -0.5, axis=1) & np.all(hi <= shape_xyz - 0.5, axis=1) & in_fov(a, b)

    def try_free(rn):
        d = random_dirs(K)
        lo, hi = _centre_range(d.T, L, r, shape_xyz[:, None])
        lo, hi = lo.T, hi.T
        ok = np.all(hi >= lo, axis=1)
        c = lo + rng.random((K, 3)) * (hi - lo)
        a, b = c - 0.5 * L * d, c + 0.5 * L * d
        ok &= in_fov(a, b)
        if len(A):  # "clearly apart": surface gaps of at least 2 voxels
            ok &= np.all(_seg_dist(a, b, A, B) >= RR[None] + rn + 2.0, axis=1)
        k = np.flatnonzero(ok)
        return None if k.size == 0 else (a[k[0]], b[k[0]], None)

    def try_touch(rn):
        if len(A) == 0:
            return None
        j = rng.integers(len(A), size=K)
        u = B[j] - A[j]
        p = A[j] + rng.uniform(0.1, 0.9, size=(K, 1)) * u
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        d = random_dirs(K)
        nrm = np.cross(u, d)
        sn = np.linalg.norm(nrm, axis=1)
        ok = sn >= 0.3  # nearly parallel pairs would have an ill-defined contact point
        nrm = nrm / np.maximum(sn, 1e-12)[:, None] * np.where(rng.random(K) < 0.5, -1.0, 1.0)[:, None]
        q = p + (RR[j] + rn)[:, None] * nrm
        c = q + rng.uniform(-0.4 * L, 0.4 * L, size=(K, 1)) * d
        a, b = c - 0.5 * L * d, c + 0.5 * L * d
        ok &= inside(a, b)
        if not ok.any():
            return None
        k = np.flatnonzero(ok)
        dist = _seg_dist(a[k], b[k], A, B)
        own = dist[np.arange(k.size), j[k]].copy()
        dist[np.arange(k.size), j[k]] = np.inf
        good = np.all(dist >= RR[None] + rn + 2.0, axis=1) & (np.abs(own - (RR[j[k]] + rn)) <= 1e-9)
        g = np.flatnonzero(good)
        return None if g.size == 0 else (a[k[g[0]]], b[k[g[0]]], int(j[k[g[0]]]))

    batches = max(1, int(max_attempts) // K)
    for k in range(n_rods):
        want_touch = touching_fraction > 0 and len(A) > 0 and touching.sum() < touching_fraction * (k + 1)
        # a single radius draws nothing, so single-radius scenes stay as they were for a seed
        rn = r_lo if r_hi == r_lo else float(rng.uniform(r_lo, r_hi))
        placed = None
        for _ in range(batches):
            placed = try_touch(rn) if want_touch else try_free(rn)
            if placed is not None:
                break
        if placed is None:  # fall back to the other kind
            for _ in range(batches):
                placed = try_free(rn) if want_touch else try_touch(rn)
                if placed is not None:
                    break
        if placed is None:
            raise _fail(f"could only place {len(A)} of {n_rods} rods (length {L:g}, radius {r:g}) in a volume of "
                        f"shape {shape}; use fewer or shorter rods or a bigger volume")
        a, b, j = placed
        A = np.vstack([A, a])
        B = np.vstack([B, b])
        RR = np.append(RR, rn)
        touching = np.append(touching, j is not None)
        if j is not None:
            touching[j] = True
    dirs = B - A
    centres = 0.5 * (A + B)
    rods = RodSet.from_straight(centres, dirs, L, RR, n_vertices=2, units="voxel")
    # from_straight renormalises; put the exact end points back so touching gaps stay exact
    rods.points[0::2] = A
    rods.points[1::2] = B
    return _finish(rods, scene="random_packing", n_rods=n_rods,
                   radius=r_lo if r_lo == r_hi else [r_lo, r_hi], aspect=float(aspect),
                   touching_fraction=float(touching_fraction), seed=int(seed),
                   touching_rods=int(touching.sum()))


def _polyline_gaps(poly, radius, placed, placed_r):
    """Smallest surface gap between a polyline (n, 3) of ``radius`` and each placed polyline."""
    from rodwarp.geometry import segment_distance

    if not placed:
        return np.zeros(0)
    a, b = poly[:-1], poly[1:]
    out = np.empty(len(placed))
    for k, (q, rq) in enumerate(zip(placed, placed_r)):
        d = segment_distance(a[:, None], b[:, None], q[None, :-1], q[None, 1:])
        out[k] = float(d.min()) - radius - rq
    return out


def _polyline_inside(poly, radius, shape_xyz, margin=_MARGIN):
    return bool(np.all(poly - radius - margin >= -0.5) and np.all(poly + radius + margin <= shape_xyz - 0.5))


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    m = rng.normal(size=(3, 3))
    Q, Rm = np.linalg.qr(m)
    Q = Q * np.sign(np.diag(Rm))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def scene_bundles(shape, n_bundles: int = 8, sizes=(3, 5), radius: float = 3.0, length: float | None = None,
                  stagger: float = 0.1, seed: int = 0, max_attempts: int = 20000) -> RodSet:
    """Bundles of parallel straight rods touching side by side (gap 0), bundles apart.

    Each bundle holds ``k`` rods (``k`` drawn uniformly from ``sizes``, inclusive) on the
    closest-packed (triangular) lattice of spacing ``2 radius`` in its cross-section, so
    neighbours in a bundle touch exactly; the rods are shifted along the common axis by up to
    ``stagger`` times the length (ends not flush, as in a real bundle).  Bundles have random
    orientations and positions, stay 2 voxels (surface gap) from each other and inside the
    volume (2-voxel margin).  ``length`` defaults to 0.7 of the smallest volume side.
    ``rods.contacts`` holds the truth contacts (the touching neighbours in each bundle).
    """
    from rodwarp.geometry import segment_distance

    shape = _check_shape(shape)
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    r = float(radius)
    L = 0.7 * min(shape) if length is None else float(length)
    k_lo, k_hi = int(sizes[0]), int(sizes[1])
    if not (r > 0 and L > 0 and 1 <= k_lo <= k_hi <= 12):
        raise _fail(f"bundles need radius > 0, length > 0 and 1 <= sizes <= 12, got {radius!r}, {length!r}, {sizes!r}")
    # closest-packed lattice points ordered outward from the centre of the first triangle
    ij = np.array([(i, j) for i in range(-4, 5) for j in range(-4, 5)], float)
    lat = np.stack([ij[:, 0] + 0.5 * ij[:, 1], ij[:, 1] * math.sqrt(3) / 2], 1) * 2.0 * r
    c0 = np.array([r, r / math.sqrt(3)])
    order = np.lexsort((lat[:, 1], lat[:, 0], np.round(np.linalg.norm(lat - c0, axis=1), 6)))
    lat = lat[order] - c0
    A = np.zeros((0, 3))
    B = np.zeros((0, 3))
    bundle_of: list[int] = []
    for nb in range(int(n_bundles)):
        k = int(rng.integers(k_lo, k_hi + 1))
        placed = False
        for _ in range(max(1, int(max_attempts) // 50)):
            Q = _random_rotation(rng)
            u, e1, e2 = Q[:, 0], Q[:, 1], Q[:, 2]
            off = lat[:k, 0:1] * e1 + lat[:k, 1:2] * e2
            shift = rng.uniform(-stagger, stagger, k)[:, None] * L * u
            ext = np.abs(u) * 0.5 * L * (1 + 2 * stagger) + np.abs(off).max(0) + r + _MARGIN
            lo, hi = ext - 0.5, shape_xyz - 0.5 - ext
            if np.any(hi < lo):
                continue
            c = lo + rng.random(3) * (hi - lo)
            a = c + off + shift - 0.5 * L * u
            b = c + off + shift + 0.5 * L * u
            if not all(_polyline_inside(np.stack([p, q]), r, shape_xyz) for p, q in zip(a, b)):
                continue
            if len(A) and np.any(segment_distance(a[:, None], b[:, None], A[None], B[None]) < 2 * r + 2.0):
                continue
            A, B = np.vstack([A, a]), np.vstack([B, b])
            bundle_of += [nb] * k
            placed = True
            break
        if not placed:
            raise _fail(f"could only place {nb} of {n_bundles} bundles (length {L:g}, radius {r:g}) in a volume "
                        f"of shape {shape}; use fewer bundles, shorter rods or a bigger volume")
    rods = RodSet.from_straight(0.5 * (A + B), B - A, L, r, n_vertices=2, units="voxel")
    rods.points[0::2] = A
    rods.points[1::2] = B
    return _finish(rods, scene="bundles", n_bundles=int(n_bundles), sizes=[k_lo, k_hi], radius=r, length=L,
                   seed=int(seed), bundle=[int(b) for b in bundle_of])


def scene_arcs(shape, n_rods: int = 20, radius: float = 3.0, length: float | None = None,
               curvature_radius=(2.0, 5.0), seed: int = 0, max_attempts: int = 5000) -> RodSet:
    """Gently curved rods: circular arcs of axis length ``length`` (default 0.6 of the smallest side).

    Each arc's radius of curvature is drawn uniformly from ``curvature_radius`` (in units of
    the arc length); arcs lie in random planes, every pair keeps a surface gap of at least 2
    voxels, and every arc stays inside the volume (2-voxel margin).  Arcs are polylines with a
    vertex every voxel or so of arc length.
    """
    shape = _check_shape(shape)
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    r = float(radius)
    L = 0.6 * min(shape) if length is None else float(length)
    polys: list[np.ndarray] = []
    for n in range(int(n_rods)):
        ok = False
        for _ in range(int(max_attempts)):
            Rc = float(rng.uniform(*curvature_radius)) * L
            phi = L / Rc
            nv = max(8, int(math.ceil(L)) + 1)
            th = np.linspace(-0.5 * phi, 0.5 * phi, nv)
            loc = np.stack([Rc * np.sin(th), Rc * (1.0 - np.cos(th)), np.zeros(nv)], 1)
            loc -= loc.mean(0)
            Q = _random_rotation(rng)
            pts = loc @ Q.T
            ext = np.abs(pts).max(0) + r + _MARGIN
            lo, hi = ext - 0.5, shape_xyz - 0.5 - ext
            if np.any(hi < lo):
                continue
            pts = pts + lo + rng.random(3) * (hi - lo)
            if polys and _polyline_gaps(pts, r, polys, [r] * len(polys)).min() < 2.0:
                continue
            polys.append(pts)
            ok = True
            break
        if not ok:
            raise _fail(f"could only place {n} of {n_rods} arcs (length {L:g}, radius {r:g}) in a volume of shape "
                        f"{shape}; use fewer or shorter arcs or a bigger volume")
    rods = RodSet.from_polylines(polys, r, units="voxel")
    return _finish(rods, scene="arcs", n_rods=int(n_rods), radius=r, length=L,
                   curvature_radius=[float(v) for v in curvature_radius], seed=int(seed))


def _wander(rng, shape_xyz, start, length, persistence, reach):
    """A smooth random curve: a persistent random walk of unit steps, steered back from the faces."""
    n = int(math.ceil(length))
    p = np.array(start, float)
    d = _random_direction(rng)
    pts = [p.copy()]
    mid = 0.5 * (shape_xyz - 1.0)
    half = 0.5 * (shape_xyz - 1.0) - reach
    for _ in range(n):
        kick = rng.normal(size=3) * math.sqrt(2.0 / persistence)
        kick -= (kick @ d) * d
        d = d + kick
        # steer away from the faces: a push that grows over the last ``reach`` voxels
        w = (p - mid) / np.maximum(half, 1.0)
        push = np.where(np.abs(w) > 0.7, -np.sign(w) * (np.abs(w) - 0.7) * 1.5, 0.0)
        d = d + push
        d /= np.linalg.norm(d)
        p = p + d
        pts.append(p.copy())
    return np.array(pts)


def scene_wire_tangle(shape, n_wires: int = 20, radius: float = 2.5, length=(150.0, 250.0),
                      persistence: float = 60.0, seed: int = 0, max_attempts: int = 400) -> RodSet:
    """A nest-like tangle of curved wires (smooth random curves) with truth.

    Each wire is a persistent random walk (persistence length ``persistence`` voxels, so a
    typical radius of curvature of that order) of length drawn from ``length``, kept inside
    the volume (2-voxel margin); wires never overlap (surface gap >= 0: they may touch, and
    cross above and below each other as in a nest).  Polylines with a vertex every 2 voxels.
    """
    shape = _check_shape(shape)
    shape_xyz = np.asarray(shape[::-1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    r = float(radius)
    reach = r + _MARGIN + 1.0
    polys: list[np.ndarray] = []
    for n in range(int(n_wires)):
        ok = False
        for _ in range(int(max_attempts)):
            Lw = float(rng.uniform(*length))
            start = reach + rng.random(3) * (shape_xyz - 1.0 - 2 * reach)
            pts = _wander(rng, shape_xyz, start, Lw, persistence, reach)[::2]
            if not _polyline_inside(pts, r, shape_xyz):
                continue
            if polys and _polyline_gaps(pts, r, polys, [r] * len(polys)).min() < 0.0:
                continue
            polys.append(pts)
            ok = True
            break
        if not ok:
            raise _fail(f"could only place {n} of {n_wires} wires in a volume of shape {shape}; "
                        f"use fewer or shorter wires or a bigger volume")
    rods = RodSet.from_polylines(polys, r, units="voxel")
    return _finish(rods, scene="wire_tangle", n_wires=int(n_wires), radius=r,
                   length=[float(v) for v in length], persistence=float(persistence), seed=int(seed))


# ----------------------------------------------------------------------------------------------
# output
# ----------------------------------------------------------------------------------------------

def truth_paths(path_tif) -> tuple[Path, Path]:
    """``(<stem>_truth.npz, <stem>_truth.json)`` beside a phantom TIFF."""
    p = Path(path_tif)
    stem = p.name
    for suf in (".ome.tiff", ".ome.tif", ".tiff", ".tif"):
        if stem.lower().endswith(suf):
            stem = stem[: -len(suf)]
            break
    return p.with_name(f"{stem}_truth.npz"), p.with_name(f"{stem}_truth.json")


def write_phantom(path_tif, volume: np.ndarray, rods: RodSet, contacts: Contacts | None = None,
                  voxel_size: float | None = None, params: dict | None = None, z_thickness: int = 1) -> dict:
    """Write a phantom TIFF and its ground truth beside it, each atomically.

    The TIFF records its voxel size (ImageJ resolution and spacing): ``voxel_size`` metres
    for rods in metric units, else 1 um per voxel width (so that the slice spacing of
    ``z_thickness`` voxel widths is on record); the truth is in voxel widths along every axis.

    Writes ``path_tif`` (multi-page, ZYX), ``<stem>_truth.npz`` (the rods in voxel units with
    ``contacts``) and ``<stem>_truth.json`` (``params``, seed and voxel size, shape, counts).

    Returns
    -------
    dict
        Paths written: ``{"tiff": ..., "truth_rods": ..., "truth_json": ...}``.
    """
    from rodwarp.atomic import write_json
    from rodwarp.ctio import write_tiff

    vol = np.asarray(volume)
    if vol.ndim != 3:
        raise _fail(f"phantom volume must be 3-D (Z, Y, X), got shape {vol.shape}")
    rv = _to_voxels(rods, voxel_size).copy()
    if contacts is None:
        contacts = rv.contacts if rv.contacts is not None else phantom_truth(rv)
    elif rods.units != "voxel":
        from rodwarp.rodset import UNITS
        k = UNITS[rods.units] / float(voxel_size)
        contacts = Contacts(contacts.rod_i, contacts.rod_j, contacts.point * k, contacts.gap * k)
    rv.contacts = contacts
    params = dict(params or {})
    rv.attrs = dict(rv.attrs)
    rv.attrs["phantom"] = json.loads(json.dumps(params, default=str))
    if voxel_size is not None:
        rv.attrs["voxel_size"] = float(voxel_size)
    npz, js = truth_paths(path_tif)
    m = 1e-6
    if rods.units != "voxel" and voxel_size is not None:
        from rodwarp.rodset import UNITS
        m = float(voxel_size) * UNITS[rods.units]
    write_tiff(path_tif, vol, voxel_size=(int(z_thickness) * m, m, m))
    rv.save(npz)
    meta = {"shape": list(vol.shape), "dtype": str(vol.dtype),
            "voxel_size": None if voxel_size is None else float(voxel_size),
            "seed": params.get("seed"), "n_rods": rv.n_rods, "n_contacts": len(contacts),
            "voxel_size_zyx_m": [int(z_thickness) * m, m, m],
            "truth_rods": npz.name, "coordinates": "voxel units: x = column, y = row, z = slice; "
                                                   "voxel (0,0,0) centred at the origin",
            "params": params}
    write_json(js, meta)
    return {"tiff": Path(path_tif), "truth_rods": npz, "truth_json": js}
