"""Time the laboratory protocol's shaking from a run's end-of-lift checkpoint (one JSON line).

``python benchmarks/lab_shake_timer.py CHECKPOINT SECONDS [--profile]`` rebuilds the run's model and solver
from the checkpoint's parameters, restores its state and contact points, and steps the shaking
stage for SECONDS of simulated time exactly as ``rodwarp simulate`` does (the adaptive step at
the run's safety, the sample times left out), timing the steps alone. It uses only the API that
rodwarp had before issue 45, so the same script times an older checkout on the same state (run
it with that checkout's Python): the same-run ratios of ``benchmarks/bench_lab_cost.py``.
With ``--profile`` every kernel launch is synchronised and timed (the solver's own profiling,
keyed by stage and kernel), which slows the run: for the split, not for the total.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np


def main(path: str, seconds: float, profile: bool = False) -> dict:
    import warp as wp

    wp.config.quiet = True
    from rodwarp import _warp
    from rodwarp.experiments import _protocol as P
    from rodwarp.experiments._params import ProtocolParams, rod_model_rule
    from rodwarp.experiments import plan
    from rodwarp.rodset import load
    from rodwarp.rodset.trajectory import read_checkpoint_file
    from rodwarp.sim import State

    _warp.load_kernels("cpu", _warp.SIMULATION_MODULES, progress=False)  # compiled (or loaded) before timing
    arrays, meta = read_checkpoint_file(path)
    known = ProtocolParams.__dataclass_fields__
    # parameters an older checkout does not know (added since, at their defaults) are left out
    kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in meta["parameters"].items() if k in known}
    params = ProtocolParams(**kw)
    rods = load(Path(path).parent.parent / "initial.npz")
    model, solver, _ = P._build(params, rods, "cpu", rod_model_rule(params)["rod_model"])
    stage = plan(params)[meta["stage"]]
    state, other, points = model.state(), State(model), solver.contacts()
    saved = {k[6:]: v for k, v in arrays.items() if k.startswith("state_")}
    state.load_numpy(saved)
    points.load_numpy(saved)
    control = stage.control(model, state.time, meta["marks"])
    stepper = dict(meta["stepper"])
    if profile:
        solver.reset_timings()
        launch = solver._launch

        def keyed(stage, kernel, *, dim, device, inputs):
            return launch(f"{stage}: {getattr(kernel, 'key', kernel)}", kernel, dim=dim, device=device, inputs=inputs)

        solver._launch = solver.collision._launch = keyed
    t_end = state.time + seconds
    steps = refused = 0
    contacts = []
    cpu0, t0 = time.process_time(), time.perf_counter()
    while state.time < t_end - 1e-12:
        dt = solver.adaptive_dt(control, stepper["vmax"], stepper["dt"], safety=params.step_safety,
                                overlap=stepper.get("overlap"))
        dt = min(dt, t_end - state.time)
        info, dt, r = solver.adaptive_step(state, other, control, points, dt)
        state, other = other, state
        steps += 1
        refused += r
        stepper.update(vmax=info.max_speed, dt=dt, overlap=info.max_overlap)
        contacts.append(info.n_contacts)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - t0
    out = {"stage": stage.name, "seconds": seconds, "n_rods": model.n_rods, "n_vertices": model.n_vertices,
            "steps": steps, "refused": refused, "cpu_s": cpu, "wall_s": wall, "cpu_s_per_s": cpu / seconds,
            "mean_dt_s": seconds / steps, "contact_points_median": float(np.median(contacts)),
            "max_overlap_over_d": stepper["overlap"] / model.min_diameter}
    if profile:
        out["kernel_ms_per_step"] = {k: 1e3 * v / steps for k, v in sorted(solver.timings.items(), key=lambda kv: -kv[1])}
        out["host_ms_per_step"] = 1e3 * (wall - sum(solver.timings.values())) / steps
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], float(sys.argv[2]), "--profile" in sys.argv[3:])))
