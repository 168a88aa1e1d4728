"""Reading and writing CT volumes: multi-page TIFF, folders of slice TIFFs, zarr arrays.

Volumes are NumPy-style arrays indexed ``(z, y, x)`` = (slice, row, column). Every problem with
the input raises :class:`~rodwarp.errors.RodwarpError` with a one-line message that says what is
wrong and how to fix it. Writes are atomic.

This module does not import warp.
"""

from __future__ import annotations

import contextlib
import logging
import re
from pathlib import Path

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.errors import RodwarpError

__all__ = ["read_volume", "open_volume_lazy", "write_tiff", "list_slices", "check_volume", "read_voxel_size",
           "read_voxel_unit", "read_voxel_ratio"]

_TIFF_SUFFIXES = (".tif", ".tiff")


def _natural_key(name: str):
    """Sort key that orders the numbers in a name numerically: slice2 < slice10."""
    return [(0, int(t), "") if t.isdigit() else (1, 0, t.lower()) for t in re.split(r"(\d+)", name) if t != ""]


def list_slices(folder) -> list[Path]:
    """The slice TIFFs of a folder, sorted naturally by the numbers in their names."""
    folder = Path(folder)
    files = [p for p in folder.iterdir()
             if p.is_file() and p.suffix.lower() in _TIFF_SUFFIXES and not p.name.startswith(".")]
    files.sort(key=lambda p: _natural_key(p.name))
    return files


def _is_zarr(path: Path) -> bool:
    if path.suffix.lower() == ".zarr":
        return True
    return path.is_dir() and any((path / m).exists() for m in ("zarr.json", ".zarray", ".zgroup"))


# ----------------------------------------------------------------------------------------------
# checks
# ----------------------------------------------------------------------------------------------

def _check_shape(shape, name: str) -> None:
    if len(shape) == 2:
        raise _fail(f"{name} is 2-D (shape {tuple(shape)}); a CT stack needs several slices: give a multi-page "
                    f"TIFF, a folder of slice TIFFs or a 3-D zarr array")
    if len(shape) != 3:
        raise _fail(f"{name} has {len(shape)} dimensions (shape {tuple(shape)}); a CT volume must be 3-D "
                    f"(slices, rows, columns); convert it to a single-channel stack")
    if 0 not in shape and shape[0] == 1:
        raise _fail(f"{name} has a single slice (shape {tuple(shape)}); a CT stack needs several slices")
    if 0 in shape:
        raise _fail(f"{name} is empty (shape {tuple(shape)}); it holds no voxels, give a non-empty volume")


def check_volume(vol: np.ndarray, name: str = "volume") -> np.ndarray:
    """Check a loaded volume (3-D, non-empty, numeric, no NaN, not constant) and return it."""
    _check_shape(vol.shape, name)
    if vol.dtype.kind not in "biuf":
        raise _fail(f"{name} has dtype {vol.dtype}; a CT volume must hold grey values (integers or floats)")
    if vol.dtype.kind == "f":
        bad = ~np.isfinite(vol)
        if bad.any():
            z, y, x = np.argwhere(bad)[0]
            raise _fail(f"{name} contains NaN or inf values (first at z={z}, y={y}, x={x}); replace them, "
                        f"e.g. with the background grey value")
    lo, hi = vol.min(), vol.max()
    if lo == hi:
        raise _fail(f"{name}: constant volume: no contrast to segment (every voxel is {lo.item()!r}); "
                    f"check the file is the reconstructed stack")
    return vol


# ----------------------------------------------------------------------------------------------
# reading
# ----------------------------------------------------------------------------------------------

