"""Segmentation as a list of stages: :class:`Stage`, the :class:`SegmentContext` they share,
and :data:`DEFAULT_STAGES`, the list :func:`~rodwarp.ct.segment_volume` runs.

A stage is any object with a ``name``, a ``run(ctx)`` that reads and writes the
:class:`SegmentContext` and a ``quality(ctx)`` that returns what it reports into
``SegmentResult.quality`` (possibly nothing); ``paths`` (optional) names the paths it runs on.
:func:`segment_volume` runs the stages in order, times each under its name in
``SegmentResult.timings``, and composes ``quality`` from their ``quality(ctx)`` in the same order
once all have run.  Adding a stage takes one file::

    from rodwarp.ct import DEFAULT_STAGES, Stage, insert_stage, segment_volume

    class RodLengths(Stage):
        name = "rod_lengths"
        paths = ("straight",)

        def run(self, ctx):
            ctx.extra["mean_length"] = sum(r.length for r in ctx.rod_list) / len(ctx.rod_list)

        def quality(self, ctx):
            return {"mean_length_voxels": ctx.extra["mean_length"]}

    result = segment_volume(volume, stages=insert_stage(DEFAULT_STAGES, RodLengths(), after="refine"))

To make a stage a default one, define it here and list it in :data:`DEFAULT_STAGES`.

The default stages, in order (``paths``: straight rods, curved filaments or both):

============  ========  ==========================================================================
``prepare``   both      field-of-view mask, background trend, dark rods, anisotropic voxels
                        (``_prepare``; a binarised stack recognised, ``_binary``)
``stats``     both      levels: background, plateau, threshold, coarse radius (``_levels``;
                        of a mask ``_binary.mask_levels``)
``detect``    both      per chunk: skeleton seeds, cylinder fits and marching, pairs and bundles
                        split (``_seeds``, ``_tracing``, ``_bundles``); with ``shape="auto"`` it
                        turns the path curved when the skeleton bends
``filaments`` curved    filaments traced as polylines, their radii and contacts (``_curved``)
``merge``     straight  pieces of one rod pasted, duplicates made one (``_pasting``)
``refine``    straight  axes, radii and ends against the greyscale, final checks, the rod set
                        (``_refine``, ``_profile``)
``contacts``  straight  contact candidates confirmed by the image (``_contacts``)
``doubt``     both      per-rod confidence and the foreground no trace explains (``_doubt``)
============  ========  ==========================================================================

Points are ``(x, y, z)`` in working voxels with the centre of voxel ``(0, 0, 0)`` at the origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.ct._voxels import _canonical, _unit
from rodwarp.ct.segment._params import _HINT, SegmentParams
from rodwarp.rodset import Contacts, RodSet

if TYPE_CHECKING:  # annotations only
    from rodwarp.ct.segment._curved import FilamentResult
    from rodwarp.ct.segment._doubt import Doubt
    from rodwarp.ct.segment._levels import _Levels
    from rodwarp.ct.segment._prepare import Prepared
    from rodwarp.ct.segment._reader import _Reader
    from rodwarp.ct.segment._refine import RefineStats
    from rodwarp.ct.segment._tracing import TraceStats

__all__ = ["Stage", "SegmentContext", "DEFAULT_STAGES", "insert_stage", "AUTO_BEND_FRACTION", "MIN_EDGE_VOXELS"]

#: ``shape="auto"`` traces filaments when more than this share of the long skeleton branches
#: (and at least 3 of them) bends smoothly away from its chord (straight packings: below 0.1,
#: arcs and wires: above 0.5)
AUTO_BEND_FRACTION = 0.3

#: ... unless the straight traces' median length is at least this many coarse radii and the
#: bend fraction below AUTO_BUNDLE_BEND: the skeleton of closest-packed bundles of straight rods
#: bends too (bend fraction up to 0.54 on 30 of rodwarp's bundle scenes of radius 1.5-3, their
#: straight traces 33-36 radii long), wires' straight pieces run 6-14 radii, and arcs' 22-26
#: radii with bend fractions of 0.77-0.95 (issue 50)
AUTO_STRAIGHT_RADII = 20.0
AUTO_BUNDLE_BEND = 0.65

#: smallest volume edge (voxels) segmentation accepts: the thinnest rod it resolves is about
#: 2 voxels across (radius 1), its blurred edges take ~2 voxels on each side and the background
#: around it another voxel or two; a smaller volume cannot hold a rod and would only be told
#: "no rods found" after the whole search
MIN_EDGE_VOXELS = 8


@dataclass
class SegmentContext:
    """What the stages of one :func:`segment_volume` call share; each stage fills its part.

    Attributes
    ----------
    volume : array-like (z, y, x)
        The volume as given.
    params : SegmentParams
        Knobs (validated).
    voxel_size : float or sequence of 3 floats or None
        As given to :func:`segment_volume` (any unit).
    progress : callable(stage, done, total) or None
        Progress callback.
    path : str
        ``"straight"`` or ``"curved"``: which stages run (a stage's ``paths``); ``detect`` may
        turn a ``shape="auto"`` run curved.
    timings : dict
        Seconds per stage name (the driver adds them; ``total`` at the end).
    prep : Prepared
        Stage ``prepare``: the corrected volume, its spacing (units of ``voxel_size``) and notes.
    reader : _Reader
        Block access to the prepared volume (working voxels).
    levels : _Levels
        Stage ``stats``: background, plateau, threshold, coarse radius ``r0`` (voxels).
    cnr : float
        Estimated contrast-to-noise ratio.
    lines : list of (p0, p1)
        Rod axes in working voxels: detected (``detect``), then pasted (``merge``).
    trace : TraceStats or None
        The straight tracer's counts (None when it did not run).
    candidates : int
        Axes detected before merging.
    mask : ndarray of bool or None
        The binarised volume when one block covered it (reused by ``doubt``).
    merged : int
        Axes pasted into others (``merge``).
    rod_list : list of _Rod
        Stage ``refine``: the accepted rods (refined axes, radii, residuals).
    refine_stats : RefineStats or None
        Refinement's figures (None with ``refine_iterations=0``).
    rejected : dict
        Reason -> rods rejected (refinement's reasons first, then the final checks').
    per_rod_radius : bool
        Rods keep their own radii (mixed radii).
    contrast, sigma_fit : float, float or None
        Rod contrast ``C`` (plateau share) and fitted blur (voxels) of the refinement.
    radius : float
        The rods' (median) radius, voxels.
    radius_spread, fit_residual : float
        Std of per-rod radii, and mean RMS of slab centroids about the axes (voxels).
    rods : RodSet or None
        The rod set in working voxels (``refine`` or ``filaments``), its ``contacts`` set by
        ``contacts`` / ``filaments``.
    contacts : Contacts or None
        The contacts (voxels).
    contacts_rejected : int
        Contact candidates the image did not confirm.
    filaments : FilamentResult or None
        Stage ``filaments``' result.
    doubt : Doubt or None
        Stage ``doubt``: per-rod confidence and unexplained foreground.
    extra : dict
        Free room for added stages to pass values on to later ones.
    """

    volume: Any
    params: SegmentParams
    voxel_size: Any = None
    progress: Callable[[str, int, int], None] | None = None
    path: str = "straight"
    timings: dict = field(default_factory=dict)
    prep: Prepared | None = None
    reader: _Reader | None = None
    levels: _Levels | None = None
    cnr: float = math.nan
    lines: list = field(default_factory=list)
    trace: TraceStats | None = None
    candidates: int = 0
    mask: np.ndarray | None = None
    merged: int = 0
    rod_list: list = field(default_factory=list)
    refine_stats: RefineStats | None = None
    rejected: dict = field(default_factory=dict)
    per_rod_radius: bool = False
    contrast: float = 1.0
    sigma_fit: float | None = None
    radius: float = math.nan
    radius_spread: float = math.nan
    fit_residual: float = math.nan
    rods: RodSet | None = None
    contacts: Contacts | None = None
    contacts_rejected: int = 0
    filaments: FilamentResult | None = None
    doubt: Doubt | None = None
    extra: dict = field(default_factory=dict)

    def note(self, stage: str, done: int, total: int) -> None:
        """Report progress (``stage``, ``done`` of ``total``) when a callback was given."""
        if self.progress is not None:
            self.progress(stage, done, total)


class Stage:
    """One step of segmentation; subclass it (or give any object these attributes).

    Attributes
    ----------
    name : str
        Unique in a stage list; the key of its time in ``SegmentResult.timings``.
    paths : tuple of str
        The paths it runs on (``"straight"``, ``"curved"``); on the others neither ``run`` nor
        ``quality`` is called.
    """

    name: str = ""
    paths: tuple[str, ...] = ("straight", "curved")

    def run(self, ctx: SegmentContext) -> None:
        """Read and fill ``ctx``; raise :class:`~rodwarp.errors.RodwarpError` (one line) to stop."""
        raise NotImplementedError

    def quality(self, ctx: SegmentContext) -> dict:
        """Keys this stage reports into ``SegmentResult.quality`` (called after every stage ran)."""
        return {}

    def __repr__(self) -> str:
        return f"<stage {self.name}>"


def insert_stage(stages: Sequence, stage, *, after: str | None = None, before: str | None = None) -> list:
    """A new stage list: ``stages`` with ``stage`` inserted after (or before) the stage so named.

    Parameters
    ----------
    stages : sequence of Stage
        E.g. :data:`DEFAULT_STAGES` (not changed).
    stage : Stage
        The stage to add.
    after, before : str
        Name of the stage to insert after or before (one of them); neither appends it.

    Raises
    ------
    RodwarpError
        No stage of that name, or ``stage.name`` already taken.
    """
    out = list(stages)
    names = [s.name for s in out]
    if stage.name in names:
        raise _fail(f"a stage named {stage.name!r} is already in the list ({', '.join(names)})")
    if after is not None and before is not None:
        raise _fail("insert_stage takes after or before, not both")
    anchor = after if after is not None else before
    if anchor is None:
        return out + [stage]
    if anchor not in names:
        raise _fail(f"no stage named {anchor!r}; the stages are {', '.join(names)}")
    k = names.index(anchor) + (1 if after is not None else 0)
    return out[:k] + [stage] + out[k:]


# ----------------------------------------------------------------------------------------------
# the default stages
# ----------------------------------------------------------------------------------------------

class PrepareStage(Stage):
    """Field-of-view mask, background trend, dark rods, anisotropic voxels; a binarised stack."""

    name = "prepare"

    def run(self, ctx):
        from rodwarp.ct.segment._prepare import _Corrected, prepare_volume
        from rodwarp.ct.segment._reader import _Reader

        P = ctx.params
        shape = _Reader(ctx.volume).shape  # shape and dtype checks first, with their own messages
        if min(shape) < MIN_EDGE_VOXELS:
            raise _fail(f"volume shape {shape} is too small to hold a rod: every dimension needs at least "
                        f"{MIN_EDGE_VOXELS} voxels (a rod about 2 voxels across, its blurred edges and some "
                        f"background); give the whole CT stack")
        prep = prepare_volume(ctx.volume, ctx.voxel_size, dark=P.dark, fov=P.fov, background=P.background)
        vol = prep.volume
        if isinstance(vol, _Corrected) and isinstance(ctx.volume, np.ndarray):
            vol = vol[:, :, :]  # in memory anyway: gathers from an array are much faster
        ctx.prep, ctx.reader = prep, _Reader(vol)

    def quality(self, ctx):
        return ctx.prep.info()


class LevelsStage(Stage):
    """Levels and binarisation: background, plateau, threshold, coarse radius, mixed radii."""

    name = "stats"

    def run(self, ctx):
        from rodwarp.ct.segment._binary import mask_levels
        from rodwarp.ct.segment._levels import _measure_levels

        ctx.note("stats", 0, 1)
        measure = mask_levels if ctx.prep.binarised is not None else _measure_levels
        st = ctx.levels = measure(ctx.reader, ctx.params)
        ctx.note("stats", 1, 1)
        noise = ctx.prep.notes.get("noise") or st.noise
        ctx.cnr = (st.fg - st.bg) / noise if noise > 0 else float("inf")

    def quality(self, ctx):
        st = ctx.levels
        return {"background": st.bg, "foreground": st.fg, "threshold": st.threshold, "cnr": ctx.cnr,
                "coarse_radius": st.r0}


def _chunks(shape, chunk, halo):
    """(chunk low, chunk high, block low, block high) corners (z, y, x) of each chunk and its halo."""
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


class DetectStage(Stage):
    """Straight rod axes, chunk by chunk: skeleton seeds, cylinder fits and marching.

    Skipped when ``shape="curved"``; with ``shape="auto"`` a skeleton whose long branches bend
    turns the path curved.  Reports the tracer's counts and the path taken (``shape``).
    """

    name = "detect"

    def run(self, ctx):
        from rodwarp.ct.segment._tracing import TraceStats, _detect_block

        if ctx.path != "straight":
            return
        P, st, reader = ctx.params, ctx.levels, ctx.reader
        halo = P.chunk_halo if P.chunk_halo is not None else \
            int(max(math.ceil(4 * P.smooth_sigma) + 2, math.ceil(3 * st.r0) + 2))
        chunks = list(_chunks(reader.shape, P.chunk, halo))
        lines, block_stats, mask = [], [], None
        for ci, (clo, chi, blo, bhi) in enumerate(chunks):
            got = _detect_block(reader.read(blo, bhi), blo, st, P, reader.shape)
            mask = got.mask
            lines.extend(got.lines)
            block_stats.append(got.stats)
            ctx.note("detect", ci + 1, len(chunks))
        trace = ctx.trace = TraceStats.total(block_stats)
        ctx.lines, ctx.candidates = lines, len(lines)
        ctx.mask = mask if len(chunks) == 1 else None
        # (below a contrast-to-noise of 1.5 the skeleton of the noise itself bends: stay straight;
        # so it does where the straight traces run long: bundles of touching rods bend the skeleton)
        run_long = bool(lines) and trace.bend_fraction < AUTO_BUNDLE_BEND and \
            float(np.median([np.linalg.norm(b - a) for a, b in lines])) >= AUTO_STRAIGHT_RADII * st.r0
        if P.shape == "auto" and trace.bend_fraction > AUTO_BEND_FRACTION and trace.bent_branches >= 3 \
                and ctx.cnr >= 1.5 and not run_long:
            ctx.path = "curved"
            return
        if not lines:
            raise _fail(f"no rods found: {trace.seeds} skeleton seeds gave no rod-like "
                        f"fit (coarse radius {st.r0:.2f} voxels); {_HINT}")

    def quality(self, ctx):
        q = {}
        trace = ctx.trace
        if trace is not None:
            q.update(skeleton_voxels=trace.skeleton_voxels, skeleton_junctions=trace.skeleton_junctions,
                     seeds=trace.seeds)
            for name in trace.events:  # only the counters that counted, in the order they first did
                q[name] = getattr(trace, name)
            # of the final traces (stage doubt)
            explained = 1.0 - ctx.doubt.unexplained_fraction if ctx.doubt is not None else None
            q.update(foreground_explained=explained, candidates=ctx.candidates,
                     bend_fraction=trace.bend_fraction, bent_branches=trace.bent_branches)
        q["shape"] = ctx.path
        return q


class FilamentStage(Stage):
    """Curved filaments traced as polylines (per-filament radii), their rod set and contacts."""

    name = "filaments"
    paths = ("curved",)

    def run(self, ctx):
        from rodwarp.ct._voxels import _resample
        from rodwarp.ct.segment._curved import trace_filaments
        from rodwarp.rodset import detect_contacts

        P, st, reader = ctx.params, ctx.levels, ctx.reader
        fil = ctx.filaments = trace_filaments(reader.read((0, 0, 0), reader.shape), st, P, ctx.progress)
        polys, radii = fil.polylines, fil.radii
        if not polys:
            raise _fail(f"no filaments found: {fil.branches} skeleton branches gave no filament longer "
                        f"than {P.min_length:g} radii (coarse radius {st.r0:.2f} voxels); {_HINT}")
        # vertices every 2 voxels (or the radius): enough for the curvature a skeleton resolves
        step = max(2.0, 0.75 * st.r0)
        polys = [_resample(p, step) for p in polys]
        key = [tuple(np.round(p.mean(0), 3)[::-1]) for p in polys]
        order = sorted(range(len(polys)), key=lambda k: key[k])
        polys = [polys[k] for k in order]
        radii = np.asarray(radii)[order]
        out = RodSet.from_polylines(polys, radii, units="voxel")
        out.contacts = ctx.contacts = detect_contacts(out, tolerance=P.contact_tolerance)
        ctx.rods, ctx.mask = out, fil.mask
        ctx.radius = float(np.median(radii))
        ctx.radius_spread = float(np.std(radii))  # of the sorted radii (the sum's order counts)

    def quality(self, ctx):
        f = ctx.filaments
        return {"skeleton_voxels": f.skeleton_voxels, "skeleton_junctions": f.skeleton_junctions,
                "branches": f.branches, "bend_fraction": f.bend_fraction, "bridges": f.bridges,
                "duplicates": f.duplicates, "rods_rejected": {"faint": f.faint} if f.faint else {},
                "filaments": f.filaments, "radius_spread": ctx.radius_spread}


class MergeStage(Stage):
    """Pieces of one rod pasted, duplicates made one."""

    name = "merge"
    paths = ("straight",)

    def run(self, ctx):
        from rodwarp.ct.segment._pasting import _gap_filler, _merge_lines

        P, st = ctx.params, ctx.levels
        ctx.lines, ctx.merged, _ = _merge_lines(ctx.lines, st.r0, P.merge_angle, P.merge_distance * st.r0,
                                                P.merge_gap * st.r0, filled=_gap_filler(ctx.reader, st, st.r0))
        ctx.note("merge", 1, 1)

    def quality(self, ctx):
        return {"merged": ctx.merged}


class RefineStage(Stage):
    """Axes, radii and ends against the greyscale; the final checks; the rod set in a fixed order."""

    name = "refine"
    paths = ("straight",)

    def run(self, ctx):
        from rodwarp.ct.segment._refine import _check_rod, _refine, _Rod

        P, st = ctx.params, ctx.levels
        if P.refine_iterations > 0:
            rods, ref, ctx.refine_stats = _refine(ctx.reader, st, P, ctx.lines, ctx.progress)
            r_glob, C, sigma_fit, mixed = ref.r, ref.C, ref.sigma, ref.mixed
        else:
            rods = [_Rod(a, b, st.r0) for a, b in ctx.lines]
            r_glob, C, sigma_fit, mixed = st.r0, 1.0, None, False
            for rod in rods:  # coarse ends run out to the half level of a cap: pull them back
                if P.end_model == "capsule":  # (0.55 r measured on phantoms, blur 1, smoothing 1)
                    u = _unit(rod.p1 - rod.p0)
                    if rod.length > 2 * r_glob:
                        rod.p0, rod.p1 = rod.p0 + 0.55 * r_glob * u, rod.p1 - 0.55 * r_glob * u
        # rods rejected by reason: those refinement dropped first, then the final checks'
        reasons: dict[str, int] = dict(ctx.refine_stats.rejected) if ctx.refine_stats is not None else {}
        for rod in rods:
            _check_rod(rod, r_glob, C, P, sigma_fit, mixed)
            if not rod.ok:
                reasons[rod.why] = reasons.get(rod.why, 0) + 1
        good = [r for r in rods if r.ok]
        ctx.rejected, ctx.radius, ctx.contrast, ctx.sigma_fit = reasons, r_glob, C, sigma_fit
        ctx.per_rod_radius = bool(mixed)
        if not good:
            why = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items()))
            raise _fail(f"no rods found: all {ctx.candidates} candidate(s) rejected ({why}); {_HINT}")
        ctx.rod_list = good
        self._rod_set(ctx, good, r_glob, C, mixed)

    @staticmethod
    def _rod_set(ctx, good, r_glob, C, mixed):
        """The rod set of the accepted rods: deterministic order and orientation."""
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
        ctx.rods = RodSet.from_polylines(polys, np.asarray(radii), units="voxel")
        ctx.fit_residual = float(np.nanmean(res)) if np.any(np.isfinite(res)) else float("nan")
        ctx.radius_spread = float(np.nanstd(mr)) if np.any(np.isfinite(mr)) else float("nan")

    def quality(self, ctx):
        q = {}
        r = ctx.refine_stats
        if r is not None:
            q.update(radius_profile_fit=r.radius_profile_fit, radius_cv=r.radius_cv, refine_rounds=r.rounds,
                     rod_refinements=r.rod_refinements, contrast_fit=r.contrast_fit, blur_sigma=r.blur_sigma,
                     end_offset=r.end_offset, touching_split=r.touching_split)
        q.update(per_rod_radius=ctx.per_rod_radius, rods_rejected=ctx.rejected, fit_residual=ctx.fit_residual,
                 radius_spread=ctx.radius_spread)
        return q


class ContactStage(Stage):
    """Contact candidates between the rods, confirmed by the image."""

    name = "contacts"
    paths = ("straight",)

    def run(self, ctx):
        from rodwarp.ct.segment._contacts import confirm_contacts

        contacts, ctx.contacts_rejected = confirm_contacts(ctx.rods, ctx.reader, ctx.levels, ctx.contrast,
                                                           ctx.params, ctx.sigma_fit)
        ctx.rods.contacts = ctx.contacts = contacts
        ctx.note("contacts", 1, 1)

    def quality(self, ctx):
        return {"contacts_rejected_by_image": ctx.contacts_rejected}


class DoubtStage(Stage):
    """Per-rod confidence and the foreground no trace explains."""

    name = "doubt"

    def run(self, ctx):
        from rodwarp.ct.segment._doubt import assess

        ctx.doubt = assess(ctx.reader, ctx.levels, ctx.rods, ctx.params, mask=ctx.mask)

    def quality(self, ctx):
        q = {}
        if ctx.doubt is not None:
            if ctx.trace is None:  # no detection block reported it
                q["foreground_explained"] = 1.0 - ctx.doubt.unexplained_fraction
            q["unexplained"] = ctx.doubt.summary()
        return q


#: the stages :func:`segment_volume` runs, in order (a tuple: build a new list to change it,
#: e.g. with :func:`insert_stage`)
DEFAULT_STAGES: tuple[Stage, ...] = (PrepareStage(), LevelsStage(), DetectStage(), FilamentStage(), MergeStage(),
                                     RefineStage(), ContactStage(), DoubtStage())
