"""Mesoscopic fields on a voxel grid: one container, one file format.

``Fields`` holds the local fields that ``rodwarp analyze`` computes (or reads back), one float64
array of shape ``(nz, ny, nx)`` per field of the registry (:data:`~rodwarp.analysis.FIELDS`:
``phi``, ``S``, ``c``, ``e``, ``n``, ``contacts``, ``n_ends``, defined in ``docs/fields.md``) -
axis order (z, y, x), like the paper's own field files - plus the 1-D voxel-centre coordinates
``x``, ``y``, ``z`` and the parameters.  A field the source did not provide is all NaN; voxels
outside the analysed domain are NaN (``n`` too); ``valid`` is the mask of the others.

File format
    ``fields.zarr``: a zarr group holding the arrays above and ``x``, ``y``, ``z``; the group
    attributes hold ``radius``, ``spacing``, ``units``, ``axis_order`` = "z,y,x" and the rest of
    ``attrs``.  ``.npz`` holds the same arrays plus ``attrs_json``.  Precomputed fields in the
    paper authors' layout (``phi``, ``s``, ``c``, ``e``, ``n``, ``cx``, ``cy``, ``cz``, ``R``,
    ``h``; voxels with ``n == 0`` outside the packing) load too.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from rodwarp._util import json_safe
from rodwarp.analysis._registry import field_names
from rodwarp.errors import RodwarpError
from rodwarp.rodset import MAX_COORDINATE
from rodwarp.arguments import real
from rodwarp.rodset import check_units
from rodwarp.rodset.files import atomic_path, consolidate_zarr

__all__ = ["Fields"]

_COORDS = ("x", "y", "z")


class Fields:
    """Local fields on a regular voxel grid, axis order (z, y, x).

    Parameters
    ----------
    e, n : ndarray, shape (nz, ny, nx)
        Entanglement and rods per ball (required: ``n > 0`` marks the voxels in the packing).
    **arrays : ndarray, shape (nz, ny, nx)
        Any other registered field by name (``phi``, ``S``, ``c``, ``contacts``, ...); one not
        given is all NaN (not provided by the source).  Read back as attributes (``f.phi``).
    x, y, z : ndarray
        Voxel-centre coordinates along each axis, in ``units``.
    radius : float
        Ball radius R, in ``units`` (positive, at most 1e12).
    spacing : float
        Grid spacing, in ``units`` (positive, at most 1e12).
    units : str
        Length unit of coordinates, radius and spacing (``m``, ``mm``, ``um`` or ``voxel``).
    attrs : dict
        Everything else worth keeping (diameter, mean rod length, rho, Z, source, ...).
    """

    def __init__(self, *, x, y, z, radius: float, spacing: float, units: str = "m", attrs: dict | None = None,
                 **arrays) -> None:
        names = field_names()
        unknown = sorted(set(arrays) - set(names))
        if unknown:
            raise RodwarpError(f"unknown field(s) {', '.join(unknown)}; registered: {', '.join(names)}")
        for name in ("e", "n"):
            if arrays.get(name) is None:
                raise RodwarpError(f"fields need '{name}' (entanglement and rods per ball)")
        data = {}
        for name in ("e",) + tuple(n for n in names if n != "e"):
            a = arrays.get(name)
            if a is None:
                data[name] = np.full(data["e"].shape, np.nan)
                continue
            a = np.asarray(a, dtype=np.float64)
            if a.ndim != 3:
                raise RodwarpError(f"field '{name}' must be 3-D (z, y, x), got shape {a.shape}")
            if name != "e" and a.shape != data["e"].shape:
                raise RodwarpError(f"field '{name}' has shape {a.shape}, expected {data['e'].shape} like 'e'")
            data[name] = a
        object.__setattr__(self, "_data", {n: data[n] for n in names})
        shape = data["e"].shape
        for name, values, size in zip(_COORDS, (x, y, z), shape[::-1]):
            a = np.asarray(values, dtype=np.float64).reshape(-1)
            if a.size != size:
                raise RodwarpError(f"coordinate '{name}' has {a.size} values but the grid has {size} along {name}")
            object.__setattr__(self, name, a)
        self.radius = real("radius", radius, gt=0, le=MAX_COORDINATE, unit=str(units))
        self.spacing = real("spacing", spacing, gt=0, le=MAX_COORDINATE, unit=str(units))
        self.units = check_units(units)
        self.attrs = {} if attrs is None else attrs

    def __getattr__(self, name: str):
        # only called when normal look-up fails: the registered fields
        data = self.__dict__.get("_data", {})
        if name in data:
            return data[name]
        raise AttributeError(f"Fields has no attribute {name!r} (fields: {', '.join(data)})")

    def __setattr__(self, name: str, value) -> None:
        if name in self.__dict__.get("_data", {}):
            a = np.asarray(value, dtype=np.float64)
            if a.shape != self.shape:
                raise RodwarpError(f"field '{name}' must have shape {self.shape}, got {a.shape}")
            self._data[name] = a
        else:
            object.__setattr__(self, name, value)

    def __repr__(self) -> str:
        return (f"Fields(shape={self.shape}, radius={self.radius:g}, spacing={self.spacing:g}, "
                f"units={self.units!r}, fields={list(self._data)})")

    @property
    def shape(self) -> tuple[int, int, int]:
        return self._data["e"].shape

    @property
    def valid(self) -> np.ndarray:
        """Voxels inside the analysed domain: finite e with at least one rod counted (n > 0)."""
        return np.isfinite(self.e) & np.isfinite(self.n) & (self.n > 0)

    @property
    def system_size(self) -> np.ndarray:
        """Extent (x, y, z) of the valid voxel centres plus one spacing, in ``units``."""
        v = self.valid
        out = np.zeros(3)
        for k, (coord, axis) in enumerate(((self.x, (0, 1)), (self.y, (0, 2)), (self.z, (1, 2)))):
            idx = np.flatnonzero(v.any(axis=axis))
            out[k] = (coord[idx[-1]] - coord[idx[0]] + self.spacing) if idx.size else 0.0
        return out

    def get(self, name: str) -> np.ndarray:
        """The array of the registered field ``name`` (all NaN when the source lacked it)."""
        if name not in self._data:
            raise KeyError(f"no field {name!r}; registered: {', '.join(self._data)}")
        return self._data[name]

    def arrays(self) -> dict[str, np.ndarray]:
        """Every field, then the coordinates x, y, z."""
        return {**self._data, "x": self.x, "y": self.y, "z": self.z}

    def meta(self) -> dict:
        return {"radius": float(self.radius), "spacing": float(self.spacing), "units": self.units,
                "axis_order": "z,y,x", **self.attrs}

    # ------------------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        """Write ``fields.zarr`` (zarr group) or ``.npz`` atomically."""
        path = Path(path)
        meta = json_safe(self.meta(), finite=False)
        if path.suffix == ".npz":
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as fh:
                    np.savez_compressed(fh, attrs_json=np.array(json.dumps(meta)), **self.arrays())
            return path
        if path.suffix != ".zarr":
            raise RodwarpError(f"cannot write fields to '{path}': use a .zarr or .npz name")
        import zarr

        units = {"x": self.units, "y": self.units, "z": self.units}
        with atomic_path(path, directory=True) as tmp:
            g = zarr.open_group(str(tmp), mode="w")
            for name, a in self.arrays().items():
                # named dimensions: xarray.open_zarr gives fields on (z, y, x) with x, y, z as
                # index coordinates (voxel centres)
                dims = (name,) if name in ("x", "y", "z") else ("z", "y", "x")
                arr = g.create_array(name, data=a, dimension_names=dims)
                if name in units:
                    arr.attrs["units"] = units[name]
            g.attrs.update(meta)
            consolidate_zarr(tmp)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Fields":
        """Read fields from ``fields.zarr``, a rodwarp ``.npz`` or a paper-authors ``.npz``."""
        path = Path(path)
        if not path.exists():
            raise RodwarpError(f"fields file '{path}' does not exist; check the path")
        if path.is_dir():
            return _load_zarr(path)
        if path.suffix != ".npz":
            raise RodwarpError(f"cannot read fields from '{path}': expected a .zarr directory or an .npz file")
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except Exception as e:  # noqa: BLE001 - numpy raises many types for corrupt archives
            raise RodwarpError(f"cannot read '{path}' as an .npz archive ({type(e).__name__}: {e})") from None
        return _from_dict(data, path)


def _load_zarr(path: Path) -> Fields:
    import zarr

    try:
        g = zarr.open_group(str(path), mode="r")
        data = {k: np.asarray(g[k][...]) for k in g.array_keys()}
        meta = dict(g.attrs)
    except Exception as e:  # noqa: BLE001
        raise RodwarpError(f"cannot read '{path}' as a zarr group of fields ({type(e).__name__}: {e})") from None
    data["attrs_json"] = np.array(json.dumps(meta))
    return _from_dict(data, path)


def _from_dict(data: dict, path: Path) -> Fields:
    try:
        return _fields_of(data, path)
    except RodwarpError as e:  # a bad radius, spacing or unit recorded in the file: say which file
        msg = str(e)
        raise RodwarpError(msg if str(path) in msg else f"'{path}': {msg}") from None


def _fields_of(data: dict, path: Path) -> Fields:
    if "e" not in data:
        raise RodwarpError(f"'{path}' holds no 'e' array; precomputed fields need at least 'e' and 'n'")
    meta = {}
    if "attrs_json" in data:
        meta = json.loads(str(data.pop("attrs_json")))
    e = np.asarray(data["e"], dtype=np.float64)
    if e.ndim != 3:
        raise RodwarpError(f"'e' in '{path}' must be 3-D (z, y, x), got shape {e.shape}")
    nan = np.full(e.shape, np.nan)
    if "n" in data:
        n = np.asarray(data["n"], dtype=np.float64)
    else:
        raise RodwarpError(f"'{path}' holds no 'n' array (rods per ball); it marks the voxels inside the packing")
    paper = "cx" in data and "x" not in data
    if paper:
        # the authors' layout: coordinates cx, cy, cz and scalars R, h, in CT voxels
        x, y, z = data["cx"], data["cy"], data["cz"]
        radius = float(np.asarray(data["R"]))
        spacing = float(np.asarray(data["h"]))
        units = "voxel"
        S = data.get("s", data.get("S", nan))
        attrs = {"source": str(path), "layout": "paper-authors"}
        outside = ~(n > 0)
        fields = {k: np.where(outside, np.nan, np.asarray(v, dtype=np.float64))
                  for k, v in (("phi", data.get("phi", nan)), ("S", S), ("c", data.get("c", nan)), ("e", e))}
        n = np.where(outside, np.nan, n)
        return Fields(**fields, n=n, x=x, y=y, z=z, radius=radius, spacing=spacing, units=units, attrs=attrs)
    for key in ("x", "y", "z"):
        if key not in data:
            raise RodwarpError(f"'{path}' holds no '{key}' coordinate array")
    radius = float(meta.pop("radius", np.nan))
    spacing = float(meta.pop("spacing", np.nan))
    units = str(meta.pop("units", "m"))
    meta.pop("axis_order", None)
    # fields of this registry only: one a later rodwarp added is skipped, one an earlier lacked is NaN
    present = {k: data[k] for k in field_names() if k in data and k not in ("e", "n")}
    return Fields(**present, e=e, n=n, x=data["x"], y=data["y"], z=data["z"], radius=radius, spacing=spacing,
                  units=units, attrs=meta)