@contextlib.contextmanager
def _tifffile_quiet():
    """Collect tifffile's log records instead of printing them while a TIFF is read.

    tifffile logs problems of damaged files (``invalid page offset``) through ``logging``;
    with no handler configured Python prints them on stderr, before and besides rodwarp's own
    one-line error. Yields the list of records, so that callers can tell a truncated file.
    """
    log = logging.getLogger("tifffile")
    records: list[logging.LogRecord] = []

    class _Collect(logging.Handler):
        def emit(self, record):
            records.append(record)

    handler = _Collect(logging.DEBUG)
    propagate = log.propagate
    log.addHandler(handler)
    log.propagate = False  # nor through the root logger's handlers
    try:
        yield records
    finally:
        log.removeHandler(handler)
        log.propagate = propagate


#: photometric interpretations of colour images (TIFF tag 262): RGB, palette, CMYK, YCbCr, CIELab
_COLOUR_PHOTOMETRIC = {2: "an RGB", 3: "a colour-palette", 5: "a CMYK", 6: "a YCbCr", 8: "a CIELab"}


def _check_greyscale(tf, path: Path, what: str = "a greyscale CT stack") -> None:
    """Refuse a TIFF whose pages are colour or multi-channel: their channels would be read as
    slices or columns of the volume (a 64 x 64 RGB image is a 64 x 64 x 3 'volume')."""
    page = tf.pages.first if hasattr(tf.pages, "first") else tf.pages[0]
    photo = int(getattr(page, "photometric", 1) or 1)
    spp = int(getattr(page, "samplesperpixel", 1) or 1)
    if (photo == 2 and spp in (3, 4) and int(getattr(page, "planarconfig", 1)) == 2 and tf.is_shaped
            and int(getattr(page, "bitspersample", 8)) > 8):
        # tifffile's own default for a (3 or 4, Y, X) array of 16-bit or float grey values
        # (deprecated there): planar "RGB" that is a stack of 3 or 4 greyscale slices
        return
    if photo in _COLOUR_PHOTOMETRIC or spp > 1:
        kind = _COLOUR_PHOTOMETRIC.get(photo, "a multi-channel")
        raise _fail(f"{path} is {kind} image ({spp} samples per pixel), not {what}; convert it to "
                    f"greyscale (one channel per pixel) first")


def _check_complete(tf, path: Path, records) -> None:
    """Refuse a truncated or damaged TIFF: a page (or its data) beyond the end of the file.

    tifffile skips pages whose offset lies past the end (logging it) and would return a
    shorter stack; the data of the last pages may be cut off too."""
    size = tf.filehandle.size
    cut = any("offset" in r.getMessage() or "truncat" in r.getMessage() for r in records)
    if not cut:
        for page in tf.pages:
            offs, counts = getattr(page, "dataoffsets", ()), getattr(page, "databytecounts", ())
            if any(o + c > size for o, c in zip(offs, counts)):
                cut = True
                break
    if cut:
        raise _fail(f"{path} is truncated or corrupt (its pages point past the end of the {size}-byte file); "
                    f"copy or export the TIFF again")


def _tiff_problem(path: Path, e: Exception) -> RodwarpError:
    """The one-line error for a TIFF tifffile could not read: not a TIFF at all, or damaged."""
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except OSError:
        magic = b""
    if magic[:2] in (b"II", b"MM"):  # a TIFF header: the rest of the file is cut off or damaged
        return _fail(f"{path} is truncated or corrupt ({type(e).__name__}: {e}); copy or export the TIFF again")
    return _fail(f"cannot read {path} as a TIFF (not a TIFF file); check the file is a complete TIFF stack")


