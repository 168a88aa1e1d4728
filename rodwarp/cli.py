"""The ``rodwarp`` command line (typer).

Every option is checked before any work (:mod:`rodwarp.validation`). Exit codes: 0 done;
2 bad input or an unusable output location (one line on stderr saying what is wrong and how to
fix it); 3 a simulation blew up (the message names the step and the likely cause); 4 a sweep
finished with failed points; 1 an internal error or an abort. No raw tracebacks.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import inspect
import sys
import typing
from pathlib import Path
from typing import Optional

import typer

from rodwarp._util import set_quiet, version_line
from rodwarp.analysis import AnalyzeOptions, fields_help
from rodwarp.ct import PhantomOptions, SegmentOptions, make_phantom
from rodwarp.errors import RodwarpError, SimulationBlowUp
from rodwarp.experiments import ProtocolParams, SweepSpec, option_table

# every command's option defaults and help texts come from its parameter dataclass's fields
# (rodwarp._util.option), so each is stated once; docs/commands.md, "Where an option is declared"
_AN = option_table(AnalyzeOptions)
#: `rodwarp analyze`'s options in --help order: AnalyzeOptions fields, and the command's own
_ANALYZE_OPTIONS = ("out", "radius", "spacing", "diameter", "length", "units", "keep_outside", "contact_tolerance",
                    "outlier", "connectivity", "bins", "convention", "device", "figures", "overwrite", "quiet")
_SG = option_table(SegmentOptions)
#: `rodwarp segment`'s options in --help order: SegmentOptions fields, and the command's own
_SEGMENT_OPTIONS = ("voxel_size", "units", "diameter", "out", "shape", "dark_rods", "min_fill", "chunk",
                    "contact_tolerance", "figures", "overwrite", "quiet")
_PH = option_table(PhantomOptions)
#: `rodwarp phantom`'s options in --help order: PhantomOptions fields, and the command's own
_PHANTOM_OPTIONS = ("shape", "voxel_size", "units", "out", "blur", "cnr", "ring", "cupping", "streaks", "fov", "dark",
                    "z_thickness", "n_rods", "radius", "aspect", "touching", "seed", "overwrite", "quiet")
_P = option_table(ProtocolParams)
_W = option_table(SweepSpec)
#: `rodwarp sweep`'s options in --help order: SweepSpec fields, the grids under their option
#: names (comma-separated text; --seeds, a count, keeps its name), and the command's own
_SWEEP_RENAMED = {"alphas": "alpha", "freqs": "freq", "gravities": "gravity", "static_loads": "static_load"}
_SWEEP_OPTIONS = ("alpha", "freq", "gravity", "static_load", "seeds", "entangle_duration", "duration", "amplitude",
                  "save_every", "out", "scheduler", "workers", "device", "share_entangling", "figures", "overwrite",
                  "quiet", "set_")
_FROM_TABLE = object()


def _option(table: dict, name: str, default=_FROM_TABLE, help: str | None = None):
    """The typer option of the dataclass field ``name``: its default and help from ``table``
    (:func:`rodwarp.experiments.option_table`), either replaced where the option's form differs
    (a comma-separated list for a tuple or list field)."""
    field_default, field_help = table[name]
    return typer.Option(field_default if default is _FROM_TABLE else default, help=help or field_help)


def _sim(name: str, **kw):
    """A ``rodwarp simulate`` option from :class:`~rodwarp.experiments.ProtocolParams`."""
    return _option(_P, name, **kw)


def _swp(name: str, **kw):
    """A ``rodwarp sweep`` option from :class:`~rodwarp.experiments.SweepSpec`."""
    return _option(_W, name, **kw)


def _csv(values) -> str:
    """A tuple or list default as the comma-separated text its option takes (``1,1,2.5``)."""
    return ",".join(f"{v:g}" for v in values)


def _flag(name: str, help: str, **kw):
    """A flag that is off by default and has no useful negative form: ``--name`` alone in
    ``--help`` (typer would add ``--no-name``, which only restates the default)."""
    return typer.Option(False, f"--{name}", help=help, show_default=False, **kw)


#: ``--quiet`` on every command that writes, in the same words
QUIET_HELP = "No progress bar and no notes on stderr (the result line, warnings and errors still print)."


def _quiet_option():
    """``--quiet``, alike on every writing command. As the options are read its value is also
    given to the code no option reaches (the packing's note), through
    :func:`rodwarp._util.set_quiet`."""
    return _flag("quiet", QUIET_HELP, callback=set_quiet)


def _field_options(cls, table: dict, order: tuple[str, ...], renamed: dict | None = None):
    """Give a command that takes ``**fields`` one option per field of ``cls`` named in ``order``.

    ``order`` is the ``--help`` order of every option of the command. A name that is a
    parameter of the command keeps that parameter (an option of the command's own, or a field
    taken in another form, such as a tuple given as 'X,Y,Z'); any other name is a field of
    ``cls`` whose option takes its type from the dataclass and its default and help from
    ``table``, so none of them is restated here. ``renamed`` maps a field to the command's
    parameter that takes it under another name (``alphas`` as ``--alpha``). typer reads the
    resulting signature. A bool field that is off by default is a flag alone (``--keep-outside``,
    :func:`_flag`); one that is on by default keeps its negative (``--figures/--no-figures``).
    """
    hints = typing.get_type_hints(cls)
    keyword = inspect.Parameter.KEYWORD_ONLY
    missing = sorted(set(table) - set(order) - set(renamed or {}))
    if missing:  # a new field must be placed in the command's --help order
        raise TypeError(f"{cls.__name__} fields {', '.join(missing)} have no place in the command's options")

    def option_type(tp):
        # `int | None` as typing.Optional, which every typer version reads
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return typing.Optional[args[0]] if len(args) == 1 and len(typing.get_args(tp)) == 2 else tp

    def decorate(fn):
        sig = inspect.signature(fn)
        own = {n: p for n, p in sig.parameters.items() if p.kind is not inspect.Parameter.VAR_KEYWORD}
        params = [p for n, p in own.items() if n not in order]  # the context
        for name in order:
            if name in own:
                params.append(own[name].replace(kind=keyword))
            else:
                default, help_text = table[name]
                if hints[name] is bool and default is False:
                    option = _flag(name.replace("_", "-"), help_text)
                else:
                    option = typer.Option(default, help=help_text)
                params.append(inspect.Parameter(name, keyword, default=option, annotation=option_type(hints[name])))
        fn.__signature__ = sig.replace(parameters=params)
        return fn

    return decorate


#: `rodwarp simulate`'s options in --help order: every ProtocolParams field in its dataclass order
#: (ExperimentParams, each protocol's, RunParams), then the command's own; a new parameter is one
#: field, placed by its dataclass
_SIMULATE_OPTIONS = (*(f.name for f in dataclasses.fields(ProtocolParams)), "resume", "overwrite", "out",
                     "entangled_from", "quiet")


def _flags_as_flags(params: list) -> list:
    """``params`` with every flag's value placeholder blanked: typer's rich ``--help`` prints
    the type of each option, ``<bool>`` too, which made ``--quiet <bool>`` (and ``--help
    <bool>``) read as if they took a value. A flag takes none."""
    for p in params:
        if getattr(p, "is_flag", False) and p.metavar is None:
            p.metavar = ""
    return params


class _Commands(typer.core.TyperGroup):
    """The ``rodwarp`` group: every command's flags (``--help`` included, which typer adds
    itself) are shown as flags (:func:`_flags_as_flags`)."""

    def get_params(self, ctx):
        return _flags_as_flags(super().get_params(ctx))

    def get_command(self, ctx, cmd_name):
        cmd = super().get_command(ctx, cmd_name)
        if cmd is not None:
            _flags_as_flags(cmd.get_params(ctx))
        return cmd


app = typer.Typer(cls=_Commands, add_completion=False, no_args_is_help=False,
                  help="Simulate and analyse packings of elastic rods (NVIDIA Warp).",
                  epilog="Example: rodwarp simulate --alpha 100 --freq 10, then rodwarp analyze "
                         "runs/alpha100_freq10_g0.5_seed0")


def _friendly(fn):
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except RodwarpError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2)
        except SimulationBlowUp as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(3)
        except FileNotFoundError as e:
            typer.echo(f"error: no such file: {e.filename or e}", err=True)
            raise typer.Exit(2)
        except OSError as e:  # a location problem found during the work (disk full, read-only)
            import errno
            import os

            where = f" {e.filename}" if e.filename else ""
            # a kernel that Warp compiles mid-run is written to the kernel cache, not to --out
            warp_layer = sys.modules.get("rodwarp._warp")
            cache = os.path.realpath(warp_layer.kernel_cache_dir()) if warp_layer is not None else None
            if cache and e.filename and os.path.realpath(str(e.filename)).startswith(cache):
                typer.echo(f"error: cannot write the Warp kernel cache{where}: {e.strerror or e}; unset "
                           "RODWARP_KERNEL_CACHE or point it at a writable folder", err=True)
            elif e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO):
                typer.echo(f"error: cannot write{where}: {e.strerror or e}; free space or choose another --out "
                           "(earlier results are kept)", err=True)
            else:
                typer.echo(f"error: cannot access{where}: {e.strerror or e}", err=True)
            raise typer.Exit(2)
        except KeyboardInterrupt:
            typer.echo("interrupted; earlier results and checkpoints are kept", err=True)
            raise typer.Exit(130)
        except (typer.Exit, typer.Abort, SystemExit):
            raise
        except Exception as e:  # a bug, not bad input: one line unless RODWARP_DEBUG is set
            import os

            if os.environ.get("RODWARP_DEBUG"):
                raise
            typer.echo(f"internal error: {type(e).__name__}: {e} (set RODWARP_DEBUG=1 for the traceback)", err=True)
            raise typer.Exit(1)

    return wrapper


@contextlib.contextmanager
def _failure_recorded(outdir):
    """Record in ``outdir``'s manifest that this process's run there failed (with the cause), so
    the folder says it is incomplete and why; a refused claim leaves another run's record alone."""
    from rodwarp.rodset.rundir import mark_failed

    try:
        yield
    except (RodwarpError, SimulationBlowUp, OSError, KeyboardInterrupt) as e:
        mark_failed(outdir, e if not isinstance(e, KeyboardInterrupt) else RuntimeError("interrupted"))
        raise


