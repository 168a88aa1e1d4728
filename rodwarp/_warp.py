"""Warp initialisation shared by every rodwarp entry point.

The kernel cache lives inside the active Python environment (``sys.prefix``) so that
repeated runs and CI reuse compiled kernels instead of recompiling, and so that deleting
the environment deletes the cache with it. ``RODWARP_KERNEL_CACHE`` overrides the place.
"""

from __future__ import annotations

import os
import sys

import warp as wp

_configured = False


def kernel_cache_dir() -> str:
    """Directory where Warp keeps compiled kernels for rodwarp."""
    return os.environ.get("RODWARP_KERNEL_CACHE") or os.path.join(
        sys.prefix, "share", "rodwarp", "warp-kernel-cache"
    )


def init() -> None:
    """Configure and initialise Warp once per process (idempotent)."""
    global _configured
    if _configured:
        return
    wp.config.kernel_cache_dir = kernel_cache_dir()
    wp.config.quiet = True
    # warp >= 1.19 routes its greeting and module-load lines through a logger
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    wp.init()
    _configured = True


def resolve_device(device: str | None) -> str:
    """Map ``auto|cpu|cuda|cuda:N`` to a Warp device name, with a clear error."""
    from rodwarp.errors import RodwarpError

    init()
    name = (device or "auto").lower()
    if name == "auto":
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    if name == "cpu":
        return "cpu"
    if name.startswith("cuda"):
        if not wp.is_cuda_available():
            raise RodwarpError(
                f"device '{device}' asked for but no CUDA device is available; use --device cpu or auto"
            )
        return "cuda:0" if name == "cuda" else name
    raise RodwarpError(f"unknown device '{device}'; use auto, cpu or cuda")


class LaunchCache:
    """Replays recorded kernel launches instead of packing their arguments again.

    ``wp.launch`` spends tens of microseconds per call checking and packing arguments, about
    as long as a small scene's kernel runs. A step launches the same kernels on the same
    arrays every time, so the first launch of a kernel with given array and struct arguments
    is recorded (``record_cmd=True``) and later ones only update what changed: the launch
    dimension and scalar arguments (by value). Arrays and structs are matched by identity;
    the cache holds a reference to each, so an identity is never reused while its entry
    lives, and a struct's fields are read at every launch (Warp copies them at invoke), so
    changing a cached struct's fields is seen.

    Parameters
    ----------
    size : int
        Most recorded launches kept (least recently used dropped first).
    """

    def __init__(self, size: int = 512):
        from collections import OrderedDict

        self.size = int(size)
        self._cmds: OrderedDict = OrderedDict()
        self.hits = 0
        self.misses = 0

    #: how each argument type is matched: 0 by identity, 1 by value, 2 by the tuple of a
    #: vector's or matrix's entries, 3 by a warp scalar's value (wp.float64(x)), 4 by a NumPy
    #: scalar's value
    _kinds: dict = {}

    @classmethod
    def _kind(cls, a) -> int:
        import ctypes

        import numpy as np

        if isinstance(a, (bool, int, float)):
            return 1
        if isinstance(a, np.generic):
            return 4
        if isinstance(a, ctypes.Array):
            return 2
        if hasattr(a, "value") and not isinstance(a, wp.array) and isinstance(a.value, (bool, int, float)):
            return 3
        return 0

    def _values(self, inputs) -> list:
        """A hashable value per by-value argument, None for those matched by identity."""
        kinds = self._kinds
        out = []
        for a in inputs:
            k = kinds.get(type(a))
            if k is None:
                k = kinds[type(a)] = self._kind(a)
            out.append(None if k == 0 else a if k == 1 else tuple(a) if k == 2 else a.value if k == 3 else a.item())
        return out

    def launch(self, kernel, dim, device, inputs) -> None:
        """``wp.launch(kernel, dim=dim, device=device, inputs=inputs)``, replayed when recorded."""
        values = self._values(inputs)
        key = (id(kernel), str(device), tuple(id(a) if v is None else None for a, v in zip(inputs, values)))
        entry = self._cmds.get(key)
        if entry is None:
            self.misses += 1
            cmd = wp.launch(kernel, dim=dim, device=device, inputs=list(inputs), record_cmd=True)
            self._cmds[key] = [cmd, tuple(inputs), dim, values]
            if len(self._cmds) > self.size:
                self._cmds.popitem(last=False)
        else:
            self.hits += 1
            self._cmds.move_to_end(key)
            cmd, _, old_dim, old_values = entry
            if dim != old_dim:
                cmd.set_dim(dim)
                entry[2] = dim
            for i, v in enumerate(values):
                if v is not None and v != old_values[i]:
                    cmd.set_param_at_index(i, inputs[i])
                    old_values[i] = v
        cmd.launch()