def _inspect_tiff(path: Path) -> None:
    """Refuse a colour, truncated or unreadable TIFF before its pixels are read."""
    import tifffile

    with _tifffile_quiet() as records:
        try:
            with tifffile.TiffFile(path) as tf:
                _check_greyscale(tf, path)
                _check_complete(tf, path, records)
        except RodwarpError:
            raise
        except Exception as e:  # tifffile raises many types on damaged files
            raise _tiff_problem(path, e) from None


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    _inspect_tiff(path)
    try:
        with _tifffile_quiet(), tifffile.TiffFile(path) as tf:
            series = tf.series[0] if tf.series else None
            if series is not None and series.ndim >= 3 and len(tf.series) == 1:
                arr = series.asarray()
            else:
                arr = tf.asarray()
    except (tifffile.TiffFileError, ValueError, OSError, IndexError, KeyError, TypeError) as e:
        raise _tiff_problem(path, e) from None
    arr = np.asarray(arr)
    # squeeze singleton axes beyond ZYX (e.g. ImageJ TZCYX with T = C = 1)
    if arr.ndim > 3 and 0 not in arr.shape:
        arr = arr.reshape([s for s in arr.shape if s != 1])
    return arr


def _read_slice(path: Path) -> np.ndarray:
    import tifffile

    try:
        with _tifffile_quiet(), tifffile.TiffFile(path) as tf:
            _check_greyscale(tf, path, "a greyscale CT slice")
            return np.asarray(tf.asarray())
    except RodwarpError:
        raise
    except Exception as e:  # tifffile raises many types on corrupt files
        raise _fail(f"cannot read slice {path} ({type(e).__name__}: {e}); remove or replace the file") from None


def _folder_files(path: Path) -> list[Path]:
    files = list_slices(path)
    if not files:
        raise _fail(f"folder {path} holds no slice TIFFs (*.tif, *.tiff); point at the folder of slices, "
                    f"a multi-page TIFF or a zarr array")
    return files


def _read_folder(path: Path) -> np.ndarray:
    files = _folder_files(path)
    first = _read_slice(files[0])
    if first.ndim != 2:
        raise _fail(f"slice {files[0].name} in {path} has shape {first.shape}; each slice TIFF must be one 2-D "
                    f"image (rows, columns)")
    vol = np.empty((len(files),) + first.shape, dtype=first.dtype)
    vol[0] = first
    for k, f in enumerate(files[1:], start=1):
        s = _read_slice(f)
        if s.shape != first.shape:
            raise _fail(f"slice {f.name} in {path} has shape {s.shape} but {files[0].name} has {first.shape}; "
                        f"all slices must have the same size: remove or fix {f.name}")
        if s.dtype != vol.dtype:
            vol = vol.astype(np.result_type(vol.dtype, s.dtype))
        vol[k] = s
    return vol


def _open_zarr(path: Path, key: str | None):
    import zarr

    try:
        node = zarr.open(str(path), mode="r")
    except Exception as e:
        raise _fail(f"cannot open {path} as zarr ({type(e).__name__}: {e}); check it is a zarr array or group") from None
    if hasattr(node, "shape") and hasattr(node, "dtype") and not hasattr(node, "array_keys"):
        if key is not None:
            raise _fail(f"{path} is a zarr array, not a group; drop the key {key!r}")
        return node, str(path)
    # a group
    if key is not None:
        try:
            arr = node[key]
        except KeyError:
            names = sorted(node.array_keys())
            raise _fail(f"zarr group {path} has no array {key!r}; choose one of: {', '.join(names) or '(none)'}") from None
        if not hasattr(arr, "shape") or hasattr(arr, "array_keys"):
            raise _fail(f"{path}/{key} is a zarr group, not an array; give the key of a 3-D array")
        return arr, f"{path}/{key}"
    names = sorted(node.array_keys())
    three = [n for n in names if len(node[n].shape) == 3]
    if len(three) == 1:
        return node[three[0]], f"{path}/{three[0]}"
    if not three:
        raise _fail(f"zarr group {path} holds no 3-D array (arrays: {', '.join(names) or 'none'}); "
                    f"give a group with one 3-D volume")
    raise _fail(f"zarr group {path} holds several 3-D arrays ({', '.join(three)}); choose one with key=")


