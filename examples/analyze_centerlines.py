"""Your own centrelines through the analysis: local fields of a CSV of rod centrelines.

examples/centerlines.csv holds 60 straight rods (l = 0.1 m, d = 2 mm) as a tracing tool exports
them: columns rod,x,y,z in metres, one row per vertex, no radius column. Loading it needs the
diameter and the unit. `rodwarp.analysis.compute_fields` evaluates the fields of docs/fields.md
on a voxel grid (ball radius R = sqrt(d l), spacing R / 2; contacts from the geometry, surface
gap below d / 10) and `field_statistics` summarises them. The script prints the rods' measured
length, diameter and aspect ratio, the ball radius against sqrt(d l), and the mean of every
field over the voxels inside the packing, with cv_e = sigma_e / mu_e. `rodwarp analyze` gives
the same numbers (in its summary.json) and writes the fields and figures too:

    rodwarp analyze examples/centerlines.csv --diameter 0.002 --units m --out runs/centerlines_analysis

    python examples/analyze_centerlines.py
"""

from pathlib import Path

import rodwarp
from rodwarp import analysis

csv = Path(__file__).with_name("centerlines.csv")
rods = rodwarp.load(csv, diameter=0.002, units="m")
fields = analysis.compute_fields(rods)
stats = analysis.field_statistics(fields)

d, l = rods.diameters.mean(), rods.rod_lengths().mean()
print(f"{rods.n_rods} rods, l = {l:.4f} m, d = {d:.4f} m, aspect ratio {l / d:.1f}; "
      f"ball radius R = {fields.radius:.5f} m (sqrt(d l) = {(d * l) ** 0.5:.5f} m)")
for name in ("phi", "S", "c", "e", "n", "n_ends"):
    print(f"mean {name} = {stats['mean_' + name]:.6g}")
print(f"cv_e = {stats['cv_e']:.6g}, outlier bound e_lb = {stats['e_lb']:.6g}, "
      f"tangles {stats['n_tangles']}, percolates {stats['percolates']}")