def _print_version(value: bool):
    if value:
        typer.echo(version_line())
        raise typer.Exit(0)


@app.callback(invoke_without_command=True)
def _root(ctx: typer.Context,
          version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                       help="Print the versions of rodwarp, Warp and NumPy and exit.")):
    """Simulate and analyse packings of elastic rods (NVIDIA Warp)."""
    if ctx.invoked_subcommand is None:  # bare `rodwarp`: the help, and success
        typer.echo(ctx.get_help())
        raise typer.Exit(0)


def _given(ctx: typer.Context, *names: str) -> set:
    """Options of ``names`` the user typed (or set in the environment), not left at their default."""
    out = set()
    for n in names:
        src = ctx.get_parameter_source(n)
        if src is not None and getattr(src, "name", "") in ("COMMANDLINE", "ENVIRONMENT", "PROMPT"):
            out.add(n)
    return out


@app.command(epilog="Example: rodwarp version")
def version():
    """Print the versions of rodwarp, Warp and NumPy (same as rodwarp --version)."""
    typer.echo(version_line())


@app.command(epilog="Example: rodwarp simulate --alpha 100 --freq 10   (the main job; "
                     "writes runs/alpha100_freq10_g0.5_seed0/)")
@_friendly
@_field_options(ProtocolParams, _P, _SIMULATE_OPTIONS)
def simulate(
    ctx: typer.Context,
    box: str = _sim("box", default=_csv(_P["box"][0])),
    strains: str = _sim("strains", default=_csv(_P["strains"][0])),
    resume: bool = _flag("resume", "Continue a killed run from its newest checkpoint in --out (only the folder's "
                                   "own run, same parameters)."),
    overwrite: bool = _flag("overwrite", "Replace the run that --out holds (its outputs are removed first)."),
    out: Optional[Path] = typer.Option(None, help="Output directory (default runs/alpha{A}_freq{F}_g{G}_seed{S}, "
                                                  "plus every other parameter that differs from its default)."),
    initial: Optional[Path] = _sim("initial"),
    initial_diameter: Optional[float] = typer.Option(None, "--diameter", help=_P["initial_diameter"][1]),
    entangled_from: Optional[Path] = typer.Option(
        None, help="Start the stability test from the entangled packing of this earlier run folder (its "
                   "entangled.npz): same parameters but for --freq, --amplitude and --duration; the result equals "
                   "a run of its own entangling, bit for bit on the CPU."),
    quiet: bool = _quiet_option(),
    **fields,
):
    """Random packing, entangling by vibration, then the vibration stability test."""
    from rodwarp.experiments import default_run_name, run_protocol

    # the options that are ProtocolParams fields, the two taken in another form converted
    checked = ProtocolParams(**fields, box=_parse_box(box), strains=_parse_strains(strains),
                             initial=str(initial) if initial else None,
                             initial_diameter=initial_diameter).validate(
        explicit=_given(ctx, *(f.name for f in dataclasses.fields(ProtocolParams)), "box", "strains", "initial",
                        "initial_diameter"))
    params = checked.params  # with --initial: the input's alpha and length
    from rodwarp._warp import kernel_cache_dir, usable_cache_dir

    usable_cache_dir(kernel_cache_dir())  # an unusable RODWARP_KERNEL_CACHE is refused before --out is taken
    if entangled_from is not None:  # refused before any note about the run
        from rodwarp.experiments import check_branch_protocol

        check_branch_protocol(params)
    from rodwarp._util import note
    from rodwarp.experiments import protocol

    if params.law == "imc" and params.rolling:  # a departure from the paper's model: said even with --quiet
        typer.echo("warning: --rolling with --contact-law imc: DisMech's IMC friction acts on the centreline (no "
                   "rolling); this run lets the rods spin, which the paper's model did not", err=True)
    for why in protocol(params.protocol).notes(params):
        note(why, enabled=not quiet)
    outdir = out or Path("runs") / default_run_name(params)
    with _failure_recorded(outdir):
        summary = run_protocol(checked, outdir, progress=not quiet, resume=resume, overwrite=overwrite,
                               entangled_from=entangled_from)
    tau = ((summary.get("excitation") or {}).get("shake") or {}).get("tau")
    typer.echo(
        f"alpha={summary['alpha']:g} n_rods={summary['n_rods']} a/g={summary['a_over_g']:.3g} "
        f"Z={summary['contacts_per_rod']:.2f} f={summary['largest_cluster_fraction']:.3f} "
        + (f"tau={tau['tau']:.2f} " if tau and tau.get("tau") is not None else "")
        + f"stable={summary['stable']} wall={summary['wall_time_s']:.1f}s -> {outdir}"
    )
    for block in ("lab", "excitation"):
        for w in (summary.get(block) or {}).get("warnings", []):
            typer.echo(f"warning: {w}", err=True)