def _resolve(path) -> Path:
    if path is None:
        raise _fail("no input path given; pass a TIFF stack, a folder of slice TIFFs or a zarr array")
    p = Path(path)
    if not p.exists():
        raise _fail(f"{p} does not exist; check the path to the CT stack")
    return p


def read_volume(path, *, key: str | None = None) -> np.ndarray:
    """Read a CT volume into memory as a ``(z, y, x)`` array in its original dtype.

    Parameters
    ----------
    path : path-like
        A multi-page TIFF, a folder of slice TIFFs (sorted naturally by the numbers in their
        names) or a zarr array / group holding one 3-D array.
    key : str, optional
        Array name inside a zarr group.

    Raises
    ------
    RodwarpError
        Missing or unreadable path, a 2-D image, not 3-D, an empty or constant volume, NaN
        values, slices of different shapes.
    """
    p = _resolve(path)
    if _is_zarr(p):
        arr, name = _open_zarr(p, key)
        _check_shape(arr.shape, name)
        try:
            vol = np.asarray(arr[...])
        except Exception as e:
            raise _fail(f"cannot read zarr array {name} ({type(e).__name__}: {e}); check the store is complete") from None
        return check_volume(vol, name)
    if key is not None:
        raise _fail(f"key={key!r} applies only to zarr groups; {p} is not a zarr store")
    if p.is_dir():
        return check_volume(_read_folder(p), str(p))
    if p.suffix.lower() not in _TIFF_SUFFIXES:
        # try TIFF anyway: some stacks have odd suffixes
        try:
            vol = _read_tiff(p)
        except RodwarpError:
            raise _fail(f"{p} is not a TIFF stack, a folder of slices or a zarr store; convert it to one of those") from None
    else:
        vol = _read_tiff(p)
    return check_volume(vol, str(p))


class _SliceStack:
    """Lazy, read-only array over a folder of slice TIFFs: slicing reads only the slices needed."""

    def __init__(self, files: list[Path], shape2d: tuple[int, int], dtype):
        self.files = files
        self.shape = (len(files),) + tuple(shape2d)
        self.dtype = np.dtype(dtype)
        self.ndim = 3

    def __len__(self) -> int:
        return self.shape[0]

    def __array__(self, dtype=None, copy=None):
        a = self[...]
        return a.astype(dtype) if dtype is not None else a

    def __getitem__(self, idx):
        if not isinstance(idx, tuple):
            idx = (idx,)
        if any(i is Ellipsis for i in idx):
            k = idx.index(Ellipsis)
            idx = idx[:k] + (slice(None),) * (3 - len(idx) + 1) + idx[k + 1:]
        idx = idx + (slice(None),) * (3 - len(idx))
        zi = idx[0]
        zs = np.arange(self.shape[0])[zi]
        scalar = np.ndim(zs) == 0
        zs = np.atleast_1d(zs)
        out = None
        for k, z in enumerate(zs):
            s = _read_slice(self.files[int(z)])
            if s.shape != self.shape[1:]:
                raise _fail(f"slice {self.files[int(z)].name} has shape {s.shape} but the stack has "
                            f"{self.shape[1:]}; all slices must have the same size: remove or fix it")
            s = s[idx[1], idx[2]]
            if out is None:
                out = np.empty((len(zs),) + np.shape(s), dtype=self.dtype)
            out[k] = s
        if out is None:
            out = np.empty((0,) + np.empty(self.shape[1:])[idx[1], idx[2]].shape, dtype=self.dtype)
        return out[0] if scalar else out


