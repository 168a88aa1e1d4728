"""Make ``examples/centerlines.csv``: 60 straight rods (l = 0.1 m, d = 2 mm, aspect ratio 50)
placed by random sequential addition in a 0.1 x 0.1 x 0.25 m box, written as a CSV of rod
centrelines in metres with no radius column, the way a tracing tool exports them (so readers
pass ``--diameter 0.002 --units m``, as docs/commands.md shows).

    python examples/make_centerlines.py
"""

from pathlib import Path

import numpy as np

from rodwarp.experiments import random_packing

rods = random_packing(60, 0.1, 0.002, np.array([0.1, 0.1, 0.25]), n_vertices=10, seed=0, device="cpu")
out = Path(__file__).with_name("centerlines.csv")
lines = ["rod,x,y,z"]
for i in range(rods.n_rods):
    for x, y, z in rods.points[rods.offsets[i]:rods.offsets[i + 1]]:
        lines.append(f"{i},{x:.6f},{y:.6f},{z:.6f}")
out.write_text("\n".join(lines) + "\n")
print(f"{rods.n_rods} rods -> {out}")