@app.command(epilog="Example: rodwarp analyze runs/alpha100_freq10_g0.5_seed0   (writes its analysis/ folder; "
                     "an earlier analysis there is replaced)",
             help="Local fields, their statistics, outliers, tangles and percolation.\n\n"
                  f"Fields (one array each in fields.zarr; means in summary.json; panels in the figures): "
                  f"{fields_help()}.")
@_friendly
@_field_options(AnalyzeOptions, _AN, _ANALYZE_OPTIONS)
def analyze(
    input: Path = typer.Argument(..., help="simulate/segment output directory, rod-set file (.npz, .zarr, .csv) "
                                           "or precomputed fields (.zarr, .npz with e and n)."),
    out: Optional[Path] = typer.Option(None, help="Output directory (default analysis/ beside the input)."),
    overwrite: bool = _flag("overwrite", "Write into --out even when it holds another kind of run."),
    quiet: bool = _quiet_option(),
    **fields,
):
    from rodwarp.analysis import analyze as run_analyze
    from rodwarp.analysis import default_out

    opts = AnalyzeOptions(**fields)
    opts.validate()
    outdir = out or default_out(input)
    with _failure_recorded(outdir):
        s = run_analyze(input, outdir, opts, progress=not quiet, overwrite=overwrite)

    def f(v):
        return "n/a" if v is None else f"{v:.3g}"

    ext = s.get("largest_tangle_extent") or {}
    typer.echo(
        f"mean phi={f(s.get('mean_phi'))} S={f(s.get('mean_S'))} c={f(s.get('mean_c'))} e={f(s.get('mean_e'))} "
        f"cv_e={f(s.get('cv_e'))} e_lb={f(s.get('e_lb'))} outliers={f(s.get('outlier_fraction'))} "
        f"tangles={s.get('n_tangles')} largest xi/L=({f(ext.get('x'))}, {f(ext.get('y'))}, {f(ext.get('z'))}) "
        f"percolates={s.get('percolates')} -> {outdir}"
    )


