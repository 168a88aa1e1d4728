"""The encodings a binarised CT stack is shared in: a boolean mask -> a two-level stack.

Used by the segmentation tests and ``scripts/bad_inputs.py`` to check that every encoding of
one mask is recognised and segmented alike (docs/segmentation.md, "Binarised stacks").
"""

from __future__ import annotations

import numpy as np

#: name -> (mask -> stack); the brighter level holds the rods
ENCODINGS = {
    "bool": lambda m: m,
    "uint8 0/1": lambda m: m.astype(np.uint8),
    "uint8 0/255": lambda m: (m * 255).astype(np.uint8),
    "uint16 100/3000": lambda m: np.where(m, 3000, 100).astype(np.uint16),
    "float32 -1/1": lambda m: np.where(m, 1.0, -1.0).astype(np.float32),
}
#: name -> the two grey levels of that encoding (background, rods)
LEVELS = {"bool": [0, 1], "uint8 0/1": [0, 1], "uint8 0/255": [0, 255], "uint16 100/3000": [100, 3000],
          "float32 -1/1": [-1, 1]}
