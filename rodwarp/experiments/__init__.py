"""The seed paper's numerical experiment, its stability verdict, parameter sweeps and the phase diagram.

>>> from rodwarp import experiments
>>> params = experiments.ProtocolParams(alpha=100, freq=10)             # doctest: +SKIP
>>> summary = experiments.run_protocol(params, "runs/a100")              # what `rodwarp simulate` does  # doctest: +SKIP
>>> experiments.judge_metrics_csv("runs/a100/metrics.csv").stable        # the verdict again            # doctest: +SKIP
>>> experiments.run_sweep(experiments.SweepSpec(alphas=[25, 50]), "runs/sweep")  # on Dask           # doctest: +SKIP
>>> experiments.phase_diagram("runs/sweep")                              # Fig. 4H/4I/4L, alpha*         # doctest: +SKIP

One private module per concern, their public names re-exported here:

=================  ==========================================================================
``_plan``          :func:`plan`, :class:`Stage` - the run plan: the stages, written once
``_params``        :class:`ProtocolParams`, :func:`rod_model_rule`, :func:`option_table` - the
                   parameters, every default stated once
``_protocol``      :func:`run_protocol` - the plan's stages on one stepping loop;
                   :func:`default_run_name`
``_recorder``      :class:`Recorder` - a run's samples (metrics rows, trajectory and VTK frames)
                   and checkpoints; :func:`plot_metrics`
``_packing``       :func:`random_packing` - the first stage, random sequential addition
``_verdict``       :func:`judge`, :class:`Thresholds`, :func:`judge_metrics_csv`, ... - stable or not
``_sweep``         :class:`SweepSpec`, :func:`run_sweep`, :func:`run_point` - the grid on Dask
``_phase``         :func:`phase_diagram`, :func:`alpha_star` - the alpha* estimate and the
                   figures (drawn in ``_phase_figures``)
``_checks``        :func:`check_protocol` (:class:`CheckedProtocol`), :func:`check_scheduler` - the options of ``simulate``
                   and ``sweep``, checked before any work
=================  ==========================================================================

The experiment is described in docs/protocol.md, the verdict in docs/verdict.md.  This is
the layer above the engine (:mod:`rodwarp.sim`) and the analysis; only the CLI is above it.
Names load on first use, so importing this package stays cheap (no Warp, no Dask).
"""

from rodwarp._util import lazy_exports

_WHERE = {
    # the protocol
    "ProtocolParams": "_params", "RODS_PER_ALPHA": "_fields", "RIGID_SAG": "_fields",
    "ExperimentParams": "_fields", "RunParams": "_fields",
    "Stage": "_plan", "Vibrate": "_plan", "REST": "_plan", "plan": "protocols", "LoopPosition": "_loop",
    "PROTOCOLS": "protocols", "Protocol": "protocols", "protocol": "protocols", "register_protocol": "protocols",
    "check_branch_protocol": "_protocol", "SIDE_WALLS": "protocols.paper", "ENTANGLE": "protocols.paper",
    "TEST": "protocols.paper",
    "option_table": "_params", "rod_model_rule": "_params", "run_protocol": "_protocol",
    "default_run_name": "_params",
    "Recorder": "_recorder", "plot_metrics": "_recorder",
    "random_packing": "_packing", "orientation_statistics": "_packing", "isotropic_directions": "_packing",
    # the verdict
    "Thresholds": "_verdict", "DEFAULT_THRESHOLDS": "_verdict", "RULE": "_verdict", "Verdict": "_verdict",
    "entangled": "_verdict", "persistence": "_verdict", "judge": "_verdict", "judge_rows": "_verdict",
    "judge_metrics_csv": "_verdict", "PileReference": "_verdict", "rod_centroids": "_verdict",
    "centroid_height_above": "_verdict", "pile_reference": "_verdict", "rods_left": "_verdict",
    # sweeps and the phase diagram
    "SweepSpec": "_sweep", "SWEEP_OWNED": "_sweep", "GRID_KEYS": "_sweep", "FIXED_KEYS": "_sweep", "RESULT_KEYS": "_sweep",
    "point_id": "_sweep", "points": "_sweep", "run_point": "_sweep", "check_points": "_sweep",
    "entangling_groups": "_sweep",
    "read_results": "_sweep", "write_results": "_sweep", "run_sweep": "_sweep",
    "phase_diagram": "_phase", "alpha_star": "_phase",
    # checks of the options
    "check_protocol": "_checks", "CheckedProtocol": "_checks", "check_input_rods": "_checks", "check_step_count": "_checks",
    "output_bytes": "_checks", "check_scheduler": "_checks",
}

__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(__name__, _WHERE)
