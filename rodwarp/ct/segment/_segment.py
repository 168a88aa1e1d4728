"""CT segmentation on the CPU, the driver: rod centrelines, radii and contacts from a greyscale volume.

The volume is indexed ``(z, y, x)`` = (slice, row, column); every point returned is ``(x, y, z)``
in (working) voxel units with the centre of voxel ``(0, 0, 0)`` at the origin.

:func:`segment_volume` runs a list of stages (:data:`~rodwarp.ct.segment._stages.DEFAULT_STAGES`,
each a :class:`~rodwarp.ct.segment._stages.Stage`) on one
:class:`~rodwarp.ct.segment._stages.SegmentContext`, times each under its name in
``SegmentResult.timings``, and composes ``SegmentResult.quality`` from the stages' reports
(:func:`_assemble_result`, the one place that writes it) and the flags (:func:`_flags`): a
short sentence for each reason the output should not be trusted.
"""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Callable, Sequence

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.ct.segment._binary import LIKELY_INVERTED_FRACTION
from rodwarp.ct.segment._params import SegmentParams, SegmentResult
from rodwarp.ct.segment._stages import AUTO_BEND_FRACTION, DEFAULT_STAGES, MIN_EDGE_VOXELS, SegmentContext, Stage

__all__ = ["segment_volume", "AUTO_BEND_FRACTION", "MIN_EDGE_VOXELS"]


def segment_volume(volume, params: SegmentParams | None = None,
                   progress: Callable[[str, int, int], None] | None = None, *,
                   voxel_size=None, stages: Sequence[Stage] | None = None) -> SegmentResult:
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
        (:mod:`rodwarp.ct.segment._prepare`); the result's coordinates are in units of that edge
        (``SegmentResult.spacing``), with voxel (0, 0, 0) at the origin.
    stages : sequence of Stage, optional
        The stages to run, in order; default :data:`DEFAULT_STAGES` (add one with
        :func:`~rodwarp.ct.insert_stage`).  Each stage's ``quality(ctx)`` joins
        ``SegmentResult.quality``; its run time is ``SegmentResult.timings[stage.name]``.

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
    ctx = SegmentContext(volume=volume, params=P, voxel_size=voxel_size, progress=progress,
                         path="curved" if P.shape == "curved" else "straight")
    ran = _run_stages(ctx, DEFAULT_STAGES if stages is None else stages)
    return _assemble_result(ctx, ran, t_all)


def _run_stages(ctx: SegmentContext, stages) -> list:
    """Run each stage whose ``paths`` hold ``ctx.path`` (read as it reaches the stage), timing it;
    the stages that ran, in order."""
    ran = []
    for stage in stages:
        if ctx.path not in getattr(stage, "paths", ("straight", "curved")):
            continue
        tic = time.perf_counter()
        stage.run(ctx)
        ctx.timings[stage.name] = ctx.timings.get(stage.name, 0.0) + time.perf_counter() - tic
        ran.append(stage)
    return ran


def _assemble_result(ctx: SegmentContext, ran, t_all: float) -> SegmentResult:
    """The :class:`SegmentResult`, its ``quality`` composed from the stages that ran, in order.

    The one place that writes ``quality``: each stage's ``quality(ctx)`` in the order the stages
    ran (a key reported again keeps its first place), then ``flags``.
    """
    ctx.timings["total"] = time.perf_counter() - t_all
    P, out = ctx.params, ctx.rods
    shape = ctx.path
    attrs = {"source": "rodwarp.segment"}
    if shape == "curved":
        attrs["shape"] = "curved"
    attrs["diameter_voxels"] = 2 * ctx.radius
    attrs["params"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(P).items()}
    out.attrs = attrs
    q: dict = {}
    for stage in ran:
        q.update(stage.quality(ctx))
    q["flags"] = _flags(q, shape)
    return SegmentResult(rods=out, contacts=ctx.contacts, diameter=2.0 * ctx.radius, timings=ctx.timings,
                         quality=q, spacing=ctx.prep.spacing, doubt=ctx.doubt)


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
