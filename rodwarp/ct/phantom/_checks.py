"""Checks of ``rodwarp phantom`` before any work (the generic ones: :mod:`rodwarp.validation`)."""

from __future__ import annotations

from pathlib import Path

from rodwarp.ct.phantom._phantom import SCENES as PHANTOM_SCENES
from rodwarp.validation import BASE_BYTES, Range, check_ranges, disk_fits, fail, memory_fits, output_location

#: bytes per voxel of `rodwarp phantom`: the float64 occupancy, the blurred copy, the noise and
#: the 16-bit output
PHANTOM_BYTES_PER_VOXEL = 34
#: each of the volume's three sizes (voxels); memory and disk bound their product
SHAPE_RANGE = Range(ge=2, le=100_000, whole=True, hint="three sizes >= 2 (Z Y X)")


def check_phantom(*, rods, shape, voxel_size, out, blur, cnr, ring, cupping, streaks, n_rods, radius, aspect,
                  touching, seed, fov=None, z_thickness=1, units=None, dark=False) -> None:
    """Checks of ``rodwarp phantom``: values, the volume's memory and disk size, the output path.

    Artefact amplitudes are bounded where they would saturate the 16-bit image (``ring`` and
    ``streaks`` at most 1 contrast, ``|cupping|`` below 1); a scene's ``radius`` must be at
    least 0.5 voxel. The rods' scale against the voxel and the volume is checked once they are
    loaded (:func:`rodwarp.ct.make_phantom`)."""
    from rodwarp.ct.phantom._phantom import PhantomOptions

    if len(shape) != 3:
        fail(f"--shape must be three sizes Z Y X, got {shape}")
    for axis, n in zip("ZYX", shape):
        SHAPE_RANGE.check(f"--shape {axis}", n)
    # every option within the range stated beside it (PhantomOptions)
    check_ranges(PhantomOptions(voxel_size=voxel_size, units=units, blur=blur, cnr=cnr, ring=ring, cupping=cupping,
                                streaks=streaks, fov=fov, dark=dark, z_thickness=z_thickness, n_rods=n_rods,
                                radius=radius, aspect=aspect, touching=touching, seed=seed))
    if units is not None and units not in ("m", "mm", "um", "voxel"):
        fail(f"--units must be m, mm, um or voxel (the unit of a CSV rod set and of --voxel-size), got '{units}'")
    if rods in PHANTOM_SCENES:
        if rods == "random":
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