@app.command(epilog="Example: rodwarp phantom random --shape 256 256 256 --n-rods 200 --cnr 5 --out ct/stack.tif")
@_friendly
@_field_options(PhantomOptions, _PH, _PHANTOM_OPTIONS)
def phantom(
    rods: str = typer.Argument(..., help="Rod set (npz, zarr, CSV), a simulate output directory, or a scene in "
                                         "voxel units: 'random' (straight rods, see --n-rods), 'bundles' "
                                         "(bundles of touching parallel rods), 'arcs' (gently curved rods), "
                                         "'wires' (a nest-like tangle of curved wires)."),
    shape: tuple[int, int, int] = typer.Option(..., help="Volume shape Z Y X (slices, rows, columns)."),
    out: Path = typer.Option(..., help="Output TIFF file, NAME.tif (a file, not a folder: the stack that "
                                       "`rodwarp segment` reads); its ground truth is written beside it as "
                                       "NAME_truth.json and NAME_truth.npz."),
    overwrite: bool = _flag("overwrite", "Replace --out even when it is not a rodwarp phantom, or lies in another "
                                         "command's run folder (an earlier phantom is always replaced)."),
    quiet: bool = _quiet_option(),
    **fields,
):
    """Synthetic 16-bit CT of a rod set: partial volume, blur, noise and artefacts, with ground truth."""
    from dataclasses import asdict

    from rodwarp.ct import check_phantom

    opts = asdict(PhantomOptions(**fields))
    check_phantom(rods=rods, shape=shape, out=out, **opts)
    from rodwarp.ct import check_phantom_out

    check_phantom_out(out, overwrite=overwrite)
    from rodwarp._util import slow_phase

    # no progress hook inside the rendering: a note once it has run NOTE_AFTER_S (large volumes)
    with slow_phase(f"rendering the {' x '.join(str(n) for n in shape)} voxel phantom", enabled=not quiet):
        rs = make_phantom(rods, shape, out, **opts)
    typer.echo(f"{rs.n_rods} rods, {len(rs.contacts) if rs.contacts is not None else 0} contacts -> {out}")


