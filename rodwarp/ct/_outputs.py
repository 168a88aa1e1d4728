"""The folder ``rodwarp segment`` writes, registered with the run-folder layer
(:func:`rodwarp.rodset.rundir.register_command`)."""

from rodwarp.rodset.rundir import register_command

#: what ``rodwarp segment`` writes in its folder (``analysis`` is a later analyze run of it)
SEGMENT_OUTPUTS = ("rods.npz", "rods.csv", "contacts.csv", "filaments.csv", "summary.json", "qa_slices.png",
                   "qa_projection.png", "qa_confidence.png",
                   "analysis")

register_command("segment", SEGMENT_OUTPUTS, hosts={"analysis": ("analyze",)})
