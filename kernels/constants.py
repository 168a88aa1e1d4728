"""Float64 constants of the device code, written once (a literal in a float64 expression must
carry its type, or Warp takes it as float32)."""

import warp as wp

F0 = wp.float64(0.0)
F1 = wp.float64(1.0)
HALF = wp.float64(0.5)
TWO = wp.float64(2.0)
THREE = wp.float64(3.0)
#: the gap of a contact out of reach: larger than any length, finite so that sums stay finite
FAR = wp.float64(1.0e299)
