"""Helpers that every part of rodwarp shares, one per job.

* :func:`one_line_error` - a :class:`~rodwarp.errors.RodwarpError` whose message is one line
  (the CLI prints it as is, so a message must never spill over several lines);
* :func:`json_safe` - any result (NumPy scalars and arrays, paths, NaN) as plain JSON values;
* :func:`versions` and :func:`version_line` - the versions recorded in every summary;
* :func:`progress_bar` - one progress bar per stage of a long computation (``rich``, on
  stderr);
* :func:`note`, :func:`set_quiet` and :func:`slow_phase` - notes on stderr (silenced by
  ``--quiet``), and a phase that says so within :data:`NOTE_AFTER_S` when it runs long;
* :func:`option` and :func:`option_table` - a command's parameter dataclass field with its
  default and ``--help`` line, and the table the CLI's option generator reads;
* :func:`lazy_exports` - the flat public face of a subpackage whose heavy parts (Warp,
  matplotlib) load only when used, so ``rodwarp --help`` stays fast.

This is the bottom layer: it imports nothing from rodwarp but :mod:`rodwarp.errors`, and no
Warp at import time.  File writes live one layer up, in :mod:`rodwarp.rodset.files`.
"""

from __future__ import annotations

import contextlib
import importlib
import math
import platform
import sys
import time
from pathlib import Path
from typing import Any, Callable, Iterator

from rodwarp.errors import RodwarpError

__all__ = ["one_line_error", "json_safe", "versions", "version_line", "progress_bar", "note", "set_quiet", "quiet",
           "slow_phase", "NOTE_AFTER_S", "lazy_exports", "option", "option_table"]

#: a phase that has run this long (s) without output says what it is doing (a note and a bar on
#: stderr), so that no command sits silent for longer
NOTE_AFTER_S = 2.0
#: the process's ``--quiet``, read by the notes of code that a command's options do not reach
#: (the packing): quiet in a library call or a sweep's worker, and set by every command's
#: ``--quiet`` option, off unless given (:func:`set_quiet`)
_QUIET = True


def one_line_error(msg: str) -> RodwarpError:
    """A :class:`RodwarpError` whose message is ``msg`` folded onto one line.

    Parameters
    ----------
    msg : str
        What is wrong and how to fix it; runs of white space (newlines included) become one
        space.

    Returns
    -------
    RodwarpError
        To be raised by the caller (``raise one_line_error(...)``), so tracebacks point at the
        place that found the problem.
    """
    return RodwarpError(" ".join(str(msg).split()))


def json_safe(obj: Any, *, finite: bool = True, strict: bool = False) -> Any:
    """``obj`` as plain JSON values: dicts, lists, str, int, float, bool and None.

    Parameters
    ----------
    obj : any
        Nested dicts, lists and tuples of NumPy scalars and arrays, paths, numbers and strings.
    finite : bool
        NaN and infinities become None (strict JSON readers reject them); with ``False`` they
        stay floats (``json.dumps`` then writes ``NaN``).
    strict : bool
        Raise TypeError for an object of no known kind instead of writing its ``str``.

    Returns
    -------
    object
        Arrays become (nested) lists, NumPy scalars Python numbers, paths strings, tuples lists,
        dict keys strings; anything else becomes its ``str`` (unless ``strict``), so that
        writing a summary never fails at its last step over a stray object.

    Raises
    ------
    TypeError
        With ``strict``, an object that is none of the kinds above.
    """
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): json_safe(v, finite=finite, strict=strict) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v, finite=finite, strict=strict) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist(), finite=finite, strict=strict)
    if obj is None or isinstance(obj, str):
        return obj
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if (math.isfinite(x) or not finite) else None
    if isinstance(obj, Path):
        return str(obj)
    if strict:
        raise TypeError(f"cannot serialise {type(obj).__name__} to JSON")
    return str(obj)


def _module_version(name: str) -> str | None:
    try:
        mod = importlib.import_module(name)
    except Exception:  # noqa: BLE001 - an optional package that is absent or broken has no version
        return None
    # warp keeps its version in warp.config.version (importing warp does not initialise it)
    return getattr(mod, "__version__", None) or getattr(getattr(mod, "config", None), "version", None)