@app.command(epilog="Example: rodwarp segment ct/stack.tif --voxel-size 0.078 --units mm --out ct/segment")
@_friendly
@_field_options(SegmentOptions, _SG, _SEGMENT_OPTIONS)
def segment(
    stack: Path = typer.Argument(..., help="Multi-page TIFF, a folder of slice TIFFs, or a zarr array."),
    out: Optional[Path] = typer.Option(None, help="Output directory (default segment/ beside the stack)."),
    dark_rods: Optional[bool] = typer.Option(None, "--dark-rods/--bright-rods", help=_SG["dark_rods"][1]),
    overwrite: bool = _flag("overwrite", "Write into --out even when it holds another command's run (an earlier "
                                         "segmentation there is always replaced)."),
    quiet: bool = _quiet_option(),
    **fields,
):
    """CT stack to rod centrelines and contacts (CPU)."""
    from rodwarp.ct import run_segment
    from rodwarp.ct import default_out as seg_default_out

    opts = SegmentOptions(**fields, dark_rods=dark_rods)
    outdir = out if out is not None else seg_default_out(stack)
    opts.validate(stack, outdir)
    with _failure_recorded(outdir):
        s = run_segment(stack, out=outdir, progress=not quiet, overwrite=overwrite, **opts.run_kwargs())
    u = s["units"]
    b = s.get("quality", {}).get("binarised")  # a two-level stack, segmented from its mask
    mask = f"binarised stack (levels {b['levels'][0]}/{b['levels'][1]}, rods {b['rod_level']}), " if b else ""
    typer.echo(f"{s['n_rods']} {'filaments' if s.get('shape') == 'curved' else 'rods'}, {s['n_contacts']} contacts, "
               f"diameter {s['diameter']:.4g} {u} ({s['diameter_voxels']:.2f} voxels), {mask}{s['wall_time_s']:.1f} s "
               f"-> {s['out']}")
    for flag in s.get("quality", {}).get("flags", []):
        typer.echo(f"warning: {flag}", err=True)


def _floats(text: str, name: str) -> list[float]:
    """A grid option's comma-separated finite numbers (``--alpha 25,50,100``).

    An empty item (``25,,50``, a trailing comma) or a value given twice is refused, never
    dropped: either would leave the grid with fewer points than were written.
    """
    items = [v.strip() for v in text.split(",")]
    if not any(items):
        raise RodwarpError(f"{name} needs at least one value")
    if "" in items:
        raise RodwarpError(f"{name} {text}: item {items.index('') + 1} of {len(items)} is empty; give "
                           f"comma-separated numbers without empty items, e.g. 25,50,100")
    try:
        vals = [float(v) for v in items]
    except ValueError:
        raise RodwarpError(f"{name} must be comma-separated numbers, e.g. 25,50,100; got '{text}'") from None
    import math

    bad = [v for v in vals if not math.isfinite(v)]
    if bad:
        raise RodwarpError(f"{name} values must be finite numbers, got {bad[0]:g} in '{text}'")
    twice = next((v for k, v in enumerate(vals) if v in vals[:k]), None)
    if twice is not None:
        raise RodwarpError(f"{name} {text}: {twice:g} is given twice; give each value once (one grid point per "
                           f"value)")
    return vals