def open_volume_lazy(path, *, key: str | None = None):
    """Open a CT volume without loading it where possible.

    Returns an array-like with ``.shape``, ``.dtype`` and NumPy slicing (``vol[z0:z1]`` returns a
    NumPy array): a zarr array, a memory map of an uncompressed TIFF, a lazy stack over a folder
    of slices, or, failing those, the loaded array. Shape is checked (3-D, non-empty); contrast
    and NaN are not (that needs the data; :func:`check_volume` checks a loaded chunk).
    """
    p = _resolve(path)
    if _is_zarr(p):
        arr, name = _open_zarr(p, key)
        _check_shape(arr.shape, name)
        return arr
    if key is not None:
        raise _fail(f"key={key!r} applies only to zarr groups; {p} is not a zarr store")
    if p.is_dir():
        files = _folder_files(p)
        first = _read_slice(files[0])
        if first.ndim != 2:
            raise _fail(f"slice {files[0].name} in {p} has shape {first.shape}; each slice TIFF must be one 2-D image")
        return _SliceStack(files, first.shape, first.dtype)
    import tifffile

    _inspect_tiff(p)  # colour, truncated or not a TIFF: refused before a memory map hides it
    try:
        with _tifffile_quiet():
            mm = tifffile.memmap(p, mode="r")
    except Exception:
        mm = None
    if mm is not None:
        if mm.ndim > 3:
            mm = mm.reshape([s for s in mm.shape if s != 1])
        _check_shape(mm.shape, str(p))
        return mm
    vol = _read_tiff(p)
    _check_shape(vol.shape, str(p))
    return vol


# ----------------------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------------------

def write_tiff(path, volume, *, voxel_size=None, unit: str = "um") -> Path:
    """Write a ``(z, y, x)`` volume as a multi-page TIFF atomically, with ImageJ metadata (axes ZYX).

    Parameters
    ----------
    path : path-like
        Destination ``.tif`` / ``.tiff``; an existing file is replaced.
    volume : array-like, 3-D
        uint8, uint16 or float32 data get ImageJ hyperstack metadata (axes ZYX); other dtypes, and
        volumes of 4 GiB or more (written as BigTIFF), get a plain ``{"axes": "ZYX"}`` description.
    voxel_size : float or (dz, dy, dx), optional
        Metres per voxel (one edge, or one per axis), stored as the ImageJ resolution (x, y)
        and spacing (z) in ``unit``.
    unit : str
        Length unit the metadata is written in: ``m``, ``mm`` or ``um`` (the ImageJ ``unit``;
        readers, :func:`read_voxel_size` included, convert it back to metres, and
        :func:`read_voxel_unit` returns it so that lengths can be reported in it); or ``voxel``
        for a volume with no physical scale (a phantom of a scene in voxel units):
        ``voxel_size`` is then in voxel widths (``(2, 1, 1)`` for slices twice as thick), written
        as ImageJ unit ``pixel``, which :func:`read_voxel_size` does not take for a length and
        :func:`read_voxel_ratio` reads.
    """
    import tifffile

    from rodwarp.rodset.files import atomic_path

    vol = np.asarray(volume)
    if vol.ndim != 3:
        raise _fail(f"write_tiff needs a 3-D (Z, Y, X) volume, got shape {vol.shape}")
    path = Path(path)
    # ImageJ hyperstacks are classic TIFF (< 4 GiB); bigger volumes are written as BigTIFF
    big = vol.nbytes > 2 ** 32 - 2 ** 25
    imagej = vol.dtype in (np.uint8, np.uint16, np.float32) and not big
    kw: dict = {"bigtiff": True} if big else {}
    if imagej:
        meta = {"axes": "ZYX"}
        if voxel_size is not None:
            from rodwarp.ct._prepare import parse_voxel_size

            from rodwarp.rodset import UNITS

            if unit not in ("m", "mm", "um", "voxel"):
                raise _fail(f"write_tiff unit must be m, mm, um or voxel, got {unit!r}")
            k = 1.0 if unit == "voxel" else UNITS[unit]
            dz, dy, dx = (v / k for v in parse_voxel_size(voxel_size))
            meta.update(unit="pixel" if unit == "voxel" else unit, spacing=dz)
            kw["resolution"] = (1.0 / dx, 1.0 / dy)
        kw.update(imagej=True, metadata=meta)
    else:
        kw["metadata"] = {"axes": "ZYX"}
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            tifffile.imwrite(fh, vol, **kw)
    return path


