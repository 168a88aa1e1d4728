"""The options of ``rodwarp segment`` (:class:`SegmentOptions`) and their checks before any work
(:func:`check_segment`; the generic ones: :mod:`rodwarp.validation`).

Lengths are in ``units`` unless marked voxels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rodwarp._util import one_line_error as _fail
from rodwarp._util import option
from rodwarp.ct._voxels import parse_voxel_size_text
from rodwarp.ct.segment._params import SegmentParams
from rodwarp.validation import Range, check_ranges, fail, output_location

__all__ = ["SegmentOptions", "check_segment"]


@dataclass(frozen=True)
class SegmentOptions:
    """Options of ``rodwarp segment`` (:func:`~rodwarp.ct.run_segment`), frozen: each field's
    default and help are the command's. Lengths in ``units`` unless marked voxels."""

    voxel_size: str | None = option(None, "Voxel edge in --units: one value, or three for z,y,x (e.g. 0.1,0.05,0.05). "
                                          "Default: the file's metadata (ImageJ/OME-TIFF, OME-Zarr).")
    units: str | None = option(None, "Unit of --voxel-size, --diameter and the outputs (m, mm, um, voxel); default mm, "
                                     "or the metadata's.")
    diameter: float | None = option(None, "Rod diameter in --units (estimated when absent).",
                                    range=Range(gt=0, le=1e12, hint="in --units"))
    shape: str = option(SegmentParams.shape, "straight (rods), curved (filaments as polylines) or auto.")
    dark_rods: bool | None = option(None, "Rods darker / brighter than the background (default: detected).")
    min_fill: float = option(SegmentParams.min_fill, "Reject rods whose axis plateau is below this share of what a "
                                                     "rod of their radius shows under the measured blur.",
                                range=Range(gt=0, le=1, hint="a share of the plateau a rod shows"))
    chunk: int | None = option(None, "Process in overlapping chunks of this edge (voxels), for big volumes.",
                               range=Range(ge=16, le=100_000, whole=True, hint="an edge of at least 16 voxels"))
    contact_tolerance: float = option(SegmentParams.contact_tolerance, "Largest surface gap counted as contact "
                                                                       "(voxels).",
                                      range=Range(ge=0, le=1000, unit="voxels"))
    figures: bool = option(True, "Write the QA PNGs.")

    def validate(self, stack, out) -> None:
        """Refuse (one line) a bad option, a missing stack or an unusable ``out`` before the
        volume is read (:func:`rodwarp.ct.check_segment`)."""
        if self.shape not in ("straight", "curved", "auto"):
            raise _fail(f"--shape must be straight, curved or auto, got '{self.shape}'")
        check_segment(stack=stack, voxel_size=self.voxel_size, units=self.units, diameter=self.diameter, out=out,
                      chunk=self.chunk, contact_tolerance=self.contact_tolerance, min_fill=self.min_fill)

    def params(self) -> SegmentParams:
        """The segmentation knobs these options set (the rest at their defaults)."""
        return SegmentParams(shape=self.shape, dark=self.dark_rods, min_fill=self.min_fill)

    def run_kwargs(self) -> dict:
        """The keywords of :func:`~rodwarp.ct.run_segment` these options give."""
        return {"voxel_size": self.voxel_size, "units": self.units, "diameter": self.diameter, "chunk": self.chunk,
                "contact_tolerance": self.contact_tolerance, "figures": self.figures, "params": self.params()}


def check_segment(*, stack, voxel_size, units, diameter, out, chunk, contact_tolerance, min_fill=0.6) -> None:
    """Checks of ``rodwarp segment`` before the volume is read (``voxel_size``: None for the
    file's metadata, or one or three comma-separated values z,y,x)."""
    from rodwarp.rodset import UNITS

    if not Path(stack).exists():
        fail(f"CT stack '{stack}' does not exist; pass a multi-page TIFF, a folder of slices or a zarr array")
    if voxel_size is not None:
        parse_voxel_size_text(voxel_size)  # the one parser: one value or three (z,y,x), positive and finite
    if units is not None and units not in UNITS:
        fail(f"--units must be one of {', '.join(UNITS)}, got '{units}'")
    # every option within the range stated beside it (SegmentOptions)
    check_ranges(SegmentOptions(units=units, diameter=diameter, min_fill=min_fill, chunk=chunk,
                                contact_tolerance=contact_tolerance))
    output_location(Path(out), "--out")