def _overrides(items: list[str]) -> dict:
    """``--set KEY=VALUE`` items as ProtocolParams overrides, each VALUE read as its field's type.

    A key the sweep owns (:data:`rodwarp.experiments.SWEEP_OWNED`: --out, --alpha, ...)
    is refused naming the sweep's own option, and a key given twice is refused rather than
    the last value kept.
    """
    import dataclasses

    from rodwarp.errors import RodwarpError
    from rodwarp.experiments import ProtocolParams
    from rodwarp.experiments import SWEEP_OWNED

    types = {f.name: f.type for f in dataclasses.fields(ProtocolParams)}
    out, given = {}, {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key:
            raise RodwarpError(f"--set needs KEY=VALUE, got '{item}'; e.g. --set rod_model=rigid")
        if key in SWEEP_OWNED:
            raise RodwarpError(f"--set {key}: {SWEEP_OWNED[key]}")
        if key not in types:
            raise RodwarpError(f"--set {key}: no such simulate parameter; see `rodwarp simulate --help`")
        text = text.strip()
        if key in given:
            raise RodwarpError(f"--set {key} is given twice ({key}={given[key]} and {key}={text}); give each "
                               f"parameter once")
        given[key] = text
        if key == "strains":  # its own message names an empty or unreadable item
            out[key] = _parse_strains(text, "--set strains")
            continue
        kind = str(types[key])
        try:
            if "bool" in kind:
                if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError
                value = text.lower() in ("true", "1", "yes")
            elif "int" in kind and "float" not in kind:
                value = int(text)
            elif "float" in kind:
                value = None if text.lower() == "none" and "None" in kind else float(text)
            elif "tuple" in kind:  # 'X,Y,Z' (box), as simulate's own option takes it
                value = _parse_box(text)
            else:
                value = text
        except ValueError:  # RodwarpError too: the box's own message names --box, not --set
            what = "three positive numbers 'X,Y,Z'" if "tuple" in kind else f"a valid {kind.replace(' | None', '')}"
            raise RodwarpError(f"--set {key}={text}: not {what}") from None
        out[key] = value
    return out


@app.command(epilog="Example: rodwarp sweep --alpha 25,50,100 --freq 1,10 --seeds 2 --out runs/sweep   "
                     "(exit 4 when any point failed)")
@_friendly
@_field_options(SweepSpec, _W, _SWEEP_OPTIONS, renamed=_SWEEP_RENAMED)
def sweep(
    ctx: typer.Context,
    alpha: str = _swp("alphas", default=_csv(_W["alphas"][0])),
    freq: str = _swp("freqs", default=_csv(_W["freqs"][0])),
    gravity: str = _swp("gravities", default=_csv(_W["gravities"][0])),
    static_load: str = _swp("static_loads", default=_csv(_W["static_loads"][0])),
    seeds: int = _swp("seeds", default=len(_W["seeds"][0])),
    save_every: float = _sim("save_every", help="Sampling interval of each point's metrics (s of simulated time)."),
    out: Path = typer.Option(..., help="Sweep directory (results.csv, points/, figures)."),
    scheduler: Optional[str] = typer.Option(None, help="Existing Dask scheduler tcp://HOST:8786 (default: a local cluster on 127.0.0.1)."),
    workers: Optional[int] = typer.Option(None, help="Local worker processes, one point each: at most one per core "
                                                     "and as many as memory holds (default: that many); they end "
                                                     "with the sweep."),
    figures: bool = typer.Option(True, help="Draw the phase diagram at the end."),
    overwrite: bool = _flag("overwrite", "Replace the run --out holds. Without it a sweep adds its points to "
                                         "the folder's sweep of the same protocol (durations, amplitude, "
                                         "--set values) and refuses any other."),
    quiet: bool = _quiet_option(),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="Any other simulate parameter for every point, "
                                             "KEY=VALUE (repeatable; the names of `rodwarp simulate`'s options "
                                             "with underscores), e.g. --set rod_model=rigid --set rolling=false."),
    **fields,
):
    """Parameter sweep: simulate + analyze per point on Dask; results.csv, then the phase diagram."""
    from rodwarp import validation as v
    from rodwarp.experiments import phase_diagram, run_sweep

    v.integer("--seeds", seeds, ge=1, le=10_000)
    if workers is not None:  # the upper bound (cores, memory) is the local cluster's: run_sweep
        v.integer("--workers", workers, ge=1)
    sets = _overrides(set_ or [])
    if "save_every" in sets and _given(ctx, "save_every"):
        raise RodwarpError(f"--save-every {save_every:g} and --set save_every={sets['save_every']:g} both given; "
                           f"give --save-every once")
    spec = SweepSpec(alphas=_floats(alpha, "--alpha"), freqs=_floats(freq, "--freq"),
                     gravities=_floats(gravity, "--gravity"), static_loads=_floats(static_load, "--static-load"),
                     seeds=list(range(seeds)), **fields,
                     # only when changed: rows of sweeps run before this option still match their points
                     overrides={**({} if save_every == _P["save_every"][0] else {"save_every": save_every}),
                                **sets})
    spec = spec.validate()  # every value in range before any folder or cluster
    with _failure_recorded(out):
        path = run_sweep(spec, out, scheduler=scheduler, workers=workers, progress=not quiet, overwrite=overwrite)
    import json

    meta = json.loads((Path(out) / "sweep.json").read_text())
    failed, total = int(meta.get("failed") or 0), int(meta.get("n_points") or 0)
    if figures and failed < total:
        from rodwarp.rodset.rundir import writing_part

        from rodwarp._util import note

        with writing_part(out, "phase_diagram"):
            written = phase_diagram(out, note=lambda msg: note(msg, enabled=not quiet))
    else:
        written = []
    figures_drawn = sum(str(f).endswith(".png") for f in written)  # written also holds the diagram's CSVs
    typer.echo(f"{total - failed} of {total} points ok, {figures_drawn} figures -> {path}")
    if failed:
        first = meta.get("first_failure") or ""
        typer.echo(f"error: {failed} of {total} sweep points failed (their status is in {path}); "
                   f"first: {first}", err=True)
        raise typer.Exit(4)


