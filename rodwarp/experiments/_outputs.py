"""The folders ``rodwarp simulate`` and ``rodwarp sweep`` write, registered with the run-folder
layer (:func:`rodwarp.rodset.rundir.register_command`)."""

from rodwarp.rodset.rundir import register_command

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

# outputs only a simulation writes: an analysis never takes a folder holding them for its own
register_command("simulate", SIMULATE_OUTPUTS, exclusive=("final.npz", "trajectory.zarr", "metrics.csv",
                                                          "checkpoints"), resumable=True,
                 hosts={"analysis": ("analyze",)})
register_command("sweep", SWEEP_OUTPUTS, hosts={"points": ("simulate", "analyze")})
register_command("phase-diagram", PHASE_DIAGRAM_OUTPUTS)