def versions(*modules: str) -> dict[str, str | None]:
    """Versions of rodwarp, Python, the platform and the packages a result depends on.

    Parameters
    ----------
    *modules : str
        Packages beyond the default numpy, scipy and warp (e.g. ``"matplotlib"``, ``"dask"``);
        one that cannot be imported is recorded as None.

    Returns
    -------
    dict
        ``rodwarp``, ``python``, ``platform``, then one key per package.
    """
    from rodwarp._version import __version__

    out: dict[str, str | None] = {"rodwarp": __version__, "python": platform.python_version(),
                                  "platform": platform.platform()}
    for name in ("numpy", "scipy", "warp", *modules):
        out[name] = _module_version(name)
    return out


def version_line() -> str:
    """``rodwarp X, warp Y, numpy Z``: what ``rodwarp --version`` prints."""
    v = versions()
    return f"rodwarp {v['rodwarp']}, warp {v['warp']}, numpy {v['numpy']}"


@contextlib.contextmanager
def progress_bar(enabled: bool = True, unit: str = "", *, seconds: bool = False, remaining: bool = False,
                 note: bool = False) -> Iterator[Callable[..., None]]:
    """A progress display for a computation in stages; yields ``update(stage, done, total, note=None)``.

    The bars go to stderr, like every note: stdout carries only a command's result line, so
    ``rodwarp simulate ... > result.txt`` captures the result and nothing else.

    Parameters
    ----------
    enabled : bool
        False: ``update`` does nothing and nothing is printed (``--quiet``).
    unit : str
        What ``done`` counts (``"voxels"``, ``"points"``), shown after the counts.
    seconds : bool
        ``done`` and ``total`` are simulated seconds, shown as ``t=0.50/5.00 s`` (a simulation's
        stages) instead of counts.
    remaining : bool
        Show the estimated time remaining as well as the time elapsed.
    note : bool
        Show the text last passed as ``update(..., note=...)`` (a rate, the item just done).

    Yields
    ------
    callable(stage, done, total=None, note=None)
        Each new ``stage`` name gets its own bar; ``total`` None means not known yet.
    """
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    counts = TextColumn("t={task.completed:.2f}/{task.total:.2f} s") if seconds else MofNCompleteColumn()
    columns = [TextColumn("{task.description}"), BarColumn(), counts]
    if unit:
        columns.append(TextColumn(unit))
    columns.append(TimeElapsedColumn())
    if remaining:
        columns.append(TimeRemainingColumn())
    if note:
        columns.append(TextColumn("{task.fields[note]}"))
    # Console(stderr=True) looks sys.stderr up at each write, so a redirected stderr (a test's
    # capture) receives the bars too
    with Progress(*columns, console=Console(stderr=True), disable=not enabled, transient=False) as bar:
        tasks: dict[str, Any] = {}

        def update(stage: str, done: float, total: float | None = None, note: str | None = None) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total, note="")
            if note is None:
                bar.update(tasks[stage], completed=done, total=total)
            else:
                bar.update(tasks[stage], completed=done, total=total, note=note)

        yield update


def set_quiet(value: bool) -> bool:
    """Set the process's ``--quiet`` (no notes, no bars from code the options do not reach).

    Parameters
    ----------
    value : bool
        True silences :func:`note` and :func:`slow_phase` where they are not told otherwise.

    Returns
    -------
    bool
        ``value``, so that this can be a command-line option's callback.
    """
    global _QUIET
    _QUIET = bool(value)
    return _QUIET


def quiet() -> bool:
    """Whether the process is quiet (:func:`set_quiet`): True in a library call, a command's
    ``--quiet`` on the command line."""
    return _QUIET


