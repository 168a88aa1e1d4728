"""Generic checks of option values before any work: finite, in range, and fitting.

Each check raises :class:`rodwarp.errors.RodwarpError` with one line that names the option,
says what is wrong and how to fix it. Size checks put their estimate in the message, so a
request that cannot fit in memory, on disk or in the box is refused in well under a second
instead of failing after minutes.

This is the bottom layer (it imports nothing from rodwarp but :mod:`rodwarp._util` and
:mod:`rodwarp.errors`); the checks of each command live next to it in its layer:
:mod:`rodwarp.experiments` (``simulate``, ``sweep``), :mod:`rodwarp.analysis` (``analyze``),
:mod:`rodwarp.ct` (``phantom``, ``segment``).
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass, fields
from pathlib import Path

from rodwarp._util import one_line_error

__all__ = ["BASE_BYTES", "MAX_MU", "Range", "check_ranges", "field_range", "fail", "number", "integer", "device_name", "human_bytes", "available_memory",
           "memory_fits", "existing_ancestor", "disk_fits", "probe_write", "output_location"]

#: fixed memory of a run (Python, Warp, NumPy, matplotlib), bytes
BASE_BYTES = 300e6
#: largest friction coefficient accepted (the command line and the engine alike): real materials
#: stay below about 2 (rubber); above 10 the contact solver's friction cone is a typo's, not a
#: material's
MAX_MU = 10.0


def fail(msg: str):
    """Raise the one-line :class:`~rodwarp.errors.RodwarpError` ``msg`` (what is wrong, how to fix it)."""
    raise one_line_error(msg)


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def number(name: str, v, *, gt=None, ge=None, le=None, lt=None, unit: str = "", hint: str = "") -> float:
    """A finite number within the given bounds, else a one-line error naming ``--name``.

    Parameters
    ----------
    name : str
        Option name as the user typed it (``--alpha``).
    v : float
        The value.
    gt, ge, le, lt : float, optional
        Strict / inclusive lower and upper bounds.
    unit : str
        Unit shown after the bound (``s``, ``Hz``, ``m``).
    hint : str
        Extra advice appended to the message.
    """
    u = f" {unit}" if unit else ""
    rng = []
    if gt is not None:
        rng.append(f"> {_fmt(gt)}{u}")
    if ge is not None:
        rng.append(f">= {_fmt(ge)}{u}")
    if lt is not None:
        rng.append(f"< {_fmt(lt)}{u}")
    if le is not None:
        rng.append(f"<= {_fmt(le)}{u}")
    want = " and ".join(rng) if rng else "finite"
    if gt == 0 and ge is None and le is None and lt is None:
        want = f"positive (> 0{u})"
    try:
        f = float(v)
    except (TypeError, ValueError):
        fail(f"{name} must be a number ({want}), got {v!r}")
    tail = f"; {hint}" if hint else ""
    if not math.isfinite(f):
        fail(f"{name} must be a finite number, {want}, got {_fmt(f)}{tail}")
    if (gt is not None and not f > gt) or (ge is not None and not f >= ge) or (lt is not None and not f < lt) \
            or (le is not None and not f <= le):
        fail(f"{name} must be {want}, got {_fmt(f)}{tail}")
    return f


def integer(name: str, v, *, ge=None, le=None, hint: str = "") -> int:
    """An integer within bounds, else a one-line error naming ``--name``."""
    tail = f"; {hint}" if hint else ""
    if isinstance(v, bool) or not isinstance(v, (int,)) and not (isinstance(v, float) and v.is_integer()):
        fail(f"{name} must be a whole number, got {v!r}")
    i = int(v)
    if ge is not None and i < ge:
        fail(f"{name} must be >= {ge}, got {i}{tail}")
    if le is not None and i > le:
        fail(f"{name} must be <= {le}, got {i}{tail}")
    return i


@dataclass(frozen=True)
class Range:
    """The values an option may take, stated once beside it.

    A parameters dataclass gives a field its range as ``option(default, help,
    range=Range(...))`` (:func:`rodwarp._util.option`); :func:`check_ranges` checks every field
    against it, so the command line and the public constructors refuse the same values with
    the same one-line message, and the option-range test reads the same bounds.

    Parameters
    ----------
    gt, ge, lt, le : float, optional
        Strict / inclusive lower and upper bounds, in ``unit``.
    unit : str
        The option's unit (``m``, ``s``, ``Hz``; empty for a pure number).
    hint : str
        Why the bounds are where they are, appended to the refusal.
    whole : bool
        The value is a whole number (a count, a seed).
    each : bool
        The value is a sequence whose every item must lie in the range (``--box``, ``--strains``).
    choices : tuple
        The only values allowed, where the range is a short list (``--connectivity 6`` or ``26``).
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    unit: str = ""
    hint: str = ""
    whole: bool = False
    each: bool = False
    choices: tuple = ()

    def check(self, name: str, value):
        """``value`` if it lies in the range, else a one-line error naming ``name``."""
        if self.each:
            try:
                items = list(value)
            except TypeError:
                fail(f"{name} must be a list of numbers, got {value!r}")
            return tuple(self._check_one(name, v) for v in items)
        return self._check_one(name, value)

    def _check_one(self, name: str, v):
        if self.choices:
            x = integer(name, v) if self.whole else number(name, v)
            if x not in self.choices:
                fail(f"{name} must be {' or '.join(_fmt(c) for c in self.choices)}, got {_fmt(x)}"
                     + (f"; {self.hint}" if self.hint else ""))
            return x
        if self.whole:
            i = integer(name, v, hint=self.hint)
            number(name, i, gt=self.gt, ge=self.ge, lt=self.lt, le=self.le, unit=self.unit, hint=self.hint)
            return i
        return number(name, v, gt=self.gt, ge=self.ge, lt=self.lt, le=self.le, unit=self.unit, hint=self.hint)

    def contains(self, v) -> bool:
        """Whether the single value ``v`` lies in the range (for tests and help texts)."""
        try:
            self._check_one("value", v)
        except ValueError:
            return False
        return True

    def text(self) -> str:
        """The range as help text, e.g. ``> 0 and <= 100 m``."""
        u = f" {self.unit}" if self.unit else ""
        if self.choices:
            return " or ".join(_fmt(c) for c in self.choices) + u
        parts = [f"{op} {_fmt(b)}" for op, b in ((">", self.gt), (">=", self.ge), ("<", self.lt), ("<=", self.le))
                 if b is not None]
        return (" and ".join(parts) + u) if parts else "any finite value"


