"""Helpers that every part of rodwarp shares, one per job.

* :func:`one_line_error` - a :class:`~rodwarp.errors.RodwarpError` whose message is one line
  (the CLI prints it as is, so a message must never spill over several lines);
* :func:`json_safe` - any result (NumPy scalars and arrays, paths, NaN) as plain JSON values;
* :func:`versions` and :func:`version_line` - the versions recorded in every summary;
* :func:`progress_bar` - one progress bar per stage of a long computation (``rich``);
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
from pathlib import Path
from typing import Any, Callable, Iterator

from rodwarp.errors import RodwarpError

__all__ = ["one_line_error", "json_safe", "versions", "version_line", "progress_bar", "lazy_exports", "option",
           "option_table"]


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
    from rodwarp import __version__

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
    with Progress(*columns, disable=not enabled, transient=False) as bar:
        tasks: dict[str, Any] = {}

        def update(stage: str, done: float, total: float | None = None, note: str | None = None) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total, note="")
            if note is None:
                bar.update(tasks[stage], completed=done, total=total)
            else:
                bar.update(tasks[stage], completed=done, total=total, note=note)

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