# ----------------------------------------------------------------------------------------------
# voxel size from metadata
# ----------------------------------------------------------------------------------------------

#: unit names found in TIFF / OME / OME-Zarr metadata -> metres
_UNIT_M = {"m": 1.0, "meter": 1.0, "metre": 1.0, "cm": 1e-2, "centimeter": 1e-2, "mm": 1e-3, "millimeter": 1e-3,
           "millimetre": 1e-3, "um": 1e-6, "\u00b5m": 1e-6, "\u03bcm": 1e-6, "micron": 1e-6, "microns": 1e-6,
           "micrometer": 1e-6, "micrometre": 1e-6, "nm": 1e-9, "nanometer": 1e-9, "nanometre": 1e-9,
           "inch": 0.0254, "in": 0.0254}


def _metres(unit) -> float | None:
    if unit is None:
        return None
    u = str(unit).strip().lower().replace("\\u00b5", "\u00b5")
    return _UNIT_M.get(u)


def _tiff_voxel_size(path: Path):
    import tifffile

    with _tifffile_quiet(), tifffile.TiffFile(path) as tf:
        if tf.is_ome and tf.ome_metadata:
            import xml.etree.ElementTree as ET

            root = ET.fromstring(tf.ome_metadata)
            px = next((el for el in root.iter() if el.tag.endswith("Pixels")), None)
            if px is not None and px.get("PhysicalSizeX"):
                out = []
                for ax in ("Z", "Y", "X"):
                    v = px.get(f"PhysicalSize{ax}")
                    unit = px.get(f"PhysicalSize{ax}Unit", "\u00b5m")  # the OME default
                    k = _metres(unit)
                    if v is None or k is None:
                        return None
                    out.append(float(v) * k)
                return tuple(out), "OME-XML PhysicalSize"
        page = tf.pages[0]
        tags = page.tags
        if "XResolution" not in tags or "YResolution" not in tags:
            return None
        xr, yr = tags["XResolution"].value, tags["YResolution"].value
        xres = xr[0] / xr[1] if isinstance(xr, tuple) else float(xr)
        yres = yr[0] / yr[1] if isinstance(yr, tuple) else float(yr)
        if not (xres > 0 and yres > 0):
            return None
        ij = tf.imagej_metadata or {}
        ru = tags["ResolutionUnit"].value if "ResolutionUnit" in tags else 1
        if ij.get("unit") is not None:
            k = _metres(ij.get("unit"))
            src = "ImageJ resolution/spacing"
        elif int(ru) == 2:
            k, src = 0.0254, "TIFF resolution (inch)"
        elif int(ru) == 3:
            k, src = 0.01, "TIFF resolution (cm)"
        else:
            return None  # resolution without a unit: pixels per nothing
        if k is None:
            return None
        dx, dy = k / xres, k / yres
        dz = float(ij["spacing"]) * k if ij.get("spacing") else dx
        # a default resolution of 1 pixel per unit is no calibration
        if xres == 1.0 and yres == 1.0 and not ij.get("spacing"):
            return None
        return (dz, dy, dx), src


