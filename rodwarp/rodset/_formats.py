"""Rod-set files: ``.npz`` and ``.zarr`` (everything, see ``docs/rodset-format.md``) and ``.csv``
(``rod,x,y,z[,radius]`` only).

Every write is atomic (:mod:`rodwarp.rodset.files`); every bad input raises
:class:`~rodwarp.errors.RodwarpError` with a one-line message naming the file (and, for a CSV,
the line).  This module must not import warp.
"""

from __future__ import annotations

import csv
import json
import math
import os
import warnings
from pathlib import Path

import numpy as np

from rodwarp._util import json_safe
from rodwarp._util import one_line_error as _fail
from rodwarp.errors import RodwarpError
from rodwarp.rodset._units import MAX_COORDINATE, _positive, check_units
from rodwarp.rodset.files import atomic_path

__all__ = ["save", "save_csv", "read", "FORMAT_NAME", "FORMAT_VERSION", "SUPPORTED_SUFFIXES"]

FORMAT_NAME = "rodwarp.rodset"
FORMAT_VERSION = 1
SUPPORTED_SUFFIXES = (".npz", ".zarr", ".csv")

_CONTACT_KEYS = ("contact_rod_i", "contact_rod_j", "contact_point", "contact_gap")
_OPTIONAL_KEYS = ("rest_points", "velocities", "box")


# ----------------------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------------------

def _meta(rods) -> dict:
    return json_safe({"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "units": rods.units,
                      "n_rods": rods.n_rods, "n_vertices": rods.n_vertices, "attrs": rods.attrs}, finite=False)


def _arrays(rods) -> dict[str, np.ndarray]:
    arrays = {"points": rods.points, "offsets": rods.offsets, "radii": rods.radii}
    for name in _OPTIONAL_KEYS:
        if getattr(rods, name) is not None:
            arrays[name] = getattr(rods, name)
    if rods.contacts is not None:
        c = rods.contacts
        arrays.update(contact_rod_i=c.rod_i, contact_rod_j=c.rod_j, contact_point=c.point, contact_gap=c.gap)
    return arrays


