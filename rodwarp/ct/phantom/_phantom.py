"""Synthetic CT phantoms of rod sets, with ground truth, for validating segmentation.

Volumes are indexed ``(z, y, x)`` = (slice, row, column); a point in voxel units has
``x = column``, ``y = row``, ``z = slice`` and the centre of voxel ``(0, 0, 0)`` is the origin.
Physical coordinates are voxel coordinates times the voxel size.

:func:`render_phantom` (in :mod:`rodwarp.ct.phantom._phantom_render`, re-exported here) turns a rod set
into a 16-bit CT-like volume: partial-volume occupancy, cupping, blur, rings, streaks and noise.
This module holds the rest: :func:`write_phantom`
(a TIFF stack plus ``<stem>_truth.npz`` and ``<stem>_truth.json`` beside it) and
:func:`make_phantom`, the ``rodwarp phantom`` command. The scenes (voxel units, with their
true contacts) are built in :mod:`rodwarp.ct.phantom._scenes`, the truth (:func:`phantom_truth`,
:func:`truth_paths`) in :mod:`rodwarp.ct.phantom._truth`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rodwarp._util import json_safe
from rodwarp._util import one_line_error as _fail
from rodwarp.ct.phantom._phantom_render import _to_voxels, capsule_volume, occupancy, render_phantom  # noqa: F401
from rodwarp.ct.phantom._truth import DEFAULT_TOLERANCE_VOXELS, phantom_truth, truth_paths  # noqa: F401
from rodwarp.rodset import UNITS, Contacts, RodSet
from rodwarp.validation import Range

__all__ = ["render_phantom", "occupancy", "phantom_truth", "write_phantom", "truth_paths", "make_phantom",
           "PhantomOptions",
           "capsule_volume", "DEFAULT_TOLERANCE_VOXELS", "SCENES"]



# ----------------------------------------------------------------------------------------------
# output
# ----------------------------------------------------------------------------------------------

def write_phantom(path_tif, volume: np.ndarray, rods: RodSet, contacts: Contacts | None = None,
                  voxel_size: float | None = None, params: dict | None = None, z_thickness: int = 1, *,
                  units: str | None = None) -> dict:
    """Write a phantom TIFF and its ground truth beside it, each atomically.

    Writes ``path_tif`` (multi-page, ZYX), ``<stem>_truth.npz`` (the rods in voxel units with
    ``contacts``) and ``<stem>_truth.json`` (``params``, seed and voxel size, shape, counts).

    Parameters
    ----------
    voxel_size : float, optional
        Voxel width in metres (as everywhere in this module). The TIFF records it (ImageJ
        resolution and spacing, slices ``z_thickness`` widths apart) in ``units``, and the
        truth JSON states it in ``units`` with ``"units"`` beside it. None (a scene in voxel
        units): the TIFF records 1 um per voxel width, so that the slice spacing is on record,
        and the JSON says ``"units": "voxel"``, ``"voxel_size": 1``.
    units : str, optional
        ``m``, ``mm`` or ``um``: the unit the voxel size is recorded in; default the rods'
        unit when metric, else ``m``.

    Returns
    -------
    dict
        Paths written: ``{"tiff": ..., "truth_rods": ..., "truth_json": ...}``.
    """
    from rodwarp.rodset.files import write_json
    from rodwarp.ct.io import write_tiff

    vol = np.asarray(volume)
    if vol.ndim != 3:
        raise _fail(f"phantom volume must be 3-D (Z, Y, X), got shape {vol.shape}")
    rv = _to_voxels(rods, voxel_size).copy()
    if contacts is None:
        contacts = rv.contacts if rv.contacts is not None else phantom_truth(rv)
    elif rods.units != "voxel":
        k = UNITS[rods.units] / float(voxel_size)
        contacts = Contacts(contacts.rod_i, contacts.rod_j, contacts.point * k, contacts.gap * k)
    rv.contacts = contacts
    params = dict(params or {})
    rv.attrs = dict(rv.attrs)
    rv.attrs["phantom"] = json_safe(params)
    npz, js = truth_paths(path_tif)
    zt = int(z_thickness)
    if voxel_size is None:
        unit, size, m = "voxel", 1.0, 1e-6
    else:
        m = float(voxel_size)  # metres per voxel width
        unit = units or (rods.units if rods.units in ("m", "mm", "um") else "m")
        if unit not in ("m", "mm", "um"):
            raise _fail(f"units must be m, mm or um (the unit the voxel size is recorded in), got {unit!r}")
        size = m / UNITS[unit]
        rv.attrs["voxel_size"] = size
        rv.attrs["voxel_size_units"] = unit
    # the truth JSON is the phantom's manifest: incomplete until its last write, so a kill in
    # between never leaves the TIFF of one phantom beside the truth of another passing as whole
    from rodwarp.ct.phantom._phantom_owner import PHANTOM_FORMAT, mark_truth

    mark_truth(path_tif, complete=False, tiff=Path(path_tif).name, seed=params.get("seed"))
    # the TIFF states the voxel in the rods' unit: segment then reports lengths in it by default
    # a scene has no physical scale: its TIFF says so (ImageJ unit 'pixel'), and segment then
    # reports in voxels instead of inventing micrometres
    write_tiff(path_tif, vol, voxel_size=(zt, 1, 1) if unit == "voxel" else (zt * m, m, m), unit=unit)
    rv.save(npz)
    meta = {"shape": list(vol.shape), "dtype": str(vol.dtype),
            "voxel_size": size, "units": unit,
            "voxel_size_zyx": [zt * size, size, size],
            "seed": params.get("seed"), "n_rods": rv.n_rods, "n_contacts": len(contacts),
            "voxel_size_zyx_m": None if unit == "voxel" else [zt * m, m, m],
            "truth_rods": npz.name, "coordinates": "voxel units: x = column, y = row, z = slice; "
                                                   "voxel (0,0,0) centred at the origin",
            "params": params, "format": PHANTOM_FORMAT, "complete": True, "status": "complete"}
    write_json(js, meta)
    return {"tiff": Path(path_tif), "truth_rods": npz, "truth_json": js}


# ----------------------------------------------------------------------------------------------
# the command
# ----------------------------------------------------------------------------------------------

#: scenes ``rodwarp phantom`` builds by name (voxel units)
SCENES = ("random", "bundles", "arcs", "wires")


def _opt(default, help: str, range: Range | None = None):
    """A :class:`PhantomOptions` field: its default, its ``--help`` line and the
    :class:`~rodwarp.validation.Range` of values it takes (:func:`rodwarp.ct.check_phantom`)."""
    return field(default=default, metadata={"help": help, "range": range})


@dataclass(frozen=True)
class PhantomOptions:
    """The options of :func:`make_phantom` (``rodwarp phantom``): every default and help line
    stated once; the command takes its options from here."""

    voxel_size: float = _opt(1.0, "Voxel edge length in the rods' units (--units; 1 for voxel-unit rods). The TIFF "
                                  "and the truth JSON record it in that unit; the rods must be at least a voxel "
                                  "thick and fit --shape.",
          range=Range(gt=0, le=1e12, hint="in the rods' units (--units)"))
    units: str | None = _opt(None, "Unit of a CSV rod set (m, mm, um, voxel; default m) and of --voxel-size; "
                                   "converts npz/zarr rod sets.")
    blur: float = _opt(1.0, "Gaussian point-spread sigma (voxels).",
          range=Range(ge=0, le=100, unit="voxels"))
    cnr: float = _opt(10.0, "Contrast-to-noise ratio (foreground - background) / noise sigma.",
          range=Range(gt=0, le=1e6))
    ring: float = _opt(0.0, "Ring artefact amplitude (fraction of the contrast, 0 to 1).",
          range=Range(ge=0, le=1, hint="a fraction of the rod/background contrast; beyond 1 it clips at 0 or 65535"))
    cupping: float = _opt(0.0, "Cupping: relative intensity drop at the slice edge (negative: a bright rim, as "
                               "beam hardening shows).",
          range=Range(gt=-1, lt=1, hint="a relative intensity drop (negative: a bright rim)"))
    streaks: float = _opt(0.0, "Metal streak amplitude (fraction of the contrast, 0 to 1).",
          range=Range(ge=0, le=1, hint="a fraction of the rod/background contrast; beyond 1 it clips at 0 or 65535"))
    fov: float | None = _opt(None, "Field of view: radius (voxels) of the reconstruction circle; 0 outside it.",
          range=Range(gt=0, le=1e6, unit="voxels"))
    dark: bool = _opt(False, "Dark rods on a bright background (grey values swapped).")
    z_thickness: int = _opt(1, "Slices this many times thicker than the voxels are wide (anisotropic voxels; the "
                               "TIFF records the spacing).",
          range=Range(ge=1, le=100, whole=True))
    n_rods: int = _opt(100, "'random', 'arcs', 'wires': number of rods; 'bundles': of bundles.",
          range=Range(ge=1, le=10_000_000, whole=True))
    radius: float = _opt(3.0, "Scenes: rod radius (voxels, at least 0.5).",
          range=Range(ge=0.5, le=1e4, unit="voxels", hint="a rod must be at least a voxel thick to show"))
    aspect: float = _opt(30.0, "'random': aspect ratio length / diameter.",
          range=Range(gt=1, le=1e4))
    touching: float = _opt(0.5, "'random': fraction of rods touching another.",
          range=Range(ge=0, le=1))
    seed: int = _opt(0, "Seed of the noise and of the scenes.",
          range=Range(ge=0, le=2**63 - 1, whole=True))


def make_phantom(rods: str, shape, out, **options) -> RodSet:
    """Render a rod set, or a named scene, as a 16-bit CT stack with its ground truth (``rodwarp phantom``).

    Parameters
    ----------
    rods : str
        A rod-set file (npz, zarr, CSV), a ``rodwarp simulate`` output folder (its
        ``final.npz``), or a scene of :data:`SCENES` built in voxel units: ``random``
        (:func:`~rodwarp.ct.scene_random_packing`), ``bundles``, ``arcs``, ``wires``.
    shape : (int, int, int)
        Volume shape Z, Y, X (slices, rows, columns).
    out : path-like
        The TIFF; the truth is written beside it (:func:`write_phantom`).
    voxel_size : float
        Voxel edge in the rods' units (``units``; 1 for rods in voxel units). The TIFF and the
        truth JSON record it in that unit (:func:`write_phantom`).
    blur, cnr, ring, cupping, streaks, fov, dark, z_thickness
        Image model, see :func:`render_phantom` (blur and fov in voxels).
    n_rods, radius, aspect, touching
        Scenes: rods (bundles for ``bundles``), radius (voxels), aspect ratio and fraction of
        touching rods (``random``).
    seed : int
        Seed of the noise and of the scenes.
    units : str, optional
        Unit of a CSV rod set (m, mm, um, voxel; default m, as a CSV does not record it); an
        npz/zarr rod set in metric units is converted to it. ``voxel_size`` is in this unit.

    The options (all keywords) are the fields of :class:`PhantomOptions`, with their defaults.

    Returns
    -------
    RodSet
        The rendered rods in voxel units, with their true contacts.

    Raises
    ------
    RodwarpError
        Rods thinner than one voxel (the message gives the diameter in voxels and a
        ``--voxel-size`` that puts 4 voxels across), or reaching outside the volume (the
        message gives their extent in voxels, and a ``--shape`` or ``--voxel-size`` that fits).
    """
    import numpy as np

    from rodwarp.ct.phantom import _scenes as sc
    from rodwarp.rodset import detect_contacts, load

    o = PhantomOptions(**options)
    voxel_size, blur, cnr, ring, cupping, streaks, fov, dark = (o.voxel_size, o.blur, o.cnr, o.ring, o.cupping,
                                                                o.streaks, o.fov, o.dark)
    z_thickness, n_rods, radius, aspect, touching, seed, units = (o.z_thickness, o.n_rods, o.radius, o.aspect,
                                                                  o.touching, o.seed, o.units)

    # scenes are built in voxel widths along every axis; thick slices span z_thickness of them
    full = (shape[0] * z_thickness, shape[1], shape[2])
    builders = {
        "random": lambda: sc.scene_random_packing(full, n_rods=n_rods, radius=radius, aspect=aspect,
                                                  touching_fraction=touching, seed=seed,
                                                  fov_radius=None if fov is None else fov - 2.0),
        "bundles": lambda: sc.scene_bundles(full, n_bundles=n_rods, radius=radius, seed=seed),
        "arcs": lambda: sc.scene_arcs(full, n_rods=n_rods, radius=radius, seed=seed),
        "wires": lambda: sc.scene_wire_tangle(full, n_wires=n_rods, radius=radius, seed=seed),
    }
    if rods in builders:
        rs = builders[rods]()
        if z_thickness > 1:  # thick slice k is centred at z = k z_thickness
            rs.points[:, 2] -= 0.5 * (z_thickness - 1)
            rs.contacts = phantom_truth(rs)
        vox = 1.0
    else:
        p = Path(rods)
        if p.is_dir() and (p / "final.npz").exists():
            p = p / "final.npz"
        rs = load(p)
        from rodwarp.rodset.sanity import check_rod_geometry

        check_rod_geometry(rs, str(p))  # duplicated or degenerate rods would be false ground truth
        if units is not None and units != rs.units:
            if p.suffix.lower() == ".csv":
                rs = load(p, units=units)  # a CSV does not record its unit: --units names it
            elif rs.units == "voxel" or units == "voxel":
                raise _fail(f"{p} records its rods in '{rs.units}'; --units {units} cannot convert to or from voxels "
                            f"without a scale: drop --units and give --voxel-size in '{rs.units}'")
            else:
                rs = rs.to_units(units)  # --voxel-size is in --units
        src_units = rs.units
        if rs.units == "voxel":
            if voxel_size != 1.0:
                raise _fail("the rods are in voxel units: drop --voxel-size (it is 1)")
            vox = 1.0
        else:
            vox = voxel_size * UNITS[rs.units]  # metres per voxel
            rs = rs.to_units("voxel", voxel_size=vox)
        _check_scale(rs, shape, z_thickness, voxel_size, src_units, p)
        rs.contacts = detect_contacts(rs, 0.1 * float(np.mean(rs.diameters)))
    bg, fg = (50000, 20000) if dark else (20000, 50000)
    vol = render_phantom(rs, tuple(shape), blur_sigma=blur, cnr=cnr, ring=ring, cupping=cupping, streaks=streaks,
                         seed=seed, fov=fov, z_thickness=z_thickness, background=bg, foreground=fg)
    params = {"shape": list(shape), "voxel_size": voxel_size, "blur_sigma": blur, "cnr": cnr, "ring": ring,
              "cupping": cupping, "streaks": streaks, "fov": fov, "dark": dark, "z_thickness": z_thickness,
              "seed": seed, "source": rods, "metres_per_voxel": vox if rods not in builders else None}
    if rods in builders or src_units == "voxel":
        params["units"] = "voxel"
        write_phantom(out, vol, rs, rs.contacts, None, params, z_thickness=z_thickness)
    else:
        params["units"] = src_units  # the unit --voxel-size is in
        write_phantom(out, vol, rs, rs.contacts, vox, params, z_thickness=z_thickness, units=src_units)
    return rs


def _check_scale(rv: RodSet, shape, z_thickness: int, voxel_size: float, units: str, source) -> None:
    """Refuse rods (``rv``, in voxel units) a CT of ``shape`` cannot show: thinner than one
    voxel, or reaching outside the volume by more than a voxel. ``voxel_size`` is in ``units``
    (the rods' own unit), for the suggested fixes."""
    zt = int(z_thickness)
    d = 2.0 * float(np.median(rv.radii))
    metric = units != "voxel"
    if d < 1.0:
        if metric:
            fix = (f"pass --voxel-size {d * voxel_size / 4.0:.3g} (4 voxels across; the rods are "
                   f"{d * voxel_size:.4g} {units} thick)")
        else:
            fix = "give thicker rods (their radii are in voxels)"
        raise _fail(f"the rods of {source} are {d:.3g} voxels thick at --voxel-size {voxel_size:g} {units}: a CT "
                    f"cannot resolve them (the image would be noise); {fix}")
    r = rv.radii[np.repeat(np.arange(rv.n_rods), np.diff(rv.offsets))][:, None]
    lo = (rv.points - r).min(axis=0)  # x, y, z in voxel widths
    hi = (rv.points + r).max(axis=0)
    Z, Y, X = (int(v) for v in shape)
    # voxel centres run from 0 to N-1 (z: thick slices zt widths apart, centred at k zt)
    vlo = np.array([-0.5, -0.5, -0.5 * zt])
    vhi = np.array([X - 0.5, Y - 0.5, (Z - 0.5) * zt])
    slack = 1.0  # partial-volume voxels at the faces are fine
    if np.all(lo >= vlo - slack) and np.all(hi <= vhi + slack):
        return
    span = " x ".join(f"{a:.4g}..{b:.4g}" for a, b in zip(lo, hi))
    have = f"--shape {Z} {Y} {X} (Z Y X) holds x, y, z from -0.5 to {vhi[0]:g}, {vhi[1]:g}, {vhi[2]:g} voxel widths"
    if np.any(lo < vlo - slack):
        raise _fail(f"the rods of {source} reach outside the volume: they span x, y, z = {span} voxel widths and "
                    f"{have}; shift the rods to coordinates >= 0 (the first voxel is centred at the origin)")
    need = np.ceil([(hi[2] + 0.5 * zt) / zt, hi[1] + 0.5, hi[0] + 0.5]).astype(int)
    fit = max(float(np.max(hi[:2] / vhi[:2])), float(hi[2] / vhi[2]))
    also = f" or raise --voxel-size to {voxel_size * fit:.3g} {units}" if metric else ""
    raise _fail(f"the rods of {source} do not fit the volume: they span x, y, z = {span} voxel widths and {have}; "
                f"enlarge --shape to {need[0]} {need[1]} {need[2]}{also}")
