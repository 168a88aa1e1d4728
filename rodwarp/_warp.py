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
