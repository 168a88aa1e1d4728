"""Test and benchmark material: not part of rodwarp's API, and not used by rodwarp itself.

* :mod:`rodwarp.testing.reference` - an independent NumPy implementation of the exact local
  fields (clipping, Gauss integral, phi, S, n, contacts), written from the formulas alone and
  sharing no code with :mod:`rodwarp.analysis` or :mod:`rodwarp.kernels`: the tests' oracle
  and the benchmarks' speed peer;
* :mod:`rodwarp.testing.scenes` - small mechanics scenes with analytic answers (cantilevers,
  inclines, ladders, log cabins) for the engine's tests and benchmarks.

It ships inside the package (rather than under ``tests/``) because ``benchmarks/`` uses it
too; nothing under ``rodwarp/`` outside this folder may import it.
"""