@app.command("phase-diagram", epilog="Example: rodwarp phase-diagram runs/sweep   (writes the figures and "
                                      "alpha_star.csv into runs/sweep; --out DIR puts them elsewhere)")
@_friendly
def phase_diagram_cmd(
    sweep_dir: Path = typer.Argument(..., help="A `rodwarp sweep` output directory (with results.csv)."),
    out: Optional[Path] = typer.Option(None, help="Output directory (default SWEEP_DIR, beside results.csv). "
                                                  "Another folder becomes a phase-diagram folder of its own."),
    overwrite: bool = _flag("overwrite", "Write into --out even when it holds another run (its outputs are removed "
                                         "first); a phase diagram of the same sweep there is always replaced."),
    quiet: bool = _quiet_option(),
):
    """Phase diagram of a sweep: cv_e against a/g (Fig. 4L), f against alpha and a/g, alpha*."""
    from rodwarp._util import note
    from rodwarp.experiments import phase_diagram
    from rodwarp.rodset import rundir

    m = rundir.read_manifest(sweep_dir) if sweep_dir.is_dir() else None
    rundir.check_manifest(sweep_dir, m, "SWEEP_DIR")
    if m is not None and m.get("kind") != "sweep":
        # its figures would land among another command's outputs
        raise RodwarpError(f"'{sweep_dir}' holds {rundir._describe(m)}, not a sweep; give the --out of a "
                           "`rodwarp sweep`")
    if not (sweep_dir / "results.csv").exists():
        raise RodwarpError(f"'{sweep_dir}' holds no results.csv; run `rodwarp sweep --out {sweep_dir}` first")
    dest = sweep_dir if out is None or out.resolve() == sweep_dir.resolve() else out

    def draw():
        # failed points are left out of the diagram: a note says how many, so a thin diagram is explained
        return phase_diagram(sweep_dir, note=lambda msg: note(msg, enabled=not quiet), dest=dest, progress=not quiet)

    if dest is sweep_dir:
        # the sweep's manifest says the diagram is incomplete until its last file is written
        with rundir.writing_part(sweep_dir, "phase_diagram"):
            written = draw()
    else:
        written = _phase_diagram_folder(sweep_dir, dest, overwrite, draw)
    figures = sum(1 for p in written if p.suffix == ".png")
    tables = ", ".join(p.name for p in written if p.suffix != ".png")
    typer.echo(f"{figures} figures, {tables} -> {dest}")


