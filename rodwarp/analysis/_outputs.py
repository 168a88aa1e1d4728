"""The folder ``rodwarp analyze`` writes, registered with the run-folder layer
(:func:`rodwarp.rodset.rundir.register_command`)."""

from rodwarp.rodset.rundir import register_command

#: what ``rodwarp analyze`` writes in its folder
ANALYZE_OUTPUTS = ("fields.zarr", "summary.json", "rods.npz", "histograms.png", "slices.png", "zprofiles.png",
                   "tangles.png", "distributions.png")

# an analysis from before manifests is known by its fields
register_command("analyze", ANALYZE_OUTPUTS, legacy_marker="fields.zarr", inside_input=True)
