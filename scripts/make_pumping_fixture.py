"""Write tests/data/pumping_pile.npz: a dense shaken pile where symplectic bending pumps energy.

The state is the end of entangling (t = 5 s) of

    rodwarp simulate --alpha 200 --freq 10 --gravity 0.5 --n-rods 300 \\
        --entangle-duration 5 --duration 2 --fields-every 100 --out RUN

run before bending became implicit wherever rods touch (rodwarp 0.1.0 at commit 1815b84);
the pile then carried 78 J of kinetic and 93 J of bending energy. The fixture keeps that
checkpoint's state, its parameters and step history, and the run's initial (straight) rods,
from which the model is rebuilt (tests/test_bending_integration.py).

Usage: python scripts/make_pumping_fixture.py RUN [OUT]
"""

import json
import sys
from pathlib import Path

import numpy as np


def main(run: str, out: str = "tests/data/pumping_pile.npz") -> None:
    run = Path(run)
    ck = sorted((run / "checkpoints").glob("ckpt_*.npz"))
    if not ck:
        sys.exit(f"error: no checkpoint in {run / 'checkpoints'}; run the command in this script's docstring first")
    with np.load(ck[0]) as z:
        meta = json.loads(str(z["meta"]))
        state = {k: z[k] for k in z.files if k.startswith("state_")}
    if meta["stage"] != 1 or meta["mid_stage"]:
        sys.exit("error: the first checkpoint is not the end of entangling")
    with np.load(run / "initial.npz") as z:
        rods = {"rods_" + k: z[k] for k in ("points", "offsets", "radii", "box")}
    info = {"parameters": meta["parameters"], "stepper": meta["stepper"], "stage_t0": float(state["state_time"])}
    tmp = Path(out).with_suffix(".tmp.npz")
    np.savez_compressed(tmp, meta=json.dumps(info), **state, **rods)
    tmp.replace(out)
    print(f"wrote {out} ({Path(out).stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(*sys.argv[1:3])
