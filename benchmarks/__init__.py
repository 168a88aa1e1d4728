"""rodwarp benchmark suite.

Run ``python -m benchmarks [--quick|--full] [--only NAME ...] [--device cpu]``.  Each
benchmark is a module ``benchmarks/bench_<name>.py`` with

* ``run(quick: bool, device: str) -> dict``: the measurements, JSON-serialisable;
* ``plot(record: dict, outdir: Path) -> list[dict]``: PNG charts drawn from the record alone,
  each returned as ``{"file": ..., "title": ..., "reading": ...}``.

The runner adds the provenance (command, date, device, versions), writes
``benchmarks/results/<name>.json`` atomically and regenerates ``benchmarks/RESULTS.md`` from
every JSON file in ``benchmarks/results``.  See ``benchmarks/README.md``.
"""

BENCHMARKS = ("pile", "broadphase", "accuracy", "simulate", "fig4h", "protocol_dt", "acn", "fields", "stability",
              "scaling", "pyelastica", "acn_peer", "segment", "segment_scans", "vtk", "analyze", "verdict", "rigid", "effort", "peer_pile", "imc",
              "resolution", "lab_cost")
# run when no --only is given; fig4h, protocol_dt, verdict, rigid, effort, resolution and lab_cost are long protocol sweeps (tens
# of minutes to hours on two cores) that run only when named
DEFAULT = ("pile", "broadphase", "accuracy", "simulate", "acn", "fields", "segment", "segment_scans", "stability",
           "scaling", "pyelastica", "acn_peer", "vtk", "analyze")
# minutes to hours on two cores) that run only when named
DEFAULT = ("pile", "broadphase", "accuracy", "simulate", "acn", "fields", "segment", "segment_scans", "stability",
           "scaling", "pyelastica", "acn_peer", "vtk", "analyze")
