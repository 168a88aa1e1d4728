"""Checks of ``rodwarp phantom`` and ``rodwarp segment`` before any work (the generic ones:
:mod:`rodwarp.validation`)."""

from __future__ import annotations

from pathlib import Path

from rodwarp.ct._phantom import SCENES as PHANTOM_SCENES
from rodwarp.validation import BASE_BYTES, disk_fits, fail, integer, memory_fits, number, output_location

#: bytes per voxel of `rodwarp phantom`: the float64 occupancy, the blurred copy, the noise and
#: the 16-bit output
PHANTOM_BYTES_PER_VOXEL = 34


def check_phantom(*, rods, shape, voxel_size, out, blur, cnr, ring, cupping, streaks, n_rods, radius, aspect,
                  touching, seed, fov=None, z_thickness=1, units=None, dark=False) -> None:
    """Checks of ``rodwarp phantom``: values, the volume's memory and disk size, the output path.

    Artefact amplitudes are bounded where they would saturate the 16-bit image (``ring`` and
    ``streaks`` at most 1 contrast, ``|cupping|`` below 1); a scene's ``radius`` must be at
    least 0.5 voxel. The rods' scale against the voxel and the volume is checked once they are
    loaded (:func:`rodwarp.ct.make_phantom`)."""
    if len(shape) != 3:
        fail(f"--shape must be three sizes Z Y X, got {shape}")
    for axis, n in zip("ZYX", shape):
        integer(f"--shape {axis}", n, ge=2, hint="three sizes >= 2 (Z Y X)")
    number("--voxel-size", voxel_size, gt=0)
    number("--blur", blur, ge=0, unit="voxels")
    number("--cnr", cnr, gt=0)
    # beyond one contrast the artefact outshines the rods and clips at 0 or 65535
    number("--ring", ring, ge=0, le=1, hint="a fraction of the rod/background contrast")
    number("--cupping", cupping, gt=-1, lt=1, hint="a relative intensity drop (negative: a bright rim)")
    if fov is not None:
        number("--fov", fov, gt=0, unit="voxels")
    integer("--z-thickness", z_thickness, ge=1, le=100)
    number("--streaks", streaks, ge=0, le=1, hint="a fraction of the rod/background contrast")
    if units is not None and units not in ("m", "mm", "um", "voxel"):
        fail(f"--units must be m, mm, um or voxel (the unit of a CSV rod set and of --voxel-size), got '{units}'")
    integer("--seed", seed, ge=0, le=2**63 - 1)
    if rods in PHANTOM_SCENES:
        integer("--n-rods", n_rods, ge=1, le=10_000_000)
        # a rod thinner than a voxel renders as noise
        number("--radius", radius, ge=0.5, unit="voxels", hint="a rod must be at least a voxel thick to show")
        if rods == "random":
            number("--aspect", aspect, gt=1)
            number("--touching", touching, ge=0, le=1)
            length = 2 * radius * aspect
            if length > max(shape):
                fail(f"'random' rods of --radius {radius:g} and --aspect {aspect:g} are {length:g} voxels long, "
                     f"longer than the volume ({max(shape)} voxels); lower --aspect or --radius, or enlarge --shape")
    elif not Path(rods).exists():
        fail(f"rod set '{rods}' does not exist; pass a rod-set file, a simulate output folder or a scene "
             f"({', '.join(PHANTOM_SCENES)})")
    n_vox = float(shape[0]) * float(shape[1]) * float(shape[2]) * float(z_thickness)
    memory_fits(f"--shape {' '.join(str(s) for s in shape)} ({n_vox:.3g} voxels)",
                BASE_BYTES + PHANTOM_BYTES_PER_VOXEL * n_vox, "lower --shape")
    out = Path(out)
    if out.suffix.lower() not in (".tif", ".tiff"):
        fail(f"--out {out} must end in .tif or .tiff (a multi-page TIFF)")
    output_location(out, "--out", directory=False)
    disk_fits(out, 2.0 * n_vox, f"the 16-bit TIFF of --shape {' '.join(str(s) for s in shape)}", "lower --shape")


def check_segment(*, stack, voxel_size, units, diameter, out, chunk, contact_tolerance, min_fill=0.6) -> None:
    """Checks of ``rodwarp segment`` before the volume is read (``voxel_size``: None for the
    file's metadata, or one or three comma-separated values z,y,x)."""
    from rodwarp.rodset import UNITS

    if not Path(stack).exists():
        fail(f"CT stack '{stack}' does not exist; pass a multi-page TIFF, a folder of slices or a zarr array")
    if voxel_size is not None:
        from rodwarp.ct._report import parse_voxel_size_text

        parse_voxel_size_text(voxel_size)  # the one parser: one value or three (z,y,x), positive and finite
    if units is not None and units not in UNITS:
        fail(f"--units must be one of {', '.join(UNITS)}, got '{units}'")
    number("--min-fill", min_fill, gt=0, le=1)
    if diameter is not None:
        number("--diameter", diameter, gt=0, hint=f"in --units {units}")
    if chunk is not None:
        integer("--chunk", chunk, ge=16, hint="an edge of at least 16 voxels")
    number("--contact-tolerance", contact_tolerance, ge=0, unit="voxels")
    output_location(Path(out), "--out")
