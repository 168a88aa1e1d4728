"""A phantom's ground truth: its true contacts (:func:`phantom_truth`) and where its truth files lie
(:func:`truth_paths`).

Points are ``(x, y, z)`` in the rods' units; in voxel units the centre of voxel ``(0, 0, 0)`` is
the origin.
"""

from __future__ import annotations

from pathlib import Path

from rodwarp._util import one_line_error as _fail
from rodwarp.rodset import Contacts, RodSet

__all__ = ["DEFAULT_TOLERANCE_VOXELS", "phantom_truth", "truth_paths"]

#: Largest surface gap (voxels) counted as a true contact. Scenes make gaps of exactly 0 or >= 2.
DEFAULT_TOLERANCE_VOXELS = 0.5


def phantom_truth(rods: RodSet, tolerance_voxels: float = DEFAULT_TOLERANCE_VOXELS, *,
                  voxel_size: float | None = None) -> Contacts:
    """Ground-truth contacts: rod pairs whose surfaces come within ``tolerance_voxels``.

    For rods in metric units pass ``voxel_size`` (metres per voxel) to convert the tolerance.
    Contact points and gaps are in the rods' units.
    """
    from rodwarp.rodset import detect_contacts

    if not isinstance(rods, RodSet):
        raise _fail(f"rods must be a RodSet, got {type(rods).__name__}")
    tol = float(tolerance_voxels)
    if rods.units != "voxel":
        if voxel_size is None:
            raise _fail(f"rods are in {rods.units!r}; pass voxel_size (metres per voxel) to convert the tolerance")
        from rodwarp.rodset import UNITS
        tol = tol * float(voxel_size) / UNITS[rods.units]
    return detect_contacts(rods, tol)


def truth_paths(path_tif) -> tuple[Path, Path]:
    """``(<stem>_truth.npz, <stem>_truth.json)`` beside a phantom TIFF."""
    p = Path(path_tif)
    stem = p.name
    for suf in (".ome.tiff", ".ome.tif", ".tiff", ".tif"):
        if stem.lower().endswith(suf):
            stem = stem[: -len(suf)]
            break
    return p.with_name(f"{stem}_truth.npz"), p.with_name(f"{stem}_truth.json")
