"""Local mesoscopic fields of a rod set on a voxel grid (host side of :mod:`rodwarp.kernels.fields`).

At every voxel centre x the ball Omega_R(x) of radius R is intersected exactly with every rod
segment (each clipped part is one segment).  The Warp kernels measure each ball once
(:class:`~rodwarp.analysis._registry.BallMeasures`: rods, clipped length and volume, the
nematic order, the entanglement, and point counts), and every field of the registry
(:data:`~rodwarp.analysis._registry.FIELDS`: ``phi``, ``S``, ``c``, ``e``, ``n``, ``contacts``,
``n_ends``) is computed from those measures by its row; ``docs/fields.md`` defines them.

Defaults follow the paper: R = sqrt(d l) with d the mean diameter and l the mean rod length,
grid spacing R / 2.  Voxels whose ball leaves the domain (the container box when the rod set
records one, else the rods' bounding box) are NaN unless ``keep_outside``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import warp as wp

from rodwarp import _warp
from rodwarp.analysis._fieldset import Fields
from rodwarp.analysis import _registry
from rodwarp.analysis._registry import BallMeasures
from rodwarp.errors import RodwarpError, RodwarpTypeError
from rodwarp.rodset import MAX_COORDINATE, Contacts, RodSet, detect_contacts
from rodwarp.arguments import instance, real

# Clipped parts held at once (each ~60 bytes): bounds memory on big grids.
MAX_CLIPPED_PER_BATCH = 2_000_000
#: smallest rod diameter and length accepted, as a fraction of the analysed domain's largest edge:
#: a grid of at most 2^31 voxels has a spacing of at least 4.7e-10 of it, so it resolves nothing finer
MIN_RELATIVE_LENGTH = 1e-9


@dataclass
class FieldParams:
    """Resolved parameters of a field computation (lengths in the rod set's units)."""

    radius: float
    spacing: float
    diameter: float
    length: float
    domain: np.ndarray  # (2, 3) lower and upper corner
    keep_outside: bool
    contact_tolerance: float


def _parts(k, start, count, a, b, seg, rod, length):
    """A :class:`rodwarp.kernels.fields.ClippedParts` of these arrays."""
    p = k.ClippedParts()
    p.start, p.count, p.a, p.b, p.seg, p.rod, p.length = start, count, a, b, seg, rod, length
    return p


#: the ball radius accepted, in rod diameters: below half a diameter a ball sees at most one rod's
#: cross-section (phi is 0 or 1, e and c vanish); the paper's R = sqrt(d l) is 5 to 18 d
MIN_RADIUS_DIAMETERS = 0.5
#: the grid spacing accepted, as fractions of the ball radius: finer than R / 100 resamples the
#: same balls (the fields vary over R) at 1e6 times the cost of the default R / 2; coarser than 2 R
#: leaves gaps between the balls
SPACING_RADII = (0.01, 2.0)


def _check_ball_and_grid(R: float, h: float, d: float, l: float, given_h: bool, units: str,
                         unit_hint: str | None = None) -> None:
    """The ball radius against the rods' diameter and the spacing against the radius (one line
    naming the option that is off; rods whose sizes are implausible for their units are
    pointed at ``--units`` first, ``unit_hint``)."""
    first = f"check the units first: {unit_hint}; else " if unit_hint else ""
    if R < MIN_RADIUS_DIAMETERS * d:
        raise RodwarpError(f"--radius {R:g} {units} is below half the rods' diameter d = {d:.3g} {units}: a ball "
                           f"that small sees one rod's cross-section at most; use --radius {MIN_RADIUS_DIAMETERS * d:.3g} "
                           f"or more (default sqrt(d l) = {math.sqrt(d * l):.3g} {units})")
    lo, hi = SPACING_RADII
    if given_h and not lo * R <= h <= hi * R:
        raise RodwarpError(f"--spacing {h:g} {units} is {h / R:.3g} ball radii (R = {R:g} {units}); it must be "
                           f"{lo:g} to {hi:g} R: " + ("finer resamples the same balls at a far higher cost"
                                                      if h < lo * R else "coarser leaves gaps between the balls")
                           + f"; {first}raise --spacing to {0.5 * R:.3g} (R / 2, the default) or leave it out")


def resolve_params(rods: RodSet, *, radius: float | None = None, spacing: float | None = None,
                   diameter: float | None = None, length: float | None = None, domain=None,
                   keep_outside: bool = False, contact_tolerance: float | None = None) -> FieldParams:
    """Fill in the paper's defaults and check every parameter (one-line errors).

    Parameters
    ----------
    rods : RodSet
        The rods; every length below is in ``rods.units``.
    radius : float, optional
        Ball radius R; default sqrt(d l).
    spacing : float, optional
        Grid spacing; default R / 2.
    diameter, length : float, optional
        Rod diameter d and length l used for the default R (and for the contact tolerance);
        default the rods' mean diameter and mean polyline length.
    domain : array_like (2, 3), optional
        Analysed box (lower corner, upper corner); default the container box recorded in the
        rod set, else its bounding box.
    keep_outside : bool
        Compute voxels whose ball leaves the domain instead of masking them (NaN).
    contact_tolerance : float, optional
        Surface gap below which two rods touch when contacts are detected (>= 0); default d / 10.

    Every length given must be positive and at most :data:`~rodwarp.rodset.MAX_COORDINATE`
    (1e12); ``diameter`` and ``length`` at least ``MIN_RELATIVE_LENGTH`` (1e-9) times the
    domain's largest edge (a grid of at most 2^31 voxels resolves nothing finer), ``radius`` at
    least d / 2 and ``spacing`` 0.01 to 2 R (:data:`MIN_RADIUS_DIAMETERS`, :data:`SPACING_RADII`).

    Raises
    ------
    TypeError
        ``rods`` not a RodSet, a length not a number, ``domain`` not 2 x 3 numbers.
    RodwarpError
        A value out of its range (named, with the range), or a grid that cannot be built.
    """
    instance("rods", rods, RodSet, "a RodSet (rodwarp.load(path) or RodSet.from_polylines(...))")
    if rods.n_rods == 0:
        raise RodwarpError("the rod set is empty: nothing to analyse")
    dom = _domain(rods.box if domain is None and rods.box is not None else
                  rods.bounding_box() if domain is None else domain, rods.units)
    floor = MIN_RELATIVE_LENGTH * float(np.max(dom[1] - dom[0]))

    def pos(v, name, least=None):
        if v is None:
            return None
        if least is None:  # the ball and the grid: their lower bounds are _check_ball_and_grid's
            real(name, v, gt=0, unit=rods.units)
            return real(name, v, le=MAX_COORDINATE, unit=rods.units)
        return real(name, v, ge=least, le=MAX_COORDINATE, unit=rods.units,
                    hint=f"at least {MIN_RELATIVE_LENGTH:g} of the analysed domain's largest edge")

    d = pos(diameter, "diameter", floor) or float(np.mean(rods.diameters))
    l = pos(length, "length", floor) or float(np.mean(rods.rod_lengths()))
    if not (d > 0 and l > 0):
        raise RodwarpError("rods have zero diameter or length; give --diameter and --length")
    R = pos(radius, "radius") or math.sqrt(d * l)
    h = pos(spacing, "spacing") or 0.5 * R
    from rodwarp.rodset.scale import unit_hint

    _check_ball_and_grid(R, h, d, l, spacing is not None, rods.units,
                         unit_hint(rods, float(np.max(dom[1] - dom[0]))))
    tol = 0.1 * d if contact_tolerance is None else real(
        "contact_tolerance", contact_tolerance, ge=0, le=MAX_COORDINATE, unit=rods.units, hint="a surface gap")
    size = dom[1] - dom[0]
    if not keep_outside and np.any(size < 2 * R):
        from rodwarp.rodset.scale import unit_hint

        hint = unit_hint(rods, float(np.max(size)))
        raise RodwarpError(
            f"no ball of radius R = {R:g} {rods.units} fits in the domain of size {size.round(6).tolist()} "
            f"{rods.units}; " + (f"check the units first: {hint}; else " if hint else "")
            + "lower --radius or pass --keep-outside")
    n_vox = np.prod(np.floor(size / h) + 1)
    if n_vox > 2**31 - 1:
        from rodwarp.rodset.scale import unit_hint

        # wrong units (a CSV in mm read as m) against a --spacing meant in the right ones is the
        # usual cause: say so before suggesting a coarser grid
        hint = unit_hint(rods, float(np.max(size)))
        if hint:
            raise RodwarpError(f"the grid would have {n_vox:.3g} voxels at spacing {h:g} {rods.units}: check the "
                               f"units first: {hint}; else raise --spacing")
        raise RodwarpError(f"the grid would have {n_vox:.3g} voxels; raise --spacing")
    return FieldParams(R, h, d, l, dom, bool(keep_outside), tol)


def _domain(domain, units: str) -> np.ndarray:
    """The analysed box as a (2, 3) array: finite, within ``MAX_COORDINATE``, not empty."""
    try:
        dom = np.asarray(domain, dtype=np.float64)
    except (TypeError, ValueError):
        dom = None
    if dom is None or dom.shape != (2, 3) or isinstance(domain, (str, bytes)):
        raise RodwarpTypeError(f"domain must be two corners (lower, upper) of 3 numbers each in {units}, "
                               f"got {domain!r}")
    if not np.isfinite(dom).all() or np.any(dom[1] <= dom[0]) or np.max(np.abs(dom)) > MAX_COORDINATE:
        raise RodwarpError(f"the analysis domain {dom.tolist()} is empty, not finite or beyond "
                           f"{MAX_COORDINATE:g} {units}; give domain as (lower corner, upper corner), upper above "
                           f"lower on every axis")
    return dom


def grid_axes(p: FieldParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Voxel-centre coordinates along x, y and z, centred in the domain at the given spacing.

    Parameters
    ----------
    p : FieldParams
        From :func:`resolve_params` (domain and spacing in the rods' units).

    Returns
    -------
    (x, y, z) : tuple of ndarray
        Coordinates in the rods' units; the grid has ``len(z), len(y), len(x)`` voxels.
    """
    out = []
    for k in range(3):
        lo, hi = p.domain[0, k], p.domain[1, k]
        n = int(math.floor((hi - lo) / p.spacing + 1e-9)) + 1
        first = lo + 0.5 * ((hi - lo) - (n - 1) * p.spacing)
        out.append(first + p.spacing * np.arange(n))
    return out[0], out[1], out[2]


def inside_mask(p: FieldParams, x, y, z) -> np.ndarray:
    """Voxels whose ball lies inside the domain (to 1e-9 R).

    Parameters
    ----------
    p : FieldParams
        Ball radius and domain.
    x, y, z : ndarray
        Voxel-centre coordinates (:func:`grid_axes`).

    Returns
    -------
    ndarray of bool, shape (nz, ny, nx)
    """
    eps = 1e-9 * p.radius
    ok = [(c - p.radius >= p.domain[0, k] - eps) & (c + p.radius <= p.domain[1, k] + eps)
          for k, c in enumerate((x, y, z))]
    return ok[2][:, None, None] & ok[1][None, :, None] & ok[0][None, None, :]


def compute_fields(rods: RodSet, *, radius: float | None = None, spacing: float | None = None,
                   diameter: float | None = None, length: float | None = None, domain=None,
                   keep_outside: bool = False, contacts: Contacts | None = None,
                   contact_tolerance: float | None = None, device: str | None = "cpu",
                   progress: Callable[[int, int], None] | None = None, convention: str = "text") -> Fields:
    """Every registered local field (phi, S, c, e, n, ...) of a rod set on a voxel grid (Warp kernels).

    Parameters
    ----------
    rods : RodSet
        Rods in any length unit; every length below is in that unit.
    radius, spacing, diameter, length, domain, keep_outside, contact_tolerance
        See :func:`resolve_params`.
    contacts : Contacts, optional
        The contacts of the packing (their contact points are counted per ball); default the
        rod set's own contacts, else contacts detected from the geometry
        (:func:`rodwarp.rodset.detect_contacts`, gap < ``contact_tolerance``).
    device : str
        Warp device (``cpu``, ``cuda``, ``auto``).
    progress : callable(done, total), optional
        Called after each batch with voxels done and voxels to do.
    convention : str
        ``"text"`` (default): the definitions of the paper's text (exact clipping, each rod pair
        once), Warp kernels.  ``"authors"``: the rules of the authors' MATLAB routine
        (:mod:`rodwarp.analysis._authors`, NumPy; its own grid, ``phi`` NaN, ``device`` unused).

    Returns
    -------
    Fields
        One array (nz, ny, nx) per registered field, NaN outside the domain; ``attrs`` record
        d, l, rho (rods per unit volume), Z (contacts per rod), the contact source and timings.

    Raises
    ------
    TypeError
        An argument of the wrong kind (``rods`` not a RodSet, ``contacts`` not Contacts, ...).
    RodwarpError
        A parameter out of its range (:func:`resolve_params`), or an unknown device.
    """
    p = resolve_params(rods, radius=radius, spacing=spacing, diameter=diameter, length=length,
                       domain=domain, keep_outside=keep_outside, contact_tolerance=contact_tolerance)
    if contacts is not None:
        instance("contacts", contacts, Contacts, "a Contacts object or None (detected from the geometry)")
    if progress is not None and not callable(progress):
        raise RodwarpTypeError(f"progress must be a callable progress(done, total) or None, got "
                               f"{type(progress).__name__}")
    from rodwarp.analysis._authors import CONVENTIONS, compute_authors_fields

    if convention not in CONVENTIONS:
        raise RodwarpError(f"convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    if convention == "authors":
        if contacts is None:
            contacts, source = resolve_contacts(rods, p.contact_tolerance)
        else:
            source = "given"
        return compute_authors_fields(rods, p, contacts, source, progress=progress)
    dev = _warp.resolve_device(device)
    from rodwarp.kernels import fields as k

    t_start = time.perf_counter()
    x, y, z = grid_axes(p)
    nx, ny, nz = len(x), len(y), len(z)
    compute = np.ones((nz, ny, nx), bool) if p.keep_outside else inside_mask(p, x, y, z)
    vox = np.flatnonzero(compute.reshape(-1)).astype(np.int32)
    origin = wp.vec3d(x[0], y[0], z[0])
    h = wp.float64(p.spacing)
    R = wp.float64(p.radius)

    p0, p1, seg_rod = rods.segments()
    seg_d = 2.0 * rods.radii[seg_rod]
    w_p0 = wp.array(p0, dtype=wp.vec3d, device=dev)
    w_p1 = wp.array(p1, dtype=wp.vec3d, device=dev)
    w_rod = wp.array(seg_rod.astype(np.int32), dtype=wp.int32, device=dev)
    w_d = wp.array(seg_d, dtype=wp.float64, device=dev)
    w_vox = wp.array(vox, dtype=wp.int32, device=dev)
    nv = len(vox)
    ns = len(seg_rod)
    slot = np.full(nz * ny * nx, -1, np.int32)
    slot[vox] = np.arange(nv, dtype=np.int32)
    w_slot = wp.array(slot, dtype=wp.int32, device=dev)
    dummy3 = wp.empty(1, dtype=wp.vec3d, device=dev)
    dummy_i = wp.empty(1, dtype=wp.int32, device=dev)
    dummy_f = wp.empty(1, dtype=wp.float64, device=dev)
    count = wp.zeros(nv, dtype=wp.int32, device=dev)
    grid = k.BallGrid()
    grid.nx, grid.ny, grid.nz, grid.origin, grid.spacing, grid.radius = nx, ny, nz, origin, h, R
    wp.launch(k.scatter_clipped_segments, dim=ns, device=dev,
              inputs=[w_p0, w_p1, w_rod, grid, w_slot, 0, nv, 0,
                      _parts(k, dummy_i, count, dummy3, dummy3, dummy_i, dummy_i, dummy_f)])
    counts = count.numpy().astype(np.int64)

    out_n = np.zeros(nv, np.int32)
    out_len = np.zeros(nv)
    out_vol = np.zeros(nv)
    out_S = np.zeros(nv)
    out_e = np.zeros(nv)
    t_pairs = time.perf_counter()
    done = 0
    for b0, b1 in _batches(counts, MAX_CLIPPED_PER_BATCH):
        cb = counts[b0:b1]
        start = np.zeros(len(cb), np.int64)
        np.cumsum(cb[:-1], out=start[1:])
        total = max(int(cb.sum()), 1)
        w_start = wp.array(start.astype(np.int32), dtype=wp.int32, device=dev)
        w_count = wp.array(cb.astype(np.int32), dtype=wp.int32, device=dev)
        fill = wp.zeros(len(cb), dtype=wp.int32, device=dev)
        ca = wp.empty(total, dtype=wp.vec3d, device=dev)
        cbb = wp.empty(total, dtype=wp.vec3d, device=dev)
        cs = wp.empty(total, dtype=wp.int32, device=dev)
        cr = wp.empty(total, dtype=wp.int32, device=dev)
        cl = wp.empty(total, dtype=wp.float64, device=dev)
        m = b1 - b0
        wp.launch(k.scatter_clipped_segments, dim=ns, device=dev,
                  inputs=[w_p0, w_p1, w_rod, grid, w_slot, int(b0), int(b1), 1,
                          _parts(k, w_start, fill, ca, cbb, cs, cr, cl)])
        wp.launch(k.sort_parts_by_segment, dim=m, device=dev, inputs=[w_start, w_count, ca, cbb, cs, cr, cl])
        o_n = wp.empty(m, dtype=wp.int32, device=dev)
        o_len = wp.empty(m, dtype=wp.float64, device=dev)
        o_vol = wp.empty(m, dtype=wp.float64, device=dev)
        o_S = wp.empty(m, dtype=wp.float64, device=dev)
        o_e = wp.empty(m, dtype=wp.float64, device=dev)
        wp.launch(k.ball_fields, dim=m, device=dev,
                  inputs=[_parts(k, w_start, w_count, ca, cbb, cs, cr, cl), w_d, o_n, o_len, o_vol, o_S, o_e])
        out_n[b0:b1] = o_n.numpy()
        out_len[b0:b1] = o_len.numpy()
        out_vol[b0:b1] = o_vol.numpy()
        out_S[b0:b1] = o_S.numpy()
        out_e[b0:b1] = o_e.numpy()
        done += m
        if progress is not None:
            progress(done, nv)
    t_fields = time.perf_counter() - t_pairs

    # the contacts of the packing, whose contact points are counted per ball
    if contacts is None:
        contacts, source = resolve_contacts(rods, p.contact_tolerance)
    else:
        source = "given"

    def count_points(points: np.ndarray) -> np.ndarray:
        return _count_points_in_balls(points, w_vox, nx, ny, origin, h, p.radius, dev)

    shape = (nz, ny, nx)
    measures = BallMeasures(rods=out_n, length=out_len, volume=out_vol, order=out_S, entanglement=out_e,
                            ball_volume=4.0 / 3.0 * math.pi * p.radius**3,
                            rod_volume=0.25 * math.pi * p.diameter**2 * p.length,
                            rod_set=rods, contacts=contacts, count_points=count_points)

    def scatter(vals):
        a = np.full(nz * ny * nx, np.nan)
        a[vox] = vals
        return a.reshape(shape)

    # every row of the registry, read now (not at import): the row is the one place a field is defined
    arrays = {spec.name: scatter(spec.kernel(measures)) for spec in _registry.FIELDS}
    attrs = {
        "convention": "text", "diameter": p.diameter, "length": p.length, "domain": p.domain.tolist(),
        "keep_outside": p.keep_outside, "rho": measures.rho, "Z": measures.Z,
        "c_normalisation": measures.contact_normalisation,
        "n_rods": rods.n_rods, "n_segments": int(len(seg_rod)), "n_contacts": len(contacts),
        "contact_source": source, "contact_tolerance": p.contact_tolerance,
        "n_voxels_computed": int(nv), "clipped_parts": int(counts.sum()),
        "device": dev, "wall_s": time.perf_counter() - t_start, "pairs_s": t_fields,
    }
    return Fields(**arrays, x=x, y=y, z=z, radius=p.radius, spacing=p.spacing, units=rods.units, attrs=attrs)


def _count_points_in_balls(points, w_vox, nx: int, ny: int, origin, h, radius: float, dev) -> np.ndarray:
    """Points (P, 3) within ``radius`` of each computed voxel's centre (int32 per voxel).

    A float32 hash grid finds the candidates with a query radius widened by the float32
    rounding of the points; ``count_contacts_in_ball`` re-tests each in float64.
    """
    from rodwarp.kernels import fields as k

    nv = w_vox.shape[0]
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0 or nv == 0:
        return np.zeros(nv, np.int32)
    cq = float(radius * (1 + 1e-5) + 1e-5 * (float(np.abs(points).max()) + radius))
    # a grid no finer than the points need (cells of the query radius; the hash wraps beyond):
    # a 128^3 grid's allocation and clearing cost more than counting a main job's contacts
    ext = points.max(axis=0) - points.min(axis=0)
    dims = [int(min(128, max(4, math.ceil(e / cq) + 2))) for e in ext]
    grid = wp.HashGrid(*dims, device=dev)
    grid.build(wp.array(points.astype(np.float32), dtype=wp.vec3, device=dev), radius=cq)
    out = wp.zeros(nv, dtype=wp.int32, device=dev)
    wp.launch(k.count_contacts_in_ball, dim=nv, device=dev,
              inputs=[grid.id, w_vox, nx, ny, origin, h, wp.float64(radius), cq,
                      wp.array(points, dtype=wp.vec3d, device=dev), out])
    return out.numpy()


def resolve_contacts(rods: RodSet, tolerance: float | None = None) -> tuple[Contacts, str]:
    """The contacts of the packing: the rod set's own when it has them, else from its geometry.

    Parameters
    ----------
    tolerance : float, optional
        Surface gap below which rods touch, in the rod set's units; default d / 10 (mean d).

    Returns
    -------
    (Contacts, str)
        The contacts and where they came from ("input" or "detected (...)").
    """
    if rods.contacts is not None:
        return rods.contacts, "input"
    tol = 0.1 * float(np.mean(rods.diameters)) if tolerance is None else float(tolerance)
    return detect_contacts(rods, tol), f"detected (surface gap < {tol:g} {rods.units})"


def _batches(counts: np.ndarray, cap: int):
    """Consecutive voxel ranges whose clipped-part totals stay below ``cap`` (at least one voxel)."""
    n = len(counts)
    b0 = 0
    csum = np.cumsum(counts)
    while b0 < n:
        base = csum[b0 - 1] if b0 else 0
        b1 = int(np.searchsorted(csum, base + cap, side="right"))
        b1 = min(max(b1, b0 + 1), n)
        yield b0, b1
        b0 = b1