def save(rods, path: str | os.PathLike) -> Path:
    """Validate ``rods`` and write them atomically in the format of the suffix (see
    :meth:`RodSet.save`); returns the path."""
    rods.validate()
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:  # a file object stops NumPy from appending ".npz"
                np.savez_compressed(fh, meta=np.array(json.dumps(_meta(rods))), **_arrays(rods))
    elif suffix == ".zarr":
        import zarr

        with atomic_path(path, directory=True) as tmp:
            g = zarr.open_group(str(tmp), mode="w")
            for name, arr in _arrays(rods).items():
                if hasattr(g, "create_array"):
                    g.create_array(name, data=arr)
                else:  # zarr 2
                    g.array(name, arr)
            g.attrs.update(_meta(rods))
    elif suffix == ".csv":
        return save_csv(rods, path)
    else:
        raise _fail(f"unsupported file type {path.suffix or '(none)'!r} for {path}; "
                    f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
    return path


def save_csv(rods, path: str | os.PathLike) -> Path:
    """Write ``rod,x,y,z,radius`` (one row per vertex) atomically, in ``rods.units`` (which the
    CSV does not record); returns the path. Values are the shortest decimals that read back to
    the same floats (Python's repr): exact, and readable (0.1, not 0.10000000000000001). The
    one writer of the format: ``RodSet.to_csv`` and segmentation's ``rods.csv`` use it."""
    rods.validate()
    path = Path(path)
    rid = rods.rod_index
    radius = np.repeat(rods.radii, rods.vertex_counts)
    lines = ["rod,x,y,z,radius\n"]
    for k, (x, y, z) in enumerate(rods.points.tolist()):
        lines.append(f"{int(rid[k])},{x!r},{y!r},{z!r},{float(radius[k])!r}\n")
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write("".join(lines))
    return path


# ----------------------------------------------------------------------------------------------
# loading
# ----------------------------------------------------------------------------------------------

def read(path: str | os.PathLike, cls, *, radius: float | None = None, diameter: float | None = None,
         units: str | None = None):
    """Read a rod set as a ``cls`` (:class:`~rodwarp.rodset.RodSet`); the parameters,
    returns and errors are :func:`rodwarp.rodset.load`'s."""
    path = Path(path)
    if not path.exists():
        raise _fail(f"no such file: {path}; check the path")
    if radius is not None and diameter is not None:
        raise _fail("pass either radius or diameter, not both")
    if units is not None:
        check_units(units)
    suffix = path.suffix.lower()
    is_zarr_dir = path.is_dir() and (suffix == ".zarr" or (path / "zarr.json").exists()
                                     or (path / ".zgroup").exists())
    if is_zarr_dir:
        rods = _load_zarr(path, cls)
    elif path.is_dir():
        raise _fail(f"{path} is a directory but not a zarr group; pass a {', '.join(SUPPORTED_SUFFIXES)} path")
    elif suffix == ".zarr":  # a zarr store is a folder; a plain file with the name is something else
        raise _fail(f"{path} is a plain file, not a zarr store (a .zarr rod set is a folder); pass the rod set's "
                    f".zarr folder, or an .npz or .csv file")
    elif suffix == ".npz":
        rods = _load_npz(path, cls)
    elif suffix == ".csv":
        if diameter is not None:
            radius = _length(diameter, "diameter") / 2.0
        elif radius is not None:
            radius = _length(radius, "radius")
        return _load_csv(path, radius, units or "m", cls)
    else:
        raise _fail(f"unsupported file type {path.suffix or '(none)'!r} for {path}; "
                    f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
    if units is not None and units != rods.units:
        try:
            rods = rods.to_units(units)
        except RodwarpError as e:
            raise _fail(f"{path}: {e}") from None
    return rods


def _length(v, name: str) -> float:
    """A rod size given to :func:`load`: positive and at most :data:`MAX_COORDINATE`."""
    f = _positive(v, name, f"a positive number (at most {MAX_COORDINATE:g}) in the file's units")
    if f > MAX_COORDINATE:
        raise _fail(f"{name} must be a positive number (at most {MAX_COORDINATE:g}) in the file's units, got {v!r}")
    return f


def _parse_meta(meta, path: Path) -> dict:
    if isinstance(meta, str):
        try:
            meta = json.loads(meta)
        except json.JSONDecodeError as e:
            raise _fail(f"{path}: 'meta' is not valid JSON ({e}); the file is damaged or not a rodwarp rod set") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise _fail(f"{path} is not a rodwarp rod set (no format {FORMAT_NAME!r} in its metadata); "
                    f"build one with RodSet.from_polylines(...) and save it")
    version = meta.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION or version < 1:
        raise _fail(f"{path} has rod-set format_version {version!r}; this rodwarp reads version "
                    f"{FORMAT_VERSION} or older, so upgrade rodwarp")
    return meta


def _assemble(arrays: dict, meta: dict, path: Path, cls):
    for key in ("points", "offsets", "radii"):
        if key not in arrays:
            raise _fail(f"{path} lacks the {key!r} array; the file is damaged or incomplete")
    present = [k for k in _CONTACT_KEYS if k in arrays]
    if present and len(present) != len(_CONTACT_KEYS):
        missing = [k for k in _CONTACT_KEYS if k not in arrays]
        raise _fail(f"{path} has {', '.join(present)} but lacks {', '.join(missing)}; the file is damaged")
    contacts = None
    try:
        if present:
            contacts = cls.contacts_type(*(arrays[k] for k in _CONTACT_KEYS))
        attrs = meta.get("attrs") or {}
        return cls(arrays["points"], arrays["offsets"], arrays["radii"], units=meta.get("units", "m"),
                      rest_points=arrays.get("rest_points"), velocities=arrays.get("velocities"),
                      contacts=contacts, box=arrays.get("box"), attrs=attrs)
    except RodwarpError as e:
        raise _fail(f"{path}: {e}") from None


def _load_npz(path: Path, cls):
    import zipfile

    # an npz is a zip archive; anything else would reach np.load's .npy/pickle fallbacks, whose
    # messages advise unpickling, which is never safe for a file of unknown origin
    if not zipfile.is_zipfile(path):
        raise _fail(f"{path} is not a rod-set .npz (not a readable zip/npz archive); the file is damaged or "
                    f"of another kind")
    try:
        with np.load(path, allow_pickle=False) as z:
            if "meta" not in z.files:
                raise _fail(f"{path} has no 'meta' entry, so it was not written by rodwarp; "
                            f"build a RodSet from its arrays and save it")
            meta = _parse_meta(str(z["meta"][()]), path)
            arrays = {k: z[k] for k in z.files if k != "meta"}
    except RodwarpError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        if "pickle" in str(e).lower():  # object arrays: rodwarp never writes them, and never unpickles
            raise _fail(f"{path} is not a rod-set .npz (it holds Python object arrays, which rodwarp does not "
                        f"write or load)") from None
        raise _fail(f"cannot read {path} as npz ({type(e).__name__}: {e}); the file is damaged or not npz") from None
    return _assemble(arrays, meta, path, cls)


def _load_zarr(path: Path, cls):
    import zarr

    try:
        g = zarr.open_group(str(path), mode="r")
        meta_raw = dict(g.attrs)
        names = list(g.array_keys())
        arrays = {k: np.asarray(g[k][...]) for k in names}
    except Exception as e:  # zarr raises many types for unreadable stores
        raise _fail(f"cannot read {path} as a zarr group ({type(e).__name__}: {e})") from None
    if "format" not in meta_raw:
        raise _fail(f"{path} has no rodwarp metadata in its group attributes, so it was not written by rodwarp; "
                    f"build a RodSet from its arrays and save it")
    meta = _parse_meta(meta_raw, path)
    return _assemble(arrays, meta, path, cls)


# -- CSV -------------------------------------------------------------------------------------

class _NeedSlowPath(Exception):
    """The fast CSV reader saw a problem; re-read line by line to report it precisely."""


def _load_csv(path: Path, radius: float | None, units: str, cls):
    name = str(path)
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    # text CSVs hold no NUL bytes; binary data (or UTF-16 text) would otherwise be reported
    # as odd characters or a bad header
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise _fail(f"{name} is UTF-16 text; save the CSV as UTF-8")
    if b"\0" in head:
        raise _fail(f"{name} is not a text CSV (it holds binary data); expected a UTF-8 text file with the header "
                    f"rod,x,y,z[,radius]")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            header = next(csv.reader(fh), None)
    except UnicodeDecodeError as e:
        raise _fail(f"{name}: not UTF-8 text ({e}); save the CSV as UTF-8") from None
    if header is None:
        raise _fail(f"{name} is empty; expected a header line rod,x,y,z[,radius]")
    cols = [h.strip().lower() for h in header]
    missing = [c for c in ("rod", "x", "y", "z") if c not in cols]
    if missing:
        raise _fail(f"{name} line 1: header lacks column(s) {', '.join(missing)}; "
                    f"the header must contain rod,x,y,z (optionally radius), got {','.join(header)!r}")
    want = ["rod", "x", "y", "z"] + (["radius"] if "radius" in cols else [])
    for c in want:
        if cols.count(c) > 1:
            raise _fail(f"{name} line 1: column {c!r} appears {cols.count(c)} times; keep one")
    if "radius" not in cols and radius is None:
        raise _fail(f"{name}: CSV has no radius column, so the rods' thickness is unknown; add a radius column "
                    f"(rod,x,y,z,radius) or pass --diameter (radius=/diameter= in Python)")
    usecols = [cols.index(c) for c in want]

    try:
        data = _csv_fast(path, usecols)
        return _csv_build(data, None, want, radius, units, name, cls)
    except _NeedSlowPath:
        pass
    data, lines = _csv_slow(path, usecols, want, name)
    try:
        return _csv_build(data, lines, want, radius, units, name, cls)
    except _NeedSlowPath:  # pragma: no cover - slow path always has line numbers
        raise _fail(f"{name}: malformed CSV; check it has one numeric row per vertex") from None


def _csv_fast(path: Path, usecols: list[int]) -> np.ndarray:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=usecols, ndmin=2, comments=None,
                              quotechar='"', dtype=np.float64, encoding="utf-8-sig")
    except (ValueError, IndexError, UnicodeDecodeError):
        raise _NeedSlowPath from None
    if data.size and not np.all(np.isfinite(data)):
        raise _NeedSlowPath
    return data.reshape(-1, len(usecols))


def _csv_slow(path: Path, usecols: list[int], names: list[str], fname: str) -> tuple[np.ndarray, np.ndarray]:
    rows, lines = [], []
    with open(path, newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(fh)
        next(reader, None)
        for row in reader:
            line = reader.line_num
            if not row or all(not f.strip() for f in row):
                continue
            vals = []
            for c, n in zip(usecols, names):
                if c >= len(row):
                    raise _fail(f"{fname} line {line}: has {len(row)} fields but column {n!r} is field {c + 1}; "
                                f"fill in the missing values")
                s = row[c].strip()
                try:
                    v = float(s)
                except ValueError:
                    raise _fail(f"{fname} line {line} column {n!r}: {s!r} is not a number") from None
                if not math.isfinite(v):
                    raise _fail(f"{fname} line {line} column {n!r}: value {s!r} is not finite; remove or fix the row")
                vals.append(v)
            rows.append(vals)
            lines.append(line)
    data = np.array(rows, dtype=np.float64).reshape(-1, len(usecols))
    return data, np.array(lines, dtype=np.int64)


def _csv_build(data: np.ndarray, lines: np.ndarray | None, names: list[str], radius: float | None, units: str,
               fname: str, cls):
    """Group CSV rows into rods. With ``lines`` None any problem raises _NeedSlowPath."""

    def fail(row: int, msg: str) -> RodwarpError:
        if lines is None:
            raise _NeedSlowPath
        return _fail(f"{fname} line {lines[row]}: {msg}")

    if data.shape[0] == 0:
        raise _fail(f"{fname}: rod set is empty (header but no rows); add one row per vertex")
    ids_f = data[:, 0]
    bad = np.flatnonzero((ids_f != np.round(ids_f)) | (np.abs(ids_f) > 2.0 ** 53))
    if bad.size:
        raise fail(int(bad[0]), f"rod id {float(ids_f[bad[0]])!r} is not an integer")
    ids = ids_f.astype(np.int64)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    block_ids = ids[starts]
    uniq, first = np.unique(block_ids, return_index=True)
    if uniq.size != block_ids.size:
        seen = np.zeros(block_ids.size, dtype=bool)
        seen[first] = True
        k = int(np.flatnonzero(~seen)[0])
        rid = int(block_ids[k])
        prev = int(starts[np.flatnonzero(block_ids[:k] == rid)[-1]])
        raise fail(int(starts[k]), f"rows of rod {rid} are not contiguous (rod {rid} also appears from line "
                                   f"{lines[prev] if lines is not None else '?'}); sort rows by rod, keeping "
                                   f"vertex order within each rod")
    offsets = np.r_[starts, ids.shape[0]].astype(np.int64)
    counts = np.diff(offsets)
    if np.any(counts < 2):
        k = int(np.flatnonzero(counts < 2)[0])
        raise fail(int(starts[k]), f"rod {int(block_ids[k])} has only 1 vertex; each rod needs 2 or more rows")
    if "radius" in names:
        rad = data[:, 4]
        r_rod = rad[starts]
        diff = np.flatnonzero(rad != np.repeat(r_rod, counts))
        if diff.size:
            row = int(diff[0])
            k = int(np.searchsorted(starts, row, side="right") - 1)
            raise fail(row, f"radius {float(rad[row])!r} differs from {float(r_rod[k])!r} on the first row of rod "
                            f"{int(block_ids[k])}; radius must be constant per rod")
        nonpos = np.flatnonzero(r_rod <= 0)
        if nonpos.size:
            k = int(nonpos[0])
            raise fail(int(starts[k]), f"radius of rod {int(block_ids[k])} is {float(r_rod[k])!r}; radii must be positive")
    else:
        r_rod = np.full(block_ids.size, float(radius))
    attrs = {}
    if not np.array_equal(block_ids, np.arange(block_ids.size)):
        attrs["source_rod_ids"] = block_ids.tolist()
    try:
        return cls(np.ascontiguousarray(data[:, 1:4]), offsets, r_rod, units=units, attrs=attrs)
    except RodwarpError as e:
        raise _fail(f"{fname}: {e}") from None
