"""Where a CT volume's files are, and what their metadata says: everything but the voxels.

Which files make a volume (a path that exists, the slice TIFFs of a folder in natural order,
a zarr store), tifffile's log kept quiet while a file is opened, :func:`write_tiff` (a
multi-page TIFF with its ImageJ metadata: axes, voxel size, unit) and the voxel size, unit or
ratio read back from TIFF, OME-TIFF and OME-Zarr metadata (:func:`read_voxel_size`,
:func:`read_voxel_unit`, :func:`read_voxel_ratio`). The voxels are read and checked in
:mod:`rodwarp.ct.io._volume_io`.
"""

from __future__ import annotations

import contextlib
import logging
import re
from pathlib import Path

import numpy as np

from rodwarp._util import one_line_error as _fail

__all__ = ["list_slices", "write_tiff", "read_voxel_size", "read_voxel_unit", "read_voxel_ratio"]


# ----------------------------------------------------------------------------------------------
# the files of a volume
# ----------------------------------------------------------------------------------------------

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


def _folder_files(path: Path) -> list[Path]:
    files = list_slices(path)
    if not files:
        raise _fail(f"folder {path} holds no slice TIFFs (*.tif, *.tiff); point at the folder of slices, "
                    f"a multi-page TIFF or a zarr array")
    return files


def _resolve(path) -> Path:
    if path is None:
        raise _fail("no input path given; pass a TIFF stack, a folder of slice TIFFs or a zarr array")
    p = Path(path)
    if not p.exists():
        raise _fail(f"{p} does not exist; check the path to the CT stack")
    return p


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
            from rodwarp.ct._voxels import parse_voxel_size

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
