"""A protocol with one more stage: the container lifted away before the vibration test.

The paper's protocol is a run plan of two stages (rodwarp.experiments.plan): entangling in the
closed box, then the stability test on the vibrated floor with the side walls and lid gone. Here
a stage is added in one place: after entangling, the walls are taken away and the packing stands
(or spreads) for 0.2 s before the test. The run writes the usual outputs (summary.json,
metrics.csv, trajectory, figures) into a temporary folder.

    python examples/custom_stage.py
"""

import csv
import tempfile
from pathlib import Path

from rodwarp.experiments import SIDE_WALLS, ProtocolParams, Stage, plan, run_protocol

params = ProtocolParams(alpha=20, n_rods=30, entangle_duration=0.2, duration=0.2, save_every=0.05,
                        fields_every=0.0, gravity=10.0, device="cpu")
entangle, test = plan(params)
lifted = (entangle, Stage("lift", 0.2, walls_out=SIDE_WALLS, title="container lifted away"), test)
with tempfile.TemporaryDirectory() as tmp:
    out = Path(tmp) / "run"
    summary = run_protocol(params, out, progress=False, stages=lifted)
    with open(out / "metrics.csv") as fh:
        stages = [row["stage"] for row in csv.DictReader(fh)]
print("stages:", " -> ".join(dict.fromkeys(stages)))
print(f"test started at t = {summary['test_start']['time']:.2f} s; height kept h = {summary['height_kept']:.3f}, "
      f"largest cluster f = {summary['largest_cluster_fraction']:.3f}, stable = {summary['stable']}")
