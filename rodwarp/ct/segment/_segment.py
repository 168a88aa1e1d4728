"""CT segmentation on the CPU, the driver: rod centrelines, radii and contacts from a greyscale volume.

The volume is indexed ``(z, y, x)`` = (slice, row, column); every point returned is ``(x, y, z)``
in (working) voxel units with the centre of voxel ``(0, 0, 0)`` at the origin.

:func:`segment_volume` runs the stages in order, each in its own module (each stage is timed
in ``SegmentResult.timings``):

====  ==============  ===================  ===================================================
  0   prepare         ``_prepare``         field-of-view mask, background trend (cupping,
                                           rings), dark rods negated, anisotropic voxels
                                           resampled onto an isotropic grid; a binarised
                                           stack (two levels, ``_binary``) made the rods' mask
  1   stats           ``_levels``          levels and binarisation: background, plateau,
                                           threshold, coarse radius, mixed radii (of a mask:
                                           levels 0 and 1, ``_binary.mask_levels``)
  2   detect          ``_seeds``,          per chunk: skeleton seeds, cylinder fits and
                      ``_tracing``,        marching, rods side by side and bundles split
                      ``_bundles``
  3   merge           ``_pasting``         pieces of one rod pasted, duplicates made one
  4   refine          ``_refine``          axes, radii and ends against the raw greyscale
                                           (the blurred-rod model of ``_profile``; of a mask,
                                           radii from its distance transforms)
  5   contacts        ``_contacts``        contact candidates confirmed by the image
====  ==============  ===================  ===================================================

With ``shape="curved"`` (or ``"auto"`` when the skeleton's long branches bend smoothly)
filaments are traced as polylines instead (``_curved``), which does stages 3-5 its own way.
``SegmentResult.quality["flags"]`` says in words when the output should not be trusted;
``_score`` scores a result against a phantom's truth, ``_report`` writes the files of
``rodwarp segment``.  This module must not import warp.

Every stage returns its own result (``Prepared``, ``_Levels``, ``TraceResult``/``TraceStats``,
``RefineStats``, ``FilamentResult``); none writes into a dict it is handed.
:func:`_assemble_result` alone composes ``SegmentResult.quality`` from them, so the keys of
``summary.json`` are written in one place.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict
from typing import TYPE_CHECKING, Callable, NamedTuple

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.ct._binary import LIKELY_INVERTED_FRACTION, mask_levels
from rodwarp.ct._contacts import confirm_contacts
from rodwarp.ct._levels import _Levels, _measure_levels
from rodwarp.ct._params import _HINT, SegmentParams, SegmentResult
from rodwarp.ct._pasting import _gap_filler, _merge_lines
from rodwarp.ct._reader import _Reader
from rodwarp.ct._refine import RefineStats, _check_rod, _refine, _Rod
from rodwarp.ct._tracing import TraceStats, _detect_block
from rodwarp.ct._voxels import _canonical, _unit
from rodwarp.rodset import RodSet, detect_contacts

if TYPE_CHECKING:  # annotations only: _prepare and _curved load when a run needs them
    from rodwarp.ct._curved import FilamentResult
    from rodwarp.ct._doubt import Doubt
    from rodwarp.ct._prepare import Prepared

__all__ = ["segment_volume", "AUTO_BEND_FRACTION"]


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


#: smallest volume edge (voxels) segmentation accepts: the thinnest rod it resolves is about
#: 2 voxels across (radius 1), its blurred edges take ~2 voxels on each side and the background
#: around it another voxel or two; a smaller volume cannot hold a rod and would only be told
#: "no rods found" after the whole search
MIN_EDGE_VOXELS = 8


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
        (:mod:`rodwarp.ct._prepare`); the result's coordinates are in units of that edge
        (``SegmentResult.spacing``), with voxel (0, 0, 0) at the origin.

    Returns
    -------
    SegmentResult
        ``quality`` holds: ``fit_residual`` (mean RMS of slab centroids about the fitted axes,
        voxels), ``foreground_explained`` (fraction of binarised foreground within r + 1.5 of a
        traced rod), ``rods_rejected`` (by reason), ``candidates``, ``merged``, ``seeds``,
        ``skeleton_junctions``, ``background``/``foreground`` levels, ``cnr`` (estimated),
        ``contrast_fit``, ``blur_sigma``, ``radius_spread`` (std of per-rod radii),
        ``contacts_rejected_by_image``; ``binarised``: ``{"levels": [lo, hi], "rod_level": v,
        "rod_fraction": f}`` when the volume held exactly two values (segmented from its mask),
        else None.

    Raises
    ------
    RodwarpError
        One line: not 3-D, empty, constant, non-finite, a label image (a handful of distinct
        values), a binarised stack whose rods' level is nearly empty or nearly full, or no
        rods found.
    """
    P = params if params is not None else SegmentParams()
    if not isinstance(P, SegmentParams):
        raise _fail(f"params must be a SegmentParams, got {type(P).__name__}")
    P.validate()
    t_all = time.perf_counter()
    timings: dict[str, float] = {}

    def note(stage, done, total):
        if progress is not None:
            progress(stage, done, total)

    from rodwarp.ct._prepare import _Corrected, prepare_volume

    tic = time.perf_counter()
    shape = _Reader(volume).shape  # shape and dtype checks first, with their own messages
    if min(shape) < MIN_EDGE_VOXELS:
        raise _fail(f"volume shape {shape} is too small to hold a rod: every dimension needs at least "
                    f"{MIN_EDGE_VOXELS} voxels (a rod about 2 voxels across, its blurred edges and some "
                    f"background); give the whole CT stack")
    prep = prepare_volume(volume, voxel_size, dark=P.dark, fov=P.fov, background=P.background)
    vol = prep.volume
    if isinstance(vol, _Corrected) and isinstance(volume, np.ndarray):
        vol = vol[:, :, :]  # in memory anyway: gathers from an array are much faster
    reader = _Reader(vol)
    timings["prepare"] = time.perf_counter() - tic
    tic = time.perf_counter()
    note("stats", 0, 1)
    st = mask_levels(reader, P) if prep.binarised is not None else _measure_levels(reader, P)
    note("stats", 1, 1)
    timings["stats"] = time.perf_counter() - tic
    noise = prep.notes.get("noise") or st.noise
    cnr = (st.fg - st.bg) / noise if noise > 0 else float("inf")
    if P.shape == "curved":
        return _finish_curved(reader, st, P, prep, cnr, timings, t_all, progress)

    # detection
    tic = time.perf_counter()
    halo = P.chunk_halo if P.chunk_halo is not None else \
        int(max(math.ceil(4 * P.smooth_sigma) + 2, math.ceil(3 * st.r0) + 2))
    chunks = list(_chunks(reader.shape, P.chunk, halo))
    lines = []
    block_stats = []
    for ci, (clo, chi, blo, bhi) in enumerate(chunks):
        raw = reader.read(blo, bhi)
        got = _detect_block(raw, blo, st, P, reader.shape)
        whole_mask = got.mask
        lines.extend(got.lines)
        block_stats.append(got.stats)
        note("detect", ci + 1, len(chunks))
    timings["detect"] = time.perf_counter() - tic
    trace = TraceStats.total(block_stats)
    candidates = len(lines)
    # (below a contrast-to-noise of 1.5 the skeleton of the noise itself bends: stay straight)
    if P.shape == "auto" and trace.bend_fraction > AUTO_BEND_FRACTION and trace.bent_branches >= 3 \
            and cnr >= 1.5:
        return _finish_curved(reader, st, P, prep, cnr, timings, t_all, progress, trace, candidates)
    if not lines:
        raise _fail(f"no rods found: {trace.seeds} skeleton seeds gave no rod-like "
                    f"fit (coarse radius {st.r0:.2f} voxels); {_HINT}")

    # merge
    tic = time.perf_counter()
    lines, nm, _ = _merge_lines(lines, st.r0, P.merge_angle, P.merge_distance * st.r0, P.merge_gap * st.r0,
                                filled=_gap_filler(reader, st, st.r0))
    note("merge", 1, 1)
    timings["merge"] = time.perf_counter() - tic

    # refine
    tic = time.perf_counter()
    ref_stats = None
    if P.refine_iterations > 0:
        rods, ref, ref_stats = _refine(reader, st, P, lines, progress)
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
    # rods rejected by reason: those refinement dropped first, then the final checks'
    reasons: dict[str, int] = dict(ref_stats.rejected) if ref_stats is not None else {}
    for rod in rods:
        _check_rod(rod, r_glob, C, P, sigma_fit, mixed)
        if not rod.ok:
            reasons[rod.why] = reasons.get(rod.why, 0) + 1
    good = [r for r in rods if r.ok]
    timings["refine"] = time.perf_counter() - tic
    if not good:
        why = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items()))
        raise _fail(f"no rods found: all {candidates} candidate(s) rejected ({why}); {_HINT}")

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
    fit_residual = float(np.nanmean(res)) if np.any(np.isfinite(res)) else float("nan")
    radius_spread = float(np.nanstd(mr)) if np.any(np.isfinite(mr)) else float("nan")

    tic = time.perf_counter()
    contacts, rej = confirm_contacts(out, reader, st, C, P, sigma_fit)
    out.contacts = contacts
    note("contacts", 1, 1)
    timings["contacts"] = time.perf_counter() - tic
    straight = _Straight(merged=nm, refine=ref_stats, per_rod_radius=bool(mixed), rejected=reasons,
                         fit_residual=fit_residual, contacts_rejected=rej)
    doubt = _assess(reader, st, out, P, timings, whole_mask if len(chunks) == 1 else None)
    return _assemble_result(out, contacts, r_glob, radius_spread, P, prep, st, cnr, timings, t_all,
                            trace=trace, candidates=candidates, straight=straight, doubt=doubt)


