"""Command line: ``python -m benchmarks [--quick|--full] [--only NAME ...] [--device cpu]``.

Runs the selected benchmarks, writes ``benchmarks/results/<name>.json`` (atomically) and
``benchmarks/results/<name>*.png``, then regenerates ``benchmarks/RESULTS.md`` from every
JSON file in ``benchmarks/results``.  ``--report`` only regenerates the charts and
RESULTS.md from the JSON files already there.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
import traceback

from benchmarks import BENCHMARKS, DEFAULT, common, report


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_true", help="small sizes, 3 timing repeats (a few minutes; default)")
    mode.add_argument("--full", action="store_true", help="all sizes, 5 timing repeats (up to ~30 minutes)")
    p.add_argument("--only", nargs="+", metavar="NAME", choices=BENCHMARKS,
                   help=f"run only these benchmarks ({', '.join(BENCHMARKS)})")
    p.add_argument("--device", default="cpu", help="Warp device: cpu (default), cuda, cuda:N or auto")
    p.add_argument("--report", action="store_true",
                   help="do not run anything: redraw the charts and RESULTS.md from benchmarks/results/*.json")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    common.RESULTS.mkdir(parents=True, exist_ok=True)
    if args.report:
        report.replot_all()
        report.write_results_md()
        return 0

    from rodwarp import _warp
    from rodwarp.rodset.files import write_json

    quick = not args.full
    names = args.only or list(DEFAULT)
    device = _warp.resolve_device(args.device)
    command = "python -m benchmarks " + " ".join(argv if argv is not None else sys.argv[1:])
    failed = []
    for name in names:
        mod = importlib.import_module(f"benchmarks.bench_{name}")
        common.log(f"=== {name} ({'quick' if quick else 'full'} mode, device {device})")
        t0 = time.perf_counter()
        try:
            body = mod.run(quick, device)
        except Exception:  # noqa: BLE001 - one failing benchmark must not lose the others
            traceback.print_exc()
            failed.append(name)
            continue
        rec = {
            "name": name,
            "title": body.pop("title", name),
            "command": command.strip(),
            "mode": "quick" if quick else "full",
            "date": common.utc_now(),
            "device": common.device_name(device),
            "versions": common.versions(),
            "wall_s": None,
        }
        rec.update(body)
        rec["wall_s"] = time.perf_counter() - t0
        rec["summary"] = mod.summary(rec)
        rec["charts"] = mod.plot(rec, common.RESULTS)
        json.dumps(rec, default=str)  # fail early on anything not serialisable
        write_json(common.RESULTS / f"{name}.json", rec)
        common.log(f"=== {name} done in {rec['wall_s']:.0f} s -> {common.RESULTS / (name + '.json')}")
        for w in rec.get("problems", []):
            common.log(f"PROBLEM ({name}): {w}")
    path = report.write_results_md()
    common.log(f"wrote {path}")
    if failed:
        common.log(f"FAILED: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
