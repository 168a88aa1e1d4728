"""Checks of ``rodwarp analyze`` before any work (the generic ones: :mod:`rodwarp.validation`)."""

from __future__ import annotations

from rodwarp.validation import BASE_BYTES, check_ranges, device_name, fail, memory_fits

#: bytes per voxel of `rodwarp analyze` (seven float64 fields, the valid mask, labels and the
#: batch scratch of the kernels), rounded up
ANALYZE_BYTES_PER_VOXEL = 200


def check_analyze(o) -> None:
    """Checks of :class:`rodwarp.analysis.AnalyzeOptions` (lengths in the input's units)."""
    from rodwarp.rodset import UNITS

    check_ranges(o)  # every field within the range stated beside it (AnalyzeOptions)
    if o.units is not None and o.units not in UNITS:
        fail(f"--units must be one of {', '.join(UNITS)}, got '{o.units}'")
    if o.outlier not in ("q3", "q1"):
        fail(f"--outlier must be q3 (Q3 + 1.5 IQR, the paper's) or q1, got '{o.outlier}'")
    if o.convention not in ("text", "authors"):
        fail(f"--convention must be text (the paper's definitions) or authors (the authors' MATLAB routine), "
             f"got '{o.convention}'")
    device_name("--device", o.device)


def check_grid_memory(n_voxels: float, rods=None, extent: float | None = None) -> None:
    """Refuse an analysis grid whose memory estimate exceeds what is available.

    With ``rods`` (and the domain's largest edge ``extent``, in the rods' units) whose sizes
    are implausible for their declared units, the message points at ``--units`` first.
    """
    from rodwarp.rodset.scale import unit_hint

    hint = unit_hint(rods, extent) if rods is not None else None
    fix = f"check the units first: {hint}; else raise --spacing or --radius" if hint else "raise --spacing or --radius"
    memory_fits(f"the analysis grid ({n_voxels:.3g} voxels)", BASE_BYTES + ANALYZE_BYTES_PER_VOXEL * n_voxels, fix)
