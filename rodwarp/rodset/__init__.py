"""The rod set: one host-side (NumPy) container for simulation, segmentation and analysis.

A :class:`RodSet` holds N polyline rods, all vertices concatenated in one ``(V, 3)`` array with
CSR-style ``offsets`` (rod ``r`` owns ``points[offsets[r]:offsets[r+1]]``), a radius per rod,
``units`` (``m``, ``mm``, ``um`` or ``voxel``) and optionally a rest shape, velocities, a
container box and its :class:`Contacts` (the contacts of the packing: touching rod pairs), whose
graph gives contacts per rod and the largest contact cluster (:func:`largest_cluster_fraction`).  Files: ``.npz`` and ``.zarr`` keep everything
(``docs/rodset-format.md``), ``.csv`` keeps ``rod,x,y,z[,radius]``.

>>> from rodwarp.rodset import RodSet, load, detect_contacts
>>> rods = load("centerlines.csv", diameter=0.002, units="m")      # doctest: +SKIP
>>> rods.contacts = detect_contacts(rods)                           # doctest: +SKIP
>>> rods.save("packing.npz")                                        # doctest: +SKIP

This is the input/output layer, under analysis, CT and simulation.  Three public modules hold
what every layer writes: :mod:`rodwarp.rodset.files` (crash-safe file writes: JSON, text, PNG
figures, zarr), :mod:`rodwarp.rodset.trajectory` (a rod set through time: trajectory.zarr,
the ParaView series, checkpoints) and :mod:`rodwarp.rodset.rundir` (output folders owned by
one run: the ``rodwarp-run.json`` manifest).  Nothing here imports warp.
"""

from rodwarp.rodset._formats import save_csv
from rodwarp.rodset._geometry import detect_contacts, segment_closest_params, segment_distance
from rodwarp.rodset._graph import contacts_per_rod, largest_cluster, largest_cluster_fraction
from rodwarp.rodset._rodset import (FORMAT_NAME, FORMAT_VERSION, MAX_COORDINATE, SUPPORTED_SUFFIXES, Contacts, RodSet,
                                    load)
from rodwarp.rodset._units import UNITS, check_units

__all__ = ["RodSet", "Contacts", "load", "UNITS", "FORMAT_NAME", "FORMAT_VERSION", "SUPPORTED_SUFFIXES",
           "MAX_COORDINATE", "detect_contacts", "segment_distance", "segment_closest_params", "contacts_per_rod",
           "largest_cluster", "largest_cluster_fraction", "save_csv", "check_units"]