def _zarr_voxel_size(path: Path, key: str | None):
    import zarr

    try:
        root = zarr.open(str(path), mode="r")
    except Exception:  # noqa: BLE001 - unreadable stores are reported by the readers
        return None
    attrs = dict(getattr(root, "attrs", {}) or {})
    ms = attrs.get("multiscales") or (attrs.get("ome") or {}).get("multiscales")
    if not ms:
        return None
    m = ms[0]
    ds = m.get("datasets") or []
    d0 = next((d for d in ds if key is None or d.get("path") == key), ds[0] if ds else None)
    if d0 is None:
        return None
    scale = None
    for t in list(m.get("coordinateTransformations") or []) + list(d0.get("coordinateTransformations") or []):
        if t.get("type") == "scale":
            s = np.asarray(t["scale"], float)
            scale = s if scale is None else scale * s
    if scale is None or len(scale) < 3:
        return None
    axes = m.get("axes") or []
    names = [a.get("name") if isinstance(a, dict) else str(a) for a in axes] or ["z", "y", "x"][-len(scale):]
    units = [a.get("unit") if isinstance(a, dict) else None for a in axes] or [None] * len(scale)
    out = []
    for ax in ("z", "y", "x"):
        if ax not in names:
            return None
        i = names.index(ax)
        k = _metres(units[i]) if i < len(units) else None
        if k is None:
            return None
        out.append(float(scale[i]) * k)
    return tuple(out), "OME-Zarr scale"


#: ImageJ units that say a volume has no physical scale (lengths in voxel widths)
_NO_SCALE = ("pixel", "pixels", "voxel", "voxels")


def _imagej_metadata(path) -> dict:
    import tifffile

    p = _resolve(path)
    if _is_zarr(p):
        return {}
    if p.is_dir():
        p = _folder_files(p)[0]
    with _tifffile_quiet(), tifffile.TiffFile(p) as tf:
        return dict(tf.imagej_metadata or {})


def read_voxel_ratio(path) -> tuple[float, float, float] | None:
    """The voxel's edges ``(dz, dy, dx)`` in voxel widths of a TIFF that states no physical
    scale (ImageJ unit ``pixel``, as ``rodwarp phantom`` writes for scenes in voxel units), or
    None."""
    try:
        ij = _imagej_metadata(path)
    except Exception:  # noqa: BLE001 - metadata is optional: unreadable metadata means none
        return None
    if str(ij.get("unit", "")).strip().lower() not in _NO_SCALE:
        return None
    dz = float(ij.get("spacing") or 1.0)
    return (dz, 1.0, 1.0) if dz > 0 else None


def read_voxel_unit(path) -> str | None:
    """The length unit (``m``, ``mm`` or ``um``) a TIFF's ImageJ metadata states its voxel
    size in, ``voxel`` for a TIFF with no physical scale (ImageJ unit ``pixel``), or None
    (another unit, no ImageJ metadata, not a TIFF, unreadable).

    ``rodwarp phantom`` writes its voxel size in the rods' units; ``rodwarp segment`` reports
    in this unit by default, so the round trip keeps the rods' units.
    """
    try:
        unit = _imagej_metadata(path).get("unit")
    except Exception:  # noqa: BLE001 - metadata is optional: unreadable metadata means none
        return None
    if str(unit or "").strip().lower() in _NO_SCALE:
        return "voxel"
    k = _metres(unit)
    return {1.0: "m", 1e-3: "mm", 1e-6: "um"}.get(k) if k is not None else None


def read_voxel_size(path, *, key: str | None = None):
    """Voxel size recorded in a CT stack's metadata, or None when it records none.

    Reads OME-XML ``PhysicalSize{X,Y,Z}`` (OME-TIFF), the ImageJ ``spacing`` / ``unit`` and
    the TIFF ``XResolution`` / ``YResolution`` tags (ImageJ TIFF; a plain TIFF with an inch or
    centimetre resolution unit gives x, y and takes z = x), and the OME-Zarr ``scale``
    transformation with its axis units.  A folder of slices is read from its first slice.

    Returns
    -------
    ((dz, dy, dx), source) or None
        Edge lengths in metres along (z, y, x) and the metadata they came from.
    """
    p = _resolve(path)
    try:
        if _is_zarr(p):
            return _zarr_voxel_size(p, key)
        if p.is_dir():
            files = _folder_files(p)
            got = _tiff_voxel_size(files[0])
            return got
        return _tiff_voxel_size(p)
    except Exception:  # noqa: BLE001 - metadata is optional: unreadable metadata means none
        return None