def _assess(reader, st, rods, P, timings, mask=None):
    """Per-rod confidence and unexplained foreground (``_doubt``), timed as ``doubt``; ``mask``:
    the binarised volume when detection kept it."""
    from rodwarp.ct._doubt import assess

    tic = time.perf_counter()
    d = assess(reader, st, rods, P, mask=mask)
    timings["doubt"] = time.perf_counter() - tic
    return d


#: ``shape="auto"`` traces filaments when more than this share of the long skeleton branches
#: (and at least 3 of them) bends smoothly away from its chord (straight packings: below 0.1,
#: arcs and wires: above 0.5)
AUTO_BEND_FRACTION = 0.3


def _finish_curved(reader, st, P, prep, cnr, timings, t_all, progress, trace=None, candidates=0):
    """The curved-filament path of :func:`segment_volume` (polylines, per-filament radii).

    ``trace`` and ``candidates``: the straight tracer's counts when ``shape="auto"`` ran it first.
    """
    from rodwarp.ct._curved import _resample, trace_filaments

    tic = time.perf_counter()
    raw = reader.read((0, 0, 0), reader.shape)
    fil = trace_filaments(raw, st, P, progress)
    polys, radii = fil.polylines, fil.radii
    timings["detect"] = timings.get("detect", 0.0) + time.perf_counter() - tic
    if not polys:
        raise _fail(f"no filaments found: {fil.branches} skeleton branches gave no filament longer "
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
    radius_spread = float(np.std(radii))  # of the sorted radii, as always (the sum's order counts)
    timings["contacts"] = time.perf_counter() - tic
    doubt = _assess(reader, st, out, P, timings, fil.mask)
    return _assemble_result(out, contacts, r_glob, radius_spread, P, prep, st, cnr, timings, t_all,
                            trace=trace, candidates=candidates, filaments=fil, doubt=doubt)


class _Straight(NamedTuple):
    """Figures of the straight-rod path that the driver measures itself, between and after stages."""

    merged: int                 # candidate lines pasted into others (stage 3)
    refine: RefineStats | None  # None with refine_iterations=0
    per_rod_radius: bool        # rods keep their own radii (mixed radii)
    rejected: dict              # reason -> rods, refinement's reasons first, then the final checks'
    fit_residual: float         # mean RMS of slab centroids about the axes (voxels)
    contacts_rejected: int      # contact candidates the image did not confirm


def _assemble_result(out: RodSet, contacts, r_glob: float, radius_spread: float, P: SegmentParams,
                     prep: Prepared, st: _Levels, cnr: float, timings: dict, t_all: float, *,
                     trace: TraceStats | None = None, candidates: int = 0, straight: _Straight | None = None,
                     filaments: FilamentResult | None = None, doubt: Doubt | None = None) -> SegmentResult:
    """The :class:`SegmentResult` of either path, its ``quality`` composed from the stages' results.

    The one place that writes ``quality``: keys in the order ``summary.json`` has always listed
    them (preparation, levels, the straight tracer's counts when it ran, the shape, then the
    straight path's or the curved path's figures).  With ``shape="auto"`` turned curved, the
    curved skeleton's ``skeleton_voxels``, ``skeleton_junctions`` and ``bend_fraction``
    replace the straight tracer's in their places.
    """
    timings["total"] = time.perf_counter() - t_all
    shape = "curved" if filaments is not None else "straight"
    attrs = {"source": "rodwarp.segment"}
    if shape == "curved":
        attrs["shape"] = "curved"
    attrs["diameter_voxels"] = 2 * r_glob
    attrs["params"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(P).items()}
    out.attrs = attrs
    q = prep.info()
    q.update(background=st.bg, foreground=st.fg, threshold=st.threshold, cnr=cnr, coarse_radius=st.r0)
    # of the final traces (before issue 33: of the detected lines), in its old place after the seeds
    explained = 1.0 - doubt.unexplained_fraction if doubt is not None else None
    if trace is not None:
        q.update(skeleton_voxels=trace.skeleton_voxels, skeleton_junctions=trace.skeleton_junctions,
                 seeds=trace.seeds)
        for name in trace.events:  # only the counters that counted, in the order they first did
            q[name] = getattr(trace, name)
        q.update(foreground_explained=explained, candidates=candidates,
                 bend_fraction=trace.bend_fraction, bent_branches=trace.bent_branches)
    q["shape"] = shape
    if filaments is not None:
        f = filaments
        q.update(skeleton_voxels=f.skeleton_voxels, skeleton_junctions=f.skeleton_junctions, branches=f.branches,
                 bend_fraction=f.bend_fraction, bridges=f.bridges, duplicates=f.duplicates,
                 rods_rejected={"faint": f.faint} if f.faint else {},
                 filaments=f.filaments, radius_spread=radius_spread)
    else:
        s = straight
        q["merged"] = s.merged
        if s.refine is not None:
            r = s.refine
            q.update(radius_profile_fit=r.radius_profile_fit, radius_cv=r.radius_cv, refine_rounds=r.rounds,
                     rod_refinements=r.rod_refinements, contrast_fit=r.contrast_fit, blur_sigma=r.blur_sigma,
                     end_offset=r.end_offset)
        q.update(per_rod_radius=s.per_rod_radius, rods_rejected=s.rejected, fit_residual=s.fit_residual,
                 radius_spread=radius_spread, contacts_rejected_by_image=s.contacts_rejected)
    if doubt is not None:
        q.setdefault("foreground_explained", explained)  # the curved path has no detection block
        q["unexplained"] = doubt.summary()
    q["flags"] = _flags(q, shape)
    return SegmentResult(rods=out, contacts=contacts, diameter=2.0 * r_glob, timings=timings, quality=q,
                         spacing=prep.spacing, doubt=doubt)


def _flags(quality: dict, shape: str) -> list[str]:
    """Quality flags: short sentences naming what makes the output untrustworthy (empty: none).

    Reads the composed ``quality``; :func:`_assemble_result` stores the list as ``quality["flags"]``.
    """
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
    un = quality.get("unexplained") or {}
    nd, nr = un.get("doubtful", 0), un.get("traces", 0)
    if nd and nr and nd > 0.1 * nr:
        flags.append(f"{nd} of {nr} traces are doubtful (confidence below {un['doubt_confidence']:g}): "
                     f"see filaments.csv and qa_confidence.png")
    b = quality.get("binarised")
    if b and b["rod_fraction"] > LIKELY_INVERTED_FRACTION:
        flags.append(f"the rods' level {b['rod_level']} fills {100 * b['rod_fraction']:.0f}% of this binarised "
                     f"stack: if the rods are the other level, pass --dark-rods or --bright-rods")
    cnr = quality.get("cnr")
    if cnr is not None and np.isfinite(cnr) and cnr < 1.5:
        flags.append(f"contrast-to-noise {cnr:.1f} is below 1.5: expect missed rods and false contacts")
    return flags
