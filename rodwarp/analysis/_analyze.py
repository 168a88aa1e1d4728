"""``rodwarp analyze``: inputs -> rod set (or precomputed fields) -> fields -> statistics -> files.

Inputs
    * a ``rodwarp simulate`` output directory (its ``final.npz``, with contacts and the box),
    * a ``rodwarp segment`` output directory (its ``rods.npz``/``rods.zarr``),
    * a rod-set file (``.npz``, ``.zarr``) or a CSV of centrelines ``rod,x,y,z[,radius]``
      (``--diameter`` when there is no radius column),
    * precomputed fields (``fields.zarr``, or an ``.npz`` holding ``e`` and ``n`` such as the
      paper authors' files), for the statistics alone.

Outputs in ``out`` (written atomically): ``fields.zarr``, ``summary.json``, ``rods.npz`` (the
analysed rod set with its contacts), PNG figures (histograms, mid-plane slices, z-profiles,
outliers and tangles).  The fields, their summary keys and their panels are the field
registry's (:data:`rodwarp.analysis.FIELDS`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rodwarp._util import option, progress_bar, slow_phase, versions
from rodwarp.analysis._fieldset import Fields
from rodwarp.rodset.commands import ANALYZE_OUTPUTS
from rodwarp.errors import RodwarpError
from rodwarp.rodset import RodSet
from rodwarp.rodset import load as load_rods
from rodwarp.rodset.files import write_json
from rodwarp.validation import Range

ROD_FILES = ("final.npz", "rods.npz", "rods.zarr", "final.zarr")


@dataclass(frozen=True)
class AnalyzeOptions:
    """Options of :func:`analyze` (lengths in the input's units), frozen; each field's default
    and help are those of ``rodwarp analyze``."""

    radius: float | None = option(None, "Ball radius R (input units; default sqrt(d l)).",
                                  range=Range(gt=0, le=1e12, hint="lengths are in the input's units"))
    spacing: float | None = option(None, "Grid spacing (input units; default R / 2).",
                                   range=Range(gt=0, le=1e12, hint="lengths are in the input's units"))
    diameter: float | None = option(None, "Rod diameter d for the default R (required for a CSV without radius).",
                                    range=Range(gt=0, le=1e12, hint="lengths are in the input's units"))
    length: float | None = option(None, "Rod length l for the default R (default the mean rod length).",
                                  range=Range(gt=0, le=1e12, hint="lengths are in the input's units"))
    units: str | None = option(None, "Length unit of a CSV (m, mm, um, voxel; default m: a CSV does not "
                                          "record its unit); converts npz/zarr rod sets, which record their own.")
    keep_outside: bool = option(False, "Keep voxels whose ball leaves the domain (masked as NaN by default).")
    contact_tolerance: float | None = option(None, "Surface gap counted as contact when contacts are detected "
                                                   "(default d / 10).",
                                                   range=Range(ge=0, le=1e12, hint="a surface gap in the input's units"))
    outlier: str = option("q3", "Outlier bound: q3 = Q3 + 1.5 IQR (the paper's) or q1 = Q1 + 1.5 IQR.")
    connectivity: int = option(26, "Tangle connectivity: 26 (default) or 6.",
                                   range=Range(choices=(6, 26), whole=True, hint="voxels sharing a face (6) or a "
                                                                                 "corner (26)"))
    bins: int = option(40, "Histogram bins.", range=Range(ge=2, le=100_000, whole=True))
    device: str = option("auto", "auto, cpu or cuda (auto: a CUDA GPU when one is present, else the CPU).")
    figures: bool = option(True, "Write the PNG figures.")
    convention: str = option("text", "Field rules: text (the paper's definitions: exact clipping, each rod pair "
                                     "once) or authors (the authors' MATLAB routine behind the published fields: "
                                     "unclipped edges, rod pairs twice; phi not computed); docs/fields.md.")

    def validate(self) -> None:
        """Raise :class:`RodwarpError` (one line) for any option that is not finite, out of
        range or unknown (:func:`rodwarp.analysis._checks.check_analyze`)."""
        from rodwarp.analysis._checks import check_analyze

        check_analyze(self)


def _is_fields_npz(path: Path) -> bool:
    try:
        with np.load(path, allow_pickle=False) as z:
            return "e" in z.files and "points" not in z.files
    except Exception:  # noqa: BLE001 - unreadable archives are reported by the loaders
        return False


def _is_zarr_with(path: Path, key: str) -> bool:
    return (path / key / "zarr.json").exists() or (path / key / ".zarray").exists()


def load_input(path, opts: AnalyzeOptions) -> tuple[str, RodSet | Fields, Path]:
    """Classify and read an input of :func:`analyze`.

    Parameters
    ----------
    path : path-like
        A simulate or segment output folder, a rod-set file (npz, zarr, CSV) or precomputed
        fields (``fields.zarr``, an npz holding ``e`` and ``n``).
    opts : AnalyzeOptions
        ``diameter`` and ``units`` for a CSV; ``units`` converts npz/zarr rod sets.

    Returns
    -------
    (kind, object, file)
        ``("rods", RodSet, file)`` or ``("fields", Fields, file)``; ``file`` is what was read.
    """
    path = Path(path)
    if not path.exists():
        raise RodwarpError(f"input '{path}' does not exist; pass a simulate/segment output directory, "
                           "a rod-set file (.npz, .zarr, .csv) or a fields file")
    if path.is_dir() and not (path.suffix == ".zarr" or (path / "zarr.json").exists()
                              or (path / ".zgroup").exists()):
        for name in ROD_FILES:
            if (path / name).exists():
                return "rods", _load_rods(path / name, opts), path / name
        if (path / "fields.zarr").exists():
            return "fields", Fields.load(path / "fields.zarr"), path / "fields.zarr"
        raise RodwarpError(f"directory '{path}' holds none of {', '.join(ROD_FILES)} or fields.zarr; "
                           "is it a rodwarp simulate or segment output?")
    if path.is_dir():  # a zarr group: fields or rods
        if _is_zarr_with(path, "e"):
            return "fields", Fields.load(path), path
        return "rods", _load_rods(path, opts), path
    if path.suffix.lower() == ".npz" and _is_fields_npz(path):
        return "fields", Fields.load(path), path
    return "rods", _load_rods(path, opts), path


def _load_rods(path: Path, opts: AnalyzeOptions) -> RodSet:
    if path.suffix.lower() == ".csv":
        rods = load_rods(path, diameter=opts.diameter, units=opts.units)
    else:
        rods = load_rods(path, units=opts.units)
    if rods.n_rods == 0:
        raise RodwarpError(f"'{path}' holds no rods: nothing to analyse")
    from rodwarp.rodset.sanity import check_rod_geometry

    # zero-length rods have no axis, duplicates would each count as a contact, and one stray
    # rod would stretch the grid over its distance: refused, naming the rod
    check_rod_geometry(rods, str(path))
    from rodwarp.rodset.scale import check_diameter_agrees

    # --diameter stands in for a missing radius column; one that contradicts the file's radii
    # would silently set R = sqrt(d l) from the wrong thickness
    check_diameter_agrees(rods, opts.diameter, path)
    return rods


def default_out(path: Path) -> Path:
    """Default output folder of :func:`analyze`: ``analysis/`` beside the input.

    Parameters
    ----------
    path : path-like
        The input; a directory of results (not a ``.zarr``) gets ``analysis/`` inside it.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    if path.is_dir() and path.suffix != ".zarr":
        return path / "analysis"
    return path.parent / "analysis"


def analyze(path, out=None, opts: AnalyzeOptions | None = None, *, progress: bool = False,
            overwrite: bool = False) -> dict:
    """Compute (or read) the fields of an input, their statistics, and write every output.

    Parameters
    ----------
    path : path-like
        Input (see the module docstring).
    out : path-like, optional
        Output directory; default :func:`default_out`.
    opts : AnalyzeOptions
        Grid, contact, statistics and device options.
    progress : bool
        Show a progress bar over the voxel batches.
    overwrite : bool
        Write into ``out`` even when it holds another kind of run (whose outputs are then
        removed). An earlier analysis in ``out`` is always replaced (:mod:`rodwarp.rodset.rundir`).

    Returns
    -------
    dict
        The summary written to ``summary.json`` (lengths in the input's units): the grid, every
        option, the versions, and :func:`rodwarp.analysis.field_statistics` (a mean per field
        of the registry, cv_e, e_lb, tangles, histograms, z-profiles).
    """
    from rodwarp.analysis._stats import field_statistics, find_tangles

    opts = opts or AnalyzeOptions()
    opts.validate()
    t0 = time.perf_counter()
    from rodwarp.analysis._checks import check_grid_memory
    from rodwarp.rodset import rundir
    from rodwarp.validation import output_location

    out = Path(out) if out is not None else default_out(Path(path))
    if Path(path).exists():
        output_location(out, "--out")  # a file, read-only or full: refused before reading the input
    kind, obj, src = load_input(path, opts)
    if kind == "rods":
        from rodwarp.analysis._fields import grid_axes, resolve_params

        fp = resolve_params(obj, radius=opts.radius, spacing=opts.spacing, diameter=opts.diameter,
                            length=opts.length, keep_outside=opts.keep_outside,
                            contact_tolerance=opts.contact_tolerance)
        check_grid_memory(float(np.prod([len(a) for a in grid_axes(fp)])), rods=obj,
                          extent=float(np.max(fp.domain[1] - fp.domain[0])))
    # the folder is taken only once the input is known to be good: a bad input leaves an
    # earlier analysis alone
    run = rundir.claim(out, "analyze", {"input": str(Path(src).resolve()), **asdict(opts)}, ANALYZE_OUTPUTS,
                       overwrite=overwrite, replace_same_kind=True, inputs=[src])
    cluster = None
    if kind == "rods":
        rods: RodSet = obj
        from rodwarp.analysis._fields import resolve_contacts
        from rodwarp.rodset import largest_cluster_fraction

        tol = fp.contact_tolerance
        contacts, source = resolve_contacts(rods, tol)
        fields = _fields_with_progress(rods, contacts, opts, progress)
        fields.attrs["contact_source"] = source
        cluster = largest_cluster_fraction(rods.n_rods, contacts)
        analysed = rods.copy()
        analysed.contacts = contacts
        analysed.save(out / "rods.npz")
        fields.attrs["source"] = str(src)
        fields.save(out / "fields.zarr")
    else:
        fields = obj  # read into memory, so writing over the input's own folder is safe
        fields.save(out / "fields.zarr")
    if not fields.valid.any():
        raise RodwarpError("no voxel of the grid lies inside the packing (every ball is empty or leaves "
                           "the domain); lower --radius/--spacing or pass --keep-outside")
    n_steps = 2 + (5 if opts.figures else 0)  # statistics, tangles, then each figure
    with slow_phase("statistics, tangles and figures", n_steps, enabled=progress, unit="steps") as step:
        stats = field_statistics(fields, method=opts.outlier, connectivity=opts.connectivity, bins=opts.bins,
                                 contact_cluster_fraction=cluster)
        step(1)
        summary = _summary_with_figures(fields, stats, src, kind, opts, out, step)
    summary["analysis_wall_s"] = time.perf_counter() - t0
    write_json(out / "summary.json", summary, finite=True)
    run.complete()
    return summary


def _summary_with_figures(fields: Fields, stats: dict, src, kind: str, opts: AnalyzeOptions, out: Path,
                          step) -> dict:
    """summary.json's contents, and the figures (``step(k)`` after each, for the slow-phase note)."""
    from rodwarp.analysis._stats import find_tangles

    summary = {
        "input": str(src),
        "input_kind": kind,
        "radius": fields.radius,
        "spacing": fields.spacing,
        "units": fields.units,
        "grid_shape_zyx": list(fields.shape),
        "axis_order": "z,y,x",
        "convention": opts.convention if kind == "rods" else fields.attrs.get("convention", "as read"),
        **{k: v for k, v in fields.attrs.items() if k not in ("source",)},
        "options": asdict(opts),
        **stats,
        "rodwarp_version": versions()["rodwarp"],
        "versions": versions("matplotlib"),
        "analysis_wall_s": None,
    }
    if opts.figures:
        from rodwarp.analysis import _figures as fieldplots

        labels, _ = find_tangles(fields.e, fields.valid, stats["e_lb"], connectivity=opts.connectivity,
                                 spacing=fields.spacing, system_size=fields.system_size)
        step(2)
        draws = [lambda: fieldplots.plot_histograms(fields, stats, out / "histograms.png"),
                 lambda: fieldplots.plot_slices(fields, out / "slices.png"),
                 lambda: fieldplots.plot_zprofiles(stats, out / "zprofiles.png"),
                 lambda: fieldplots.plot_tangles(fields, labels, stats, out / "tangles.png"),
                 lambda: fieldplots.plot_distributions(fields, stats, out / "distributions.png")]
        figs = []
        for k, draw in enumerate(draws):
            figs.append(draw())
            step(3 + k)
        summary["figures"] = [Path(f).name for f in figs]
    return summary


def _fields_with_progress(rods: RodSet, contacts, opts: AnalyzeOptions, progress: bool) -> Fields:
    from rodwarp import _warp
    from rodwarp.analysis._fields import compute_fields

    # a first run compiles the field kernels: say so before the bar, not after a silent wait
    if opts.convention == "text":  # the authors' convention is NumPy
        _warp.load_kernels(_warp.resolve_device(opts.device), ("acn", "fields"), progress=progress)
    with progress_bar(progress, unit="voxels") as update:
        return compute_fields(rods, radius=opts.radius, spacing=opts.spacing, diameter=opts.diameter,
                              length=opts.length, keep_outside=opts.keep_outside,
                              contact_tolerance=opts.contact_tolerance, contacts=contacts,
                              device=opts.device, progress=lambda done, total: update("fields", done, total),
                              convention=opts.convention)