def check_ranges(obj, flag=None, skip=()) -> None:
    """Check every field of the dataclass instance ``obj`` that states a :class:`Range`.

    Parameters
    ----------
    obj : dataclass instance
        Parameters whose fields carry ``range`` metadata; a field whose value is None (an
        option left at "decide for me") is not checked.
    flag : callable, optional
        Field name -> the name shown in messages; default the field's ``flag`` metadata, else
        the option ``--field-name``.
    skip : iterable of str
        Fields checked elsewhere (in another form).
    """
    for f in fields(obj):
        rng = f.metadata.get("range")
        value = getattr(obj, f.name)
        if rng is None or value is None or f.name in skip:
            continue
        name = flag(f.name) if flag else f.metadata.get("flag") or "--" + f.name.replace("_", "-")
        rng.check(name, value)


def field_range(cls, name: str) -> Range | None:
    """The :class:`Range` the dataclass ``cls`` states for its field ``name`` (None if none)."""
    return next((f.metadata.get("range") for f in fields(cls) if f.name == name), None)


def device_name(name: str, device: str) -> str:
    """``auto``, ``cpu``, ``cuda`` or ``cuda:N`` (availability is checked when the device is used)."""
    d = str(device).strip().lower()
    if d in ("auto", "cpu", "cuda") or (d.startswith("cuda:") and d[5:].isdigit()):
        return d
    fail(f"unknown device '{device}' for {name}; use auto, cpu, cuda or cuda:N")


def human_bytes(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{n:.0f} B"
        n /= 1000.0
    return f"{n:.3g} PB"  # pragma: no cover


def available_memory() -> float:
    """Memory this process may still use (bytes): MemAvailable, else physical memory."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return float("inf")


def memory_fits(what: str, need: float, fix: str) -> None:
    """Refuse a request whose memory estimate ``need`` (bytes) exceeds what is available."""
    have = available_memory()
    if need > have:
        fail(f"{what} needs about {human_bytes(need)} of memory, {human_bytes(have)} is available; {fix}")


def existing_ancestor(path: Path) -> Path:
    """The path itself or its nearest existing parent."""
    p = Path(os.path.abspath(path))
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def disk_fits(path: Path, need: float, what: str, fix: str) -> None:
    """Refuse when the file system holding ``path`` has less than ``need`` bytes free."""
    base = existing_ancestor(path)
    if base.is_file():
        base = base.parent
    try:
        free = shutil.disk_usage(base).free
    except OSError:
        return
    if need > free:
        fail(f"{what} needs about {human_bytes(need)} on disk, {human_bytes(free)} is free at {base}; {fix}")


def probe_write(directory: Path) -> None:
    """Write and remove a 4 kB hidden file in ``directory`` (raises the OSError a real write gets)."""
    import tempfile

    fd, tmp = tempfile.mkstemp(prefix=".rodwarp-probe.", suffix=".tmp", dir=directory)
    try:
        os.write(fd, b"x" * 4096)
        os.fsync(fd)
    finally:
        os.close(fd)
        os.unlink(tmp)


def output_location(path, name: str = "--out", *, directory: bool = True) -> Path:
    """Check that ``path`` can be created and written, before any work.

    A directory output (``directory``) must not be an existing file and no parent may be a
    file; a file output must not be an existing directory. The nearest existing directory
    is probed with a real write (a temporary file, removed again), which catches read-only
    mounts and a full disk that permission bits do not show (root ignores them).

    Returns
    -------
    Path
        ``path``.
    """
    import errno

    path = Path(path)
    if directory and path.exists() and not path.is_dir():
        fail(f"{name} {path} is a file, not a directory; pass a directory path (it is created if missing)")
    if not directory and path.is_dir():
        fail(f"{name} {path} is a directory; pass a file path")
    p = Path(os.path.abspath(path if directory else path.parent))
    for parent in [p, *p.parents]:
        if parent.exists():
            if not parent.is_dir():
                fail(f"{name} {path}: {parent} is a file, so nothing can be created under it; choose another path")
            break
    probe_dir = existing_ancestor(p)
    try:
        probe_write(probe_dir)
    except OSError as e:
        why = {errno.EROFS: "the file system is read-only", errno.ENOSPC: "the disk is full",
               errno.EACCES: "permission denied", errno.EPERM: "permission denied",
               errno.EDQUOT: "the disk quota is exceeded"}.get(e.errno, e.strerror or str(e))
        fail(f"{name} {path}: cannot write in {probe_dir} ({why}); choose a writable location")
    return path
