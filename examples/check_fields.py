"""Check rodwarp's field kernels on your own rods and device against an independent oracle.

`rodwarp.testing.reference.fields_numpy` computes the local fields of docs/fields.md (phi, S,
n, e and the contact count) in NumPy and SciPy from the formulas alone: it shares no code with the Warp
kernels of `rodwarp.analysis`. Run on the same rods and ball centres, the two must agree to
round-off. This script takes the 60 rods of examples/centerlines.csv (l = 0.1 m, d = 2 mm),
their fields on the default grid (ball radius R = sqrt(d l), spacing R / 2) on the CPU (or on
the device named as the first argument: cpu, cuda), and the oracle's fields at the first 200
voxels inside the packing, and prints the largest difference of each field. The test suite
runs the same comparison on random curved rods (tests/test_fields.py).

    python examples/check_fields.py          # or: python examples/check_fields.py cuda
"""

import sys
from pathlib import Path

import numpy as np

import rodwarp
from rodwarp import analysis
from rodwarp.testing.reference import fields_numpy

device = sys.argv[1] if len(sys.argv) > 1 else "cpu"
rods = rodwarp.load(Path(__file__).with_name("centerlines.csv"), diameter=0.002, units="m")
fields = analysis.compute_fields(rods, device=device)

# the ball centres of the voxels inside the packing (the grid is indexed z, y, x)
Z, Y, X = np.meshgrid(fields.z, fields.y, fields.x, indexing="ij")
inside = np.flatnonzero(fields.valid.ravel())[:200]
centres = np.c_[X.ravel(), Y.ravel(), Z.ravel()][inside]

p0, p1, seg_rod = rods.segments()
contact_points = rods.contacts.point if rods.contacts is not None else None
ref = fields_numpy(p0, p1, seg_rod, 2 * rods.radii[seg_rod], centres, fields.radius,
                   contact_points=contact_points)

print(f"{len(centres)} voxels of {rods.n_rods} rods on {device}, R = {fields.radius:.5f} m")
for name in ("phi", "S", "n", "e"):
    ours = getattr(fields, name).ravel()[inside]
    diff = float(np.max(np.abs(ours - ref[name])))
    print(f"{name}: largest |warp - numpy| = {diff:.3g} (mean {float(np.mean(ref[name])):.6g})")
