"""Crash-safe file writes: write to a temporary sibling, then rename over the target.

A crash at any moment leaves either the old file or the new one, never a torn file.  Every
output of rodwarp goes through :func:`atomic_path` (or the helpers built on it: JSON, text,
PNG figures); :func:`consolidate_zarr` finishes a zarr group for ``xarray.open_zarr``.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator

from rodwarp._util import json_safe

__all__ = ["atomic_path", "write_json", "write_text", "save_figure", "consolidate_zarr", "read_csv_rows"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    Parameters
    ----------
    path : path-like
        Final destination (file, or directory when ``directory`` is true).
    directory : bool
        The caller writes a directory tree (for example a zarr group) instead of a file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    if directory:
        tmp.unlink()
    try:
        yield tmp
        # mkstemp creates 0600; give the result the permissions a plain open() would
        mask = os.umask(0)
        os.umask(mask)
        if tmp.exists():
            os.chmod(tmp, (0o777 if tmp.is_dir() else 0o666) & ~mask)
        if directory:
            if path.exists():
                old = path.with_name(f".{path.name}.old")
                if old.exists():
                    shutil.rmtree(old)
                os.replace(path, old)
                os.replace(tmp, path)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, path)
        else:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, path)
    except BaseException as e:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        elif tmp.exists():
            tmp.unlink()
        if isinstance(e, OSError) and not isinstance(e, FileNotFoundError):
            # a failed write (disk full, read-only) names the file it was writing, not nothing
            raise OSError(e.errno, e.strerror or str(e), str(path)) from e
        raise


def write_json(path: str | os.PathLike, data: Any, *, finite: bool = False) -> None:
    """Write ``data`` as indented JSON atomically.

    Parameters
    ----------
    path : path-like
        Destination.
    data : any
        Nested dicts and lists of numbers, strings, NumPy values and paths
        (:func:`rodwarp._util.json_safe`; an object of another kind raises TypeError).
    finite : bool
        Write NaN and infinities as null (strict JSON), as summaries do; by default they are
        written as ``NaN``, which Python's json module reads back.
    """
    text = json.dumps(json_safe(data, finite=finite, strict=True), indent=2, sort_keys=False)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n")


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write text atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def save_figure(fig, path: str | os.PathLike, dpi: int = 110) -> Path:
    """Render a matplotlib figure to PNG atomically and return the path.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        Drawn on its own canvas (no pyplot state is touched, so an interactive session's
        backend is left alone).
    path : path-like
        PNG to write; its folder is created.
    dpi : int
        Resolution (dots per inch).
    """
    path = Path(path)
    with atomic_path(path) as tmp:
        # the temporary name has no .png suffix, so the format must be explicit
        fig.savefig(tmp, format="png", dpi=dpi)
    return path


def consolidate_zarr(path: str | os.PathLike) -> None:
    """Write zarr's consolidated metadata of the group at ``path``, so ``xarray.open_zarr``
    reads every array's metadata in one go (and does not warn that it had to look for it)."""
    import warnings

    import zarr

    with warnings.catch_warnings():
        # zarr 3 notes that consolidated metadata is not in the v3 spec yet; xarray reads it
        warnings.simplefilter("ignore")
        zarr.consolidate_metadata(str(path))


def read_csv_rows(path: str | os.PathLike, fix: str) -> tuple[list[str], list[dict]]:
    """The header and rows (dicts of strings) of a UTF-8 CSV that rodwarp wrote, or one line why not.

    Parameters
    ----------
    path : path-like
        The CSV (a spreadsheet's byte-order mark is tolerated).
    fix : str
        What the user should do, appended to every refusal.

    Returns
    -------
    (header, rows)
        The header's names, and one dict per data row as :class:`csv.DictReader` gives it.

    Raises
    ------
    RodwarpError
        ``path`` is a folder, is not UTF-8 text (a binary or other-encoding file, whose
        UnicodeDecodeError would otherwise be an internal error), holds NUL bytes, or is not CSV.
    """
    import csv
    import io

    from rodwarp.errors import RodwarpError

    path = Path(path)
    if path.is_dir():
        raise RodwarpError(f"{path} is a folder, not a CSV; {fix}")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            text = fh.read()
        if "\0" in text:  # valid UTF-8, yet binary: Python's csv reads NUL bytes into the values
            raise RodwarpError(f"{path} is not a text CSV (it holds NUL bytes); {fix}")
        reader = csv.DictReader(io.StringIO(text, newline=""))
        rows = list(reader)
        return list(reader.fieldnames or []), rows
    except UnicodeDecodeError as e:
        raise RodwarpError(f"{path} is not a text CSV (not UTF-8: it holds byte 0x{e.object[e.start]:02x}); "
                           f"{fix}") from None
    except csv.Error as e:
        raise RodwarpError(f"{path} is not a readable CSV ({e}); {fix}") from None
