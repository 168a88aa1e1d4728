"""Mesoscopic fields on a voxel grid: one container, one file format.

``Fields`` holds the local fields that ``rodwarp analyze`` computes (or reads back), each a
float64 array of shape ``(nz, ny, nx)`` - axis order (z, y, x), like the paper's own field
files - plus the 1-D voxel-centre coordinates ``x``, ``y``, ``z`` and the parameters.

Arrays
    ``phi``  local volume fraction (clipped rod volume / ball volume)
    ``S``    local nematic order (largest eigenvalue of the length-weighted Q tensor)
    ``c``    contact density: contacts in the ball / (rho Z V_ball / 2)
    ``e``    local entanglement: sum over pairs of distinct rods of the ACN of their clipped parts
    ``n``    rods with a clipped part in the ball
    ``contacts``  raw number of contact points in the ball (optional)

Voxels outside the analysed domain are NaN (``n`` too); ``valid`` is the mask of the others.

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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rodwarp.atomic import atomic_path
from rodwarp.errors import RodwarpError

FIELD_NAMES = ("phi", "S", "c", "e", "n")
OPTIONAL_NAMES = ("contacts",)


@dataclass
class Fields:
    """Local fields on a regular voxel grid, axis order (z, y, x).

    Parameters
    ----------
    phi, S, c, e, n : ndarray, shape (nz, ny, nx)
        The fields (NaN outside the domain).  ``c`` or ``phi``/``S`` may be all-NaN when
        the source did not provide them.
    x, y, z : ndarray
        Voxel-centre coordinates along each axis, in ``units``.
    radius : float
        Ball radius R, in ``units``.
    spacing : float
        Grid spacing, in ``units``.
    units : str
        Length unit of coordinates, radius and spacing (``m``, ``mm``, ``um`` or ``voxel``).
    contacts : ndarray or None
        Raw number of contact points in each ball.
    attrs : dict
        Everything else worth keeping (diameter, mean rod length, rho, Z, source, ...).
    """

    phi: np.ndarray
    S: np.ndarray
    c: np.ndarray
    e: np.ndarray
    n: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    radius: float
    spacing: float
    units: str = "m"
    contacts: np.ndarray | None = None
    attrs: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in FIELD_NAMES + OPTIONAL_NAMES:
            a = getattr(self, name)
            if a is None:
                continue
            a = np.asarray(a, dtype=np.float64)
            if a.ndim != 3:
                raise RodwarpError(f"field '{name}' must be 3-D (z, y, x), got shape {a.shape}")
            setattr(self, name, a)
        shape = self.e.shape
        for name in FIELD_NAMES + OPTIONAL_NAMES:
            a = getattr(self, name)
            if a is not None and a.shape != shape:
                raise RodwarpError(f"field '{name}' has shape {a.shape}, expected {shape} like 'e'")
        for name, size in zip("zyx", shape):
            a = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            if a.size != size:
                raise RodwarpError(f"coordinate '{name}' has {a.size} values but the grid has {size} along {name}")
            setattr(self, name, a)

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.e.shape

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

    def arrays(self) -> dict[str, np.ndarray]:
        out = {name: getattr(self, name) for name in FIELD_NAMES}
        if self.contacts is not None:
            out["contacts"] = self.contacts
        out.update(x=self.x, y=self.y, z=self.z)
        return out

    def meta(self) -> dict:
        return {"radius": float(self.radius), "spacing": float(self.spacing), "units": self.units,
                "axis_order": "z,y,x", **self.attrs}

    # ------------------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        """Write ``fields.zarr`` (zarr group) or ``.npz`` atomically."""
        path = Path(path)
        meta = json.loads(json.dumps(self.meta(), default=_jsonable))
        if path.suffix == ".npz":
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as fh:
                    np.savez_compressed(fh, attrs_json=np.array(json.dumps(meta)), **self.arrays())
            return path
        if path.suffix != ".zarr":
            raise RodwarpError(f"cannot write fields to '{path}': use a .zarr or .npz name")
        import zarr

        from rodwarp.outputs import consolidate

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
            consolidate(tmp)
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


def _jsonable(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


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
    return Fields(phi=data.get("phi", nan), S=data.get("S", nan), c=data.get("c", nan), e=e, n=n,
                  x=data["x"], y=data["y"], z=data["z"], radius=radius, spacing=spacing, units=units,
                  contacts=data.get("contacts"), attrs=meta)
