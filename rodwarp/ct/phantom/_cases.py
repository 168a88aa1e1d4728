"""Phantom scans with ground truth for the things real reconstructions contain.

Each case is a small synthetic CT (:func:`rodwarp.ct.render_phantom`) of a known rod set with one difficulty
of real scans: a field-of-view mask, cupping, rings, anisotropic voxels, mixed radii, bundles
of touching rods, thin rods, dark rods on a bright background, gently curved rods, a tangle of
curved wires; plus the easy cases (isolated straight rods at CNR 5 and 2, rods cut by the
faces).  The tests and ``benchmarks/bench_segment_scans.py`` score the segmentation on them.

:func:`make_case` returns a :class:`ScanCase`: the volume, the truth in *physical* units
(voxel widths: x and y in voxels, z in voxel widths too, so an anisotropic scan's truth is in
the same units as an isotropic one's), the voxel size (Z, Y, X) in those units and whether the
truth is curved.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rodwarp.ct.phantom._phantom_render import render_phantom
from rodwarp.ct.phantom._truth import phantom_truth
from rodwarp.ct.phantom._scenes import scene_arcs, scene_bundles, scene_random_packing, scene_wire_tangle
from rodwarp.rodset import RodSet

__all__ = ["ScanCase", "CASES", "make_case", "crop_straight", "scored_subset"]


@dataclass
class ScanCase:
    """One phantom scan and its truth.

    Attributes
    ----------
    name : str
        Case name (a key of :data:`CASES`).
    volume : ndarray (Z, Y, X) uint16
        The scan.
    truth : RodSet
        True rods in units of the voxel width (``units="voxel"``), contacts included.
    voxel_size : tuple of float
        Voxel edge lengths (z, y, x) in the truth's units ((1, 1, 1) unless anisotropic).
    curved : bool
        The truth holds curved filaments (score with ``match_polylines``).
    face_margin : float or None
        Rods (found or true) whose axis midpoint lies within this of a volume face graze it
        and are left out of the scores (:func:`scored_subset`).
    notes : str
        What the case contains.
    params : dict
        Phantom parameters (seeds included).
    """

    name: str
    volume: np.ndarray
    truth: RodSet
    voxel_size: tuple = (1.0, 1.0, 1.0)
    curved: bool = False
    face_margin: float | None = None
    notes: str = ""
    params: dict = field(default_factory=dict)


def crop_straight(rods: RodSet, lo_xyz, hi_xyz, min_length: float = 0.0) -> RodSet:
    """Straight rods clipped to the box ``lo <= p <= hi`` (per axis); rods that end up shorter
    than ``min_length`` are dropped.  Coordinates are shifted so that ``lo`` is the origin."""
    lo = np.asarray(lo_xyz, float)
    hi = np.asarray(hi_xyz, float)
    polys, radii = [], []
    for k in range(rods.n_rods):
        p = rods.rod(k)
        a, b = p[0], p[-1]
        d = b - a
        t0, t1 = 0.0, 1.0
        for ax in range(3):
            if abs(d[ax]) < 1e-12:
                if not (lo[ax] <= a[ax] <= hi[ax]):
                    t0, t1 = 1.0, 0.0
                continue
            ta, tb = (lo[ax] - a[ax]) / d[ax], (hi[ax] - a[ax]) / d[ax]
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        if t1 <= t0 or (t1 - t0) * np.linalg.norm(d) < min_length:
            continue
        polys.append(np.stack([a + t0 * d, a + t1 * d]) - lo)
        radii.append(rods.radii[k])
    out = RodSet.from_polylines(polys, np.asarray(radii), units="voxel")
    out.contacts = phantom_truth(out)
    return out


def _packing(shape, seed, cnr=5.0, blur=1.0, n_rods=40, radius=3.0, aspect=12.0, touching_fraction=0.5, **render):
    truth = scene_random_packing(shape, n_rods=n_rods, radius=radius, aspect=aspect, seed=seed,
                                 touching_fraction=touching_fraction, max_attempts=400000,
                                 fov_radius=render.pop("fov_radius", None))
    vol = render_phantom(truth, shape, blur_sigma=blur, cnr=cnr, seed=seed, **render)
    return truth, vol


def _case_baseline(seed):
    return _packing((160, 160, 160), seed), {}


def _case_cnr2(seed):
    return _packing((160, 160, 160), seed, cnr=2.0), {}


def _case_faces(seed):
    big = (224, 224, 224)
    truth = scene_random_packing(big, n_rods=70, radius=3.0, aspect=14.0, seed=seed, max_attempts=200000)
    vol = render_phantom(truth, big, blur_sigma=1.0, cnr=5.0, seed=seed)
    o = 32
    vol = np.ascontiguousarray(vol[o:o + 160, o:o + 160, o:o + 160])
    # rods cut by the faces end at the last voxel centre inside (x = -0 .. 159)
    cut = crop_straight(truth, (o, o, o), (o + 159, o + 159, o + 159), min_length=12.0)
    # rods grazing a face (axis midpoint within r + 1 of it) are half outside: not scored
    return (cut, vol), {"face_margin": 4.0}


def _case_fov(seed):
    shape = (160, 160, 160)
    truth, vol = _packing(shape, seed, fov_radius=72.0, fov=76.0)
    return (truth, vol), {}


def _case_cupping(seed):
    # beam hardening as reconstructions show it: a bright rim (and dark centre); a background
    # 3.3 times the contrast, so that 30% lifts the corners by a whole contrast
    return _packing((160, 160, 160), seed, cupping=-0.3, background=40000, foreground=52000), {}


def _case_cupping_rings(seed):
    return _packing((160, 160, 160), seed, cupping=-0.15, ring=0.3, background=40000, foreground=52000), {}


def _case_mixed_radii(seed):
    shape = (160, 160, 160)
    truth = scene_random_packing(shape, n_rods=40, radius=(2.0, 5.0), aspect=10.0, seed=seed,
                                    max_attempts=200000)
    vol = render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=seed)
    return (truth, vol), {}


def _case_bundles(seed):
    shape = (128, 128, 128)
    truth = scene_bundles(shape, n_bundles=10, sizes=(3, 5), radius=3.0, length=80.0, seed=seed)
    vol = render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=seed)
    return (truth, vol), {}


def _case_dense(seed):
    # a dense packing: 110 rods (volume fraction about 0.08), 80% of them touching another
    return _packing((160, 160, 160), seed, n_rods=110, touching_fraction=0.8), {}


def _case_dense_bundles(seed):
    # bundles inside a dense packing: 6 bundles of 3-5 touching rods, and the rods of a random
    # packing (60% touching) that keep 2 voxels from every bundle rod
    from rodwarp.rodset import segment_distance

    shape = (160, 160, 160)
    bun = scene_bundles(shape, n_bundles=6, sizes=(3, 5), radius=3.0, length=80.0, seed=seed)
    pack = scene_random_packing(shape, n_rods=90, radius=3.0, aspect=12.0, touching_fraction=0.6, seed=seed + 1,
                                max_attempts=400000)
    A, B = bun.points[0::2], bun.points[1::2]
    polys = [bun.rod(k) for k in range(bun.n_rods)]
    for k in range(pack.n_rods):
        p = pack.rod(k)
        d = segment_distance(np.repeat(p[:1], len(A), 0), np.repeat(p[-1:], len(A), 0), A, B)
        if d.min() >= 2 * 3.0 + 2.0:
            polys.append(p)
    truth = RodSet.from_polylines(polys, 3.0, units="voxel")
    truth.contacts = phantom_truth(truth)
    vol = render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=seed)
    return (truth, vol), {}


def _case_thin(seed):
    return _packing((160, 160, 160), seed, n_rods=60, radius=1.5, aspect=20.0, blur=1.2), {}


def _case_thin_faint(seed):
    return _packing((160, 160, 160), seed, n_rods=60, radius=2.0, aspect=16.0, blur=1.5, cnr=3.0), {}


def _case_anisotropic(seed):
    # z voxels twice as thick as x, y: 160 x 160 x 160 voxel widths in 80 slices
    shape = (80, 160, 160)
    full = scene_random_packing((160, 160, 160), n_rods=40, radius=3.0, aspect=12.0, seed=seed,
                                   max_attempts=200000)
    # thick slice k is centred at z = 2k (voxel widths): keep the rods within the 80 slices
    truth = full.copy()
    truth.points[:, 2] -= 0.5
    vol = render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=seed, z_thickness=2)
    return (truth, vol), {"voxel_size": (2.0, 1.0, 1.0)}


def _case_dark(seed):
    truth = scene_random_packing((160, 160, 160), n_rods=40, radius=3.0, aspect=12.0, seed=seed,
                                    max_attempts=200000)
    vol = render_phantom(truth, (160, 160, 160), blur_sigma=1.0, cnr=5.0, seed=seed,
                            background=50000, foreground=20000)
    return (truth, vol), {}


def _case_arcs(seed):
    shape = (160, 160, 160)
    truth = scene_arcs(shape, n_rods=20, radius=3.0, length=100.0, curvature_radius=(2.0, 5.0), seed=seed)
    vol = render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=seed)
    return (truth, vol), {"curved": True}


def _case_wires(seed):
    shape = (160, 160, 160)
    truth = scene_wire_tangle(shape, n_wires=20, radius=2.5, seed=seed)
    vol = render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=seed)
    return (truth, vol), {"curved": True}


#: name -> (builder, description)
CASES = {
    "baseline": (_case_baseline, "40 straight rods r 3, CNR 5, blur 1, 160^3"),
    "cnr2": (_case_cnr2, "the same at CNR 2"),
    "faces": (_case_faces, "rods cut by the volume faces (a 160^3 crop of a 224^3 packing)"),
    "fov": (_case_fov, "zeros outside a circular field of view (radius 76 voxels)"),
    "cupping": (_case_cupping, "cupping (beam hardening) 30%: bright rim, background 3.3x the contrast"),
    "cupping_rings": (_case_cupping_rings, "cupping 15% and ring artefacts (0.3 of the contrast), background 3.3x the contrast"),
    "mixed_radii": (_case_mixed_radii, "radii mixed uniformly in 2..5 voxels"),
    "bundles": (_case_bundles, "10 bundles of 3-5 parallel touching rods, 128^3"),
    "dense": (_case_dense, "a dense packing: 110 rods r 3, 80% touching, 160^3"),
    "dense_bundles": (_case_dense_bundles, "6 bundles of 3-5 touching rods inside a dense packing (about 60 more rods), 160^3"),
    "thin": (_case_thin, "thin rods: r 1.5 voxels at blur 1.2"),
    "thin_faint": (_case_thin_faint, "thin faint rods: r 2, blur 1.5, CNR 3"),
    "anisotropic": (_case_anisotropic, "z voxels twice as thick as x, y"),
    "dark": (_case_dark, "dark rods on a bright background"),
    "arcs": (_case_arcs, "20 gently curved rods (arcs, radius of curvature 2-5 rod lengths)"),
    "wires": (_case_wires, "a nest-like tangle of 20 curved wires"),
}


def make_case(name: str, seed: int = 0) -> ScanCase:
    """Build the phantom scan ``name`` (see :data:`CASES`) for ``seed``."""
    if name not in CASES:
        from rodwarp.errors import RodwarpError

        raise RodwarpError(f"unknown scan case '{name}'; choose one of {', '.join(CASES)}")
    fn, notes = CASES[name]
    (truth, vol), extra = fn(int(seed))
    return ScanCase(name=name, volume=vol, truth=truth, voxel_size=tuple(extra.get("voxel_size", (1.0, 1.0, 1.0))),
                    curved=bool(extra.get("curved", False)), face_margin=extra.get("face_margin"), notes=notes,
                    params={"seed": int(seed)})


def scored_subset(rods: RodSet, contacts, shape_xyz, margin: float | None):
    """The rods whose axis midpoint lies at least ``margin`` inside the box ``[0, n - 1]`` of
    every axis, and the contacts among them (re-indexed); everything when ``margin`` is None."""
    from rodwarp.rodset import Contacts

    if margin is None or rods.n_rods == 0:
        return rods, contacts
    hi = np.asarray(shape_xyz, float) - 1.0
    mid = np.array([0.5 * (rods.rod(k)[0] + rods.rod(k)[-1]) for k in range(rods.n_rods)])
    keep = np.all((mid >= margin) & (mid <= hi - margin), axis=1)
    idx = np.flatnonzero(keep)
    if len(idx) == 0:
        return rods, contacts
    new = -np.ones(rods.n_rods, np.int64)
    new[idx] = np.arange(len(idx))
    sub = RodSet.from_polylines([rods.rod(k) for k in idx], rods.radii[idx], units=rods.units)
    if contacts is None:
        return sub, None
    ok = keep[contacts.rod_i] & keep[contacts.rod_j]
    return sub, Contacts(new[contacts.rod_i[ok]], new[contacts.rod_j[ok]], contacts.point[ok], contacts.gap[ok])