def note(msg: str, *, enabled: bool | None = None) -> None:
    """Print ``note: msg`` as one line on stderr, unless quiet.

    Parameters
    ----------
    msg : str
        What is happening or was decided (not a result: results go to stdout, from the CLI).
    enabled : bool, optional
        Print or not; None: unless the process is quiet (:func:`quiet`).
    """
    if enabled if enabled is not None else not _QUIET:
        print(f"note: {' '.join(str(msg).split())}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def slow_phase(what: str, total: float | None = None, *, enabled: bool | None = None, unit: str = "",
               after: float | None = None) -> Iterator[Callable[..., None]]:
    """A phase that is silent while short and says what it is doing once it runs long.

    Yields ``update(done, total=None)``. ``after`` seconds into the phase ``note: <what>...``
    is printed on stderr (by a timer, so even while the phase is between two updates), and the
    next update opens a progress bar over ``total`` (time elapsed and remaining); a phase that
    ends sooner prints nothing, so a quick phase (a dozen rods) adds no output while a long one
    (17,280 rods) speaks within ``after``.

    Parameters
    ----------
    what : str
        The phase, as the note and the bar name it (``"placing 17280 rods"``).
    total : float, optional
        What ``done`` counts up to (None: not known).
    enabled : bool, optional
        False: never print; None: unless the process is quiet (:func:`quiet`).
    unit : str
        What ``done`` counts (``"rods"``), shown after the counts.
    after : float, optional
        Seconds of silence allowed (default :data:`NOTE_AFTER_S`, read at each phase's start).

    Yields
    ------
    callable(done, total=None)
        Call it as the phase advances; the bar opens at the first call after the note.
    """
    import threading

    enabled = (not _QUIET) if enabled is None else enabled
    after = NOTE_AFTER_S if after is None else after
    start = time.perf_counter()
    said = threading.Event()
    lock = threading.Lock()

    def say() -> None:  # once, from the timer or from the first late update, whichever is first
        with lock:
            if not said.is_set():
                note(f"{what}...", enabled=True)
                said.set()

    timer = threading.Timer(after, say)
    timer.daemon = True
    if enabled:
        timer.start()
    with contextlib.ExitStack() as stack:
        stack.callback(timer.cancel)
        bar: list[Callable[..., None]] = []  # the bar's update, once open

        def update(done: float, total_now: float | None = None) -> None:
            if not enabled:
                return
            if not bar:
                if time.perf_counter() - start < after:
                    return
                say()
                bar.append(stack.enter_context(progress_bar(True, unit, remaining=True)))
            bar[0](what, done, total if total_now is None else total_now)

        yield update


def lazy_exports(package: str, where: dict[str, str]):
    """Module ``__getattr__`` and ``__dir__`` of a subpackage's flat public face.

    Parameters
    ----------
    package : str
        The subpackage (``__name__`` of its ``__init__``).
    where : dict
        Public name -> private module (relative to ``package``) that defines it.

    Returns
    -------
    (__getattr__, __dir__)
        Assign both in the ``__init__``: ``rodwarp.analysis.compute_fields`` then imports
        ``rodwarp.analysis._fields`` on first use only (the scikit-image pattern, without
        its ``lazy_loader`` dependency).
    """

    def __getattr__(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        importlib.import_module(package).__dict__[name] = value  # later look-ups skip this hook
        return value

    def __dir__():
        return sorted(set(where) | set(importlib.import_module(package).__dict__))

    return __getattr__, __dir__


def option(default, help: str, **metadata):
    """A field of a command's parameter dataclass: its default and its ``--help`` line, stated
    once; the command line takes both from here (:func:`option_table`, the CLI's option
    generator). ``metadata`` adds more keys (e.g. ``short``, a folder-name abbreviation)."""
    from dataclasses import field

    return field(default=default, metadata={"help": help, **metadata})


def option_table(cls) -> dict:
    """``{field: (default, help)}`` of a parameter dataclass whose fields carry ``help`` metadata
    (:func:`option`): where the CLI's options take their defaults and help text from. A
    default factory is called (lists)."""
    from dataclasses import MISSING, fields

    out = {}
    for f in fields(cls):
        if "help" in f.metadata:
            default = f.default_factory() if f.default_factory is not MISSING else f.default
            out[f.name] = (default, f.metadata["help"])
    return out
