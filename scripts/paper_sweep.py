"""Run the paper's stability sweep (Fig. 4H/4I/4L) with `rodwarp.experiments` and draw its phase diagram.

alpha 25..300 x f = 1, 10, 100 Hz at A = 1 mm, g = 0.5 m/s^2 (a/g = 0.079, 7.9, 790), one seed.
Durations can be cut from the paper's 5 s + 5 s; the ones used are written to OUT/sweep.json
and into every row of OUT/results.csv. Finished points are skipped when the command is repeated.

    python scripts/paper_sweep.py --entangle-duration 1 --duration 1 --workers 2 --out runs/sweep_paper
    python scripts/paper_sweep.py ... --scheduler tcp://HOST:8786      # on an existing Dask cluster

With --copy-to DIR, the figures, results.csv, alpha_star.csv and sweep.json are copied there.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from rodwarp.experiments import SweepSpec, phase_diagram, run_sweep


def _floats(s):
    return [float(x) for x in s.split(",") if x.strip()]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--alphas", default="25,50,100,200,300")
    ap.add_argument("--freqs", default="1,10,100")
    ap.add_argument("--gravities", default="0.5")
    ap.add_argument("--static-loads", default="0")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--amplitude", type=float, default=0.001)
    ap.add_argument("--entangle-duration", type=float, default=5.0)
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--device", default="auto")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--out", default="runs/sweep_paper")
    ap.add_argument("--copy-to", default=None)
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    spec = SweepSpec(alphas=_floats(args.alphas), freqs=_floats(args.freqs), gravities=_floats(args.gravities),
                     static_loads=_floats(args.static_loads), seeds=list(range(args.seeds)),
                     amplitude=args.amplitude, entangle_duration=args.entangle_duration,
                     duration=args.duration, device=args.device)
    csv_path = run_sweep(spec, args.out, scheduler=args.scheduler, workers=args.workers,
                         progress=not args.no_progress)
    written = phase_diagram(args.out)
    print(f"wrote {csv_path}")
    for p in written:
        print(f"wrote {p}")
    if args.copy_to:
        dest = Path(args.copy_to)
        dest.mkdir(parents=True, exist_ok=True)
        for p in [csv_path, Path(args.out) / "sweep.json", *written]:
            shutil.copy2(p, dest / Path(p).name)
        print(f"copied results to {dest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
