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


def usable_cache_dir(path: str) -> str:
    """``path``, created if missing, once a real write there succeeded.

    Warp writes compiled kernels into the cache on the first launch of each module; an
    unusable place would otherwise fail deep inside Warp with an OSError about a file the
    user never named.  Checked once per process, before Warp is initialised.  A read-only
    cache that already holds this Warp version's kernels (a shared installation's) is
    accepted: Warp only reads it.

    Parameters
    ----------
    path : str
        The kernel cache folder (:func:`kernel_cache_dir`).

    Returns
    -------
    str
        ``path``.

    Raises
    ------
    RodwarpError
        One line naming ``RODWARP_KERNEL_CACHE``, what is wrong with the place (a file, not
        writable) and the fix.
    """
    from rodwarp.validation import existing_ancestor, fail, probe_write

    if os.environ.get("RODWARP_KERNEL_CACHE"):
        what, fix = f"RODWARP_KERNEL_CACHE={path}", "unset RODWARP_KERNEL_CACHE or point it at a writable folder"
    else:
        what, fix = f"the kernel cache {path}", "set RODWARP_KERNEL_CACHE to a writable folder"
    base = existing_ancestor(path)
    if not base.is_dir():
        fail(f"{what}: {base} is a file, not a folder, so the kernel cache cannot live there; {fix}")
    try:
        os.makedirs(path, exist_ok=True)
        probe_write(path)
    except OSError as e:
        if not _prebuilt(path):
            fail(f"{what} is not a writable folder ({e.strerror or e}); {fix}")
    return path


def _prebuilt(path: str) -> bool:
    """Whether ``path`` holds kernels built by this Warp version (its ``<version>`` subfolder)."""
    built = os.path.join(path, wp.config.version)
    try:
        return os.path.isdir(built) and bool(os.listdir(built))
    except OSError:
        return False


#: what Warp's native library prints on stderr, once per process, when it finds no NVIDIA driver
#: (warp/native/cuda_util.cpp; no Warp setting turns that probe's message off)
_NO_DRIVER_LINE = "Could not find or load the NVIDIA CUDA driver"


def init() -> None:
    """Configure and initialise Warp once per process (idempotent).

    Warp's native library probes for the NVIDIA driver at initialisation and, on a machine
    without one, prints a "Warp CUDA warning" on stderr.  A CPU machine is a normal place to
    run rodwarp (``--device auto`` picks the CPU there), so that line is dropped; a user who
    asks for ``--device cuda`` gets :func:`resolve_device`'s one-line refusal instead.  Any
    other output of the initialisation is passed on unchanged.
    """
    global _configured
    if _configured:
        return
    wp.config.kernel_cache_dir = usable_cache_dir(kernel_cache_dir())
    wp.config.quiet = True
    # warp >= 1.19 routes its greeting and module-load lines through a logger
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    _init_without_driver_warning()
    _configured = True


def _init_without_driver_warning() -> None:
    """``wp.init()`` with file descriptor 2 caught, and re-emitted without the no-driver line.

    The warning is written by C code (``fprintf(stderr, ...)``), below ``sys.stderr``, so only
    redirecting the descriptor itself catches it.
    """
    import tempfile

    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable descriptor 2 (a daemon): nothing to filter
        wp.init()
        return
    with tempfile.TemporaryFile() as caught:
        try:
            os.dup2(caught.fileno(), 2)
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        caught.seek(0)
        text = caught.read().decode(errors="replace")
    kept = [line for line in text.splitlines(keepends=True) if _NO_DRIVER_LINE not in line]
    if kept:
        sys.stderr.write("".join(kept))
        sys.stderr.flush()


#: the kernel modules a simulation launches (:mod:`rodwarp.kernels`); ``fields`` and ``acn``
#: are the analysis' own and load when it runs
SIMULATION_MODULES = ("packing", "broadphase", "narrowphase", "frames", "elastics", "friction", "wall_contacts",
                      "coloring", "overlap",
                      "solve")


def _module_dir(module, device) -> str:
    """Cache folder Warp compiles ``module`` into for ``device`` (``wp_<name>_<hash>``).

    The hash depends on the block size the module is built for: 1 for a CPU launch (Warp's
    default there), the module's own ``block_dim`` on a GPU.
    """
    dev = wp.get_device(device)
    block_dim = 1 if dev.is_cpu else module.options["block_dim"]
    return os.path.join(wp.config.kernel_cache_dir, module.get_module_identifier(block_dim))


def cold_modules(device: str, names=SIMULATION_MODULES) -> list:
    """The Warp modules among ``rodwarp.kernels.<names>`` not yet compiled in the kernel cache.

    Parameters
    ----------
    device : str
        Warp device name (``cpu``, ``cuda:0``), as :func:`resolve_device` returns.
    names : sequence of str
        Modules of :mod:`rodwarp.kernels`.

    Returns
    -------
    list of warp Module
        Those whose cache folder is missing or empty (Warp builds a module in a private folder
        and renames it into place, so a folder that exists holds a complete build).
    """
    import importlib

    from warp._src.context import get_module

    init()
    out = []
    for name in names:
        importlib.import_module(f"rodwarp.kernels.{name}")
        module = get_module(f"rodwarp.kernels.{name}")
        path = _module_dir(module, device)
        if not (os.path.isdir(path) and os.listdir(path)):
            out.append(module)
    return out


def load_kernels(device: str, names=SIMULATION_MODULES, *, progress: bool = True) -> bool:
    """Compile (first run) or load the kernel modules of ``names`` for ``device`` now.

    Warp compiles a module at its first launch, which on the first run left a progress bar
    at t = 0 for tens of seconds with no word why.  When a module is missing from the kernel
    cache this says so on stderr, once, before compiling, and (with ``progress``) shows a bar
    over the modules; with every module cached it prints nothing and leaves the loading to
    the first launch, as before.

    Parameters
    ----------
    device : str
        Warp device name, as :func:`resolve_device` returns.
    names : sequence of str
        Modules of :mod:`rodwarp.kernels`.
    progress : bool
        Show a bar over the modules being compiled (the one-line notice is printed either way:
        it explains the wait even in a ``--quiet`` run).

    Returns
    -------
    bool
        Whether anything had to be compiled.
    """
    cold = cold_modules(device, names)
    if not cold:
        return False
    # no duration promised: it depends on the machine and the device (19 s for the nine CPU
    # modules of the default simulate on this project's two-core machine)
    print(f"compiling Warp kernels (first run; later runs load them from {wp.config.kernel_cache_dir})",
          file=sys.stderr, flush=True)
    from rodwarp._util import progress_bar

    with progress_bar(progress) as update:
        update("compiling kernels", 0, len(cold), note=None)
        for k, module in enumerate(cold):
            wp.load_module(module, device=device)
            update("compiling kernels", k + 1, len(cold))
    return True


def resolve_device(device: str | None) -> str:
    """Map ``auto|cpu|cuda|cuda:N`` to a Warp device name, with a clear error.

    Raises
    ------
    TypeError
        ``device`` is not a string (nor None, which means ``auto``).
    RodwarpError
        An unknown device, or CUDA asked for where none is available.
    """
    from rodwarp.errors import RodwarpError, RodwarpTypeError

    if device is not None and not isinstance(device, str):
        raise RodwarpTypeError(f"device must be a string (auto, cpu, cuda or cuda:N), got {type(device).__name__} "
                               f"{device!r}")
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
