"""Reading CT volumes: multi-page TIFF, folders of slice TIFFs, zarr arrays.

Volumes are NumPy-style arrays indexed ``(z, y, x)`` = (slice, row, column). Every problem with
the input raises :class:`~rodwarp.errors.RodwarpError` with a one-line message that says what is
wrong and how to fix it. Writing (:func:`write_tiff`, atomic) and the voxel size from the
metadata (:func:`read_voxel_size`, ...) are in :mod:`rodwarp.ct.io._volume_meta`, re-exported here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.ct.io._volume_meta import _TIFF_SUFFIXES, _folder_files, _is_zarr, _resolve, _tifffile_quiet
# re-exported: their home is _volume_meta
from rodwarp.ct.io._volume_meta import list_slices, read_voxel_ratio, read_voxel_size  # noqa: F401
from rodwarp.ct.io._volume_meta import read_voxel_unit, write_tiff  # noqa: F401
from rodwarp.errors import RodwarpError

__all__ = ["read_volume", "open_volume_lazy", "write_tiff", "list_slices", "check_volume", "read_voxel_size",
           "read_voxel_unit", "read_voxel_ratio"]


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
