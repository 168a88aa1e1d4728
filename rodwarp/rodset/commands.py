"""What each command writes in its output folder: one table of data, read by
:mod:`rodwarp.rodset.rundir` (which names no command itself). A new command adds its row here;
importing a command's module registers nothing.

Each row: ``outputs`` (bare names or ``*`` patterns the command writes in its folder) and the
traits :func:`rodwarp.rodset.rundir.register_command` documents (``legacy_marker``,
``exclusive``, ``resumable``, ``hosts``, ``inside_input``).
"""

#: what ``rodwarp simulate`` writes in its folder (``analysis`` is a later analyze run of it)
SIMULATE_OUTPUTS = ("summary.json", "metrics.csv", "metrics.png", "trajectory.zarr", "trajectory.pvd", "vtk",
                    "initial.npz", "entangled.npz", "entangled_from.json", "final.npz", "snapshots.png",
                    "checkpoints", "analysis", "fields_press*.npz", "rods_press*.npz")
#: what ``rodwarp sweep`` writes in its folder, with the files of ``rodwarp phase-diagram``
#: (names with ``*`` are patterns of bare names: one figure per group of points)
SWEEP_OUTPUTS = ("sweep.json", "results.csv", "points", "alpha_star.csv", "power_law.csv", "phase_*.png")
#: what ``rodwarp phase-diagram --out DIR`` writes in a folder of its own (in the sweep's folder,
#: its default, these files are the sweep's)
PHASE_DIAGRAM_OUTPUTS = ("alpha_star.csv", "power_law.csv", "phase_*.png")
#: what ``rodwarp analyze`` writes in its folder
ANALYZE_OUTPUTS = ("fields.zarr", "summary.json", "rods.npz", "histograms.png", "slices.png", "zprofiles.png",
                   "tangles.png", "distributions.png")
#: what ``rodwarp segment`` writes in its folder (``analysis`` is a later analyze run of it)
SEGMENT_OUTPUTS = ("rods.npz", "rods.csv", "contacts.csv", "filaments.csv", "summary.json", "qa_slices.png",
                   "qa_projection.png", "qa_confidence.png", "analysis")

#: every command's folder contract, by the name manifests record
COMMANDS = {
    # outputs only a simulation writes: an analysis never takes a folder holding them for its own
    "simulate": dict(outputs=SIMULATE_OUTPUTS, exclusive=("final.npz", "trajectory.zarr", "metrics.csv", "checkpoints"),
                     resumable=True, hosts={"analysis": ("analyze",)}),
    "sweep": dict(outputs=SWEEP_OUTPUTS, hosts={"points": ("simulate", "analyze")}),
    "phase-diagram": dict(outputs=PHASE_DIAGRAM_OUTPUTS),
    # an analysis from before manifests is known by its fields
    "analyze": dict(outputs=ANALYZE_OUTPUTS, legacy_marker="fields.zarr", inside_input=True),
    "segment": dict(outputs=SEGMENT_OUTPUTS, hosts={"analysis": ("analyze",)}),
}
