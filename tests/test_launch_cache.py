"""Recorded launches replay exactly what wp.launch would do."""

import numpy as np
import warp as wp

from rodwarp import _warp
from rodwarp._warp import LaunchCache
from rodwarp.kernels.structs import StepParams

_warp.init()


@wp.kernel
def axpy(a: wp.float64, n: int, p: StepParams, x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    if i < n:
        y[i] = a * x[i] + p.dt


def test_replayed_launches_follow_changed_scalars_dims_struct_fields_and_arrays():
    cache = LaunchCache(size=4)
    x = wp.array(np.arange(8.0), dtype=wp.float64)
    y = wp.zeros(8, dtype=wp.float64)
    p = StepParams()
    p.dt = wp.float64(0.5)
    cache.launch(axpy, 8, "cpu", [wp.float64(2.0), 8, p, x, y])
    np.testing.assert_array_equal(y.numpy(), 2.0 * np.arange(8.0) + 0.5)
    # new scalar values, a smaller launch, a changed struct field: all seen by the replay
    p.dt = wp.float64(-1.0)
    y.zero_()
    cache.launch(axpy, 4, "cpu", [wp.float64(3.0), np.int32(3), p, x, y])
    np.testing.assert_array_equal(y.numpy(), np.r_[3.0 * np.arange(3.0) - 1.0, np.zeros(5)])
    assert cache.hits == 1 and cache.misses == 1
    # another array is another launch
    z = wp.zeros(8, dtype=wp.float64)
    cache.launch(axpy, 8, "cpu", [1.0, 8, p, x, z])
    np.testing.assert_array_equal(z.numpy(), np.arange(8.0) - 1.0)
    assert cache.misses == 2


def test_the_cache_forgets_the_least_recently_used_launch():
    cache = LaunchCache(size=2)
    x = wp.array(np.ones(4), dtype=wp.float64)
    ys = [wp.zeros(4, dtype=wp.float64) for _ in range(3)]
    p = StepParams()
    for y in ys:
        cache.launch(axpy, 4, "cpu", [1.0, 4, p, x, y])
    assert len(cache._cmds) == 2
    cache.launch(axpy, 4, "cpu", [1.0, 4, p, x, ys[0]])  # forgotten: recorded again
    assert cache.misses == 4
