"""Validation material: what the tests and benchmarks check rodwarp against, and what a user
calls to check rodwarp on their own rods and device (docs/validation.md, "Checking rodwarp
yourself"; examples/check_fields.py). rodwarp itself never uses it.

* :mod:`rodwarp.testing.reference` - an independent NumPy implementation of the exact local
  fields (clipping, Gauss integral, phi, S, n, contacts), written from the formulas alone and
  sharing no code with :mod:`rodwarp.analysis` or :mod:`rodwarp.kernels`: the tests' oracle,
  the benchmarks' speed peer, and a user's check of the Warp fields on another device;
* :mod:`rodwarp.testing.binarised` - the encodings a binarised CT stack is shared in (bool,
  0/1, 0/255, any two values), for the segmentation's checks of binarised input;
* :mod:`rodwarp.testing.scenes` - small mechanics scenes with analytic answers (cantilevers,
  inclines, ladders, log cabins) for the engine's tests and benchmarks;
* :mod:`rodwarp.testing.ct_generator` - a second CT phantom generator, sharing no code with
  ``rodwarp phantom`` (touching bundles of thin rods, wire tangles; analytic partial volume, a
  tailed point-spread function, Poisson noise, beam hardening, rings), so that segmentation is
  scored on data it was not tuned on.

It ships inside the package (rather than under ``tests/``) because users and ``benchmarks/``
call it too; nothing under ``rodwarp/`` outside this folder imports it.
"""