def _phase_diagram_folder(sweep_dir: Path, out: Path, overwrite: bool, draw) -> list:
    """Run ``draw()`` (the phase diagram of ``sweep_dir``) into a folder ``out`` of its own.

    ``out`` is taken as a ``phase-diagram`` run folder (docs/run-folders.md): an earlier
    phase diagram of the same sweep there is replaced, anything else (another sweep's diagram,
    another command's run, files of an earlier run) is refused unless ``overwrite``.
    """
    from rodwarp.rodset.commands import PHASE_DIAGRAM_OUTPUTS
    from rodwarp.rodset import rundir

    source = str(sweep_dir.resolve())
    old = rundir.read_manifest(out) if out.is_dir() else None
    same_sweep = bool(old) and old.get("kind") == "phase-diagram" and \
        (old.get("parameters") or {}).get("sweep") == source
    run = rundir.claim(out, "phase-diagram", {"sweep": source}, PHASE_DIAGRAM_OUTPUTS, overwrite=overwrite,
                       replace_same_kind=same_sweep)
    with _failure_recorded(out):
        written = draw()
    run.complete()
    return written


def _parse_strains(text: str, name: str = "--strains"):
    """--strains 'E1,E2,...' (empty: none); their range is checked with the other options.

    An empty item (``0,,0.1``, a trailing comma) is refused, never dropped: the piston would
    press at fewer strains than were written. ``name`` is the option in messages.
    """
    if not text.strip():
        return ()
    items = [v.strip() for v in text.split(",")]
    if "" in items:
        raise RodwarpError(f"{name} {text}: item {items.index('') + 1} of {len(items)} is empty; give "
                           f"comma-separated strains without empty items, e.g. 0,0.05,0.1 ('' for none)")
    try:
        return tuple(float(v) for v in items)
    except ValueError:
        raise RodwarpError(f"{name} must be comma-separated numbers 'E1,E2,...' (e.g. 0,0.05,0.1), "
                           f"got '{text}'") from None


def _parse_box(text: str):
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise RodwarpError(f"--box must be three numbers 'X,Y,Z' in rod lengths, got '{text}'")
    import math

    if len(vals) != 3 or not all(math.isfinite(v) and v > 0 for v in vals):
        raise RodwarpError(f"--box must be three positive numbers 'X,Y,Z' in rod lengths, got '{text}'")
    return vals


#: options that take a path: an empty value becomes Path('') == Path('.'), so `--out ''` (an
#: unset shell variable) would write into the current folder without a word
_PATH_OPTIONS = ("--out", "--initial", "--entangled-from")


def _empty_path_option(args: list[str]) -> str | None:
    """The first path option of ``args`` given an empty (or all-blank) value, else None.

    Checked on the raw arguments because typer turns '' into ``Path('.')``, which cannot be
    told apart from a deliberate ``.`` afterwards. Arguments after ``--`` are not options.
    """
    for k, a in enumerate(args):
        if a == "--":
            break
        name, eq, value = a.partition("=")
        if name in _PATH_OPTIONS:
            if eq and not value.strip():
                return name
            if not eq and k + 1 < len(args) and not args[k + 1].strip():
                return name
    return None


def main(argv=None) -> int:
    """Console entry point: like ``app()`` but a usage error (a bad option value, a missing
    argument, an unknown option) is one line on stderr with exit code 2, not a box."""
    # typer >= 0.2x raises its vendored click's exceptions; older typer uses the click package
    # (which other dependencies may install alongside): catch whichever exist
    usage, abort = [], [typer.Abort]
    for modname in ("typer._click.exceptions", "click.exceptions"):
        try:
            import importlib

            mod = importlib.import_module(modname)
        except ImportError:
            continue
        usage.append(mod.UsageError)
        if hasattr(mod, "Abort"):
            abort.append(mod.Abort)
    args = list(argv if argv is not None else sys.argv[1:])
    empty = _empty_path_option(args)
    if empty:
        typer.echo(f"error: {empty} is empty; give a path ({empty} . names the current folder)", err=True)
        return 2
    try:
        rv = app(args=args, prog_name="rodwarp", standalone_mode=False)
    except tuple(usage) as e:
        cmd = e.ctx.command_path if getattr(e, "ctx", None) is not None else "rodwarp"
        msg = " ".join(e.format_message().split())
        typer.echo(f"error: {msg} (see '{cmd} --help')", err=True)
        return 2
    except tuple(abort):
        typer.echo("aborted", err=True)
        return 1
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
