"""Read access to a CT volume in memory or on disk (lazy), for every stage of segmentation.

A volume is indexed ``(z, y, x)``; lazy volumes (zarr, a slice stack) are read through an LRU
cache of blocks, so that refining many rods does not re-read or re-decompress.
"""

from __future__ import annotations

import numpy as np

from rodwarp._util import one_line_error as _fail


class _Reader:
    """Uniform read access to an ndarray or a lazy array-like (numpy slicing) volume."""

    def __init__(self, volume):
        shape = getattr(volume, "shape", None)
        if shape is None:
            try:
                volume = np.asarray(volume)
            except Exception as e:  # pragma: no cover - exotic inputs
                raise _fail(f"volume must be an array (z, y, x): {e}") from None
            shape = volume.shape
        shape = tuple(int(s) for s in shape)
        if len(shape) != 3:
            raise _fail(f"volume must be 3-D (z, y, x), got {len(shape)}-D shape {shape}; "
                        f"pass a stack of slices")
        if min(shape) == 0:
            raise _fail(f"volume is empty (shape {shape})")
        dtype = np.dtype(getattr(volume, "dtype", np.float32))
        if dtype.kind not in "biuf":
            raise _fail(f"volume must be numeric, got dtype {dtype}")
        self.vol = volume
        self.shape = shape
        self.in_memory = isinstance(volume, np.ndarray)
        # lazy volumes: gathers go through an LRU cache of blocks (the array's own chunks
        # when it has them), so that refining many rods does not re-read or re-decompress
        ch = getattr(volume, "chunks", None)
        try:
            ch = tuple(int(c) for c in ch) if ch is not None and len(ch) == 3 else None
        except TypeError:
            ch = None
        self.block = tuple(min(s, max(16, min(c, 128))) for s, c in zip(shape, ch or (64, 64, 64)))
        self.cache_bytes = 512 << 20
        self._cache: dict = {}

    def read(self, lo, hi) -> np.ndarray:
        """float32 copy of ``vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]`` (zyx, clamped)."""
        lo = [max(0, int(a)) for a in lo]
        hi = [min(s, int(b)) for s, b in zip(self.shape, hi)]
        a = np.asarray(self.vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
        a = a.astype(np.float32, copy=True)
        if a.size and not np.all(np.isfinite(a)):
            raise _fail("volume contains NaN or inf values; replace them before segmenting")
        return a

    def strided(self, step: int) -> np.ndarray:
        if step <= 1:
            return self.read((0, 0, 0), self.shape)
        try:
            a = np.asarray(self.vol[::step, ::step, ::step])
        except Exception:
            a = np.stack([np.asarray(self.vol[z])[::step, ::step] for z in range(0, self.shape[0], step)])
        a = a.astype(np.float32)
        if a.size and not np.all(np.isfinite(a)):
            raise _fail("volume contains NaN or inf values; replace them before segmenting")
        return a

    def minmax(self) -> tuple[float, float]:
        lo, hi = np.inf, -np.inf
        step = max(1, int(4e6 // max(1, self.shape[1] * self.shape[2])))
        for z in range(0, self.shape[0], step):
            a = self.read((z, 0, 0), (z + step, self.shape[1], self.shape[2]))
            lo, hi = min(lo, float(a.min())), max(hi, float(a.max()))
        return lo, hi

    def gather(self, zyx: np.ndarray) -> np.ndarray:
        """Raw values (float64) at integer voxel coordinates ``zyx`` (n, 3), all inside the volume."""
        if len(zyx) == 0:
            return np.zeros(0)
        if self.in_memory:
            return self.vol[zyx[:, 0], zyx[:, 1], zyx[:, 2]].astype(np.float64)
        out = np.empty(len(zyx))
        bz, by, bx = self.block
        bid = zyx // np.array(self.block)
        key = (bid[:, 0] * ((self.shape[1] + by - 1) // by) + bid[:, 1]) * ((self.shape[2] + bx - 1) // bx) + bid[:, 2]
        order = np.argsort(key, kind="stable")
        ks = key[order]
        cut = np.flatnonzero(np.diff(ks)) + 1
        for grp in np.split(order, cut):
            b = tuple(int(v) for v in bid[grp[0]])
            blk = self._block(b)
            q = zyx[grp] - np.array(b) * np.array(self.block)
            out[grp] = blk[q[:, 0], q[:, 1], q[:, 2]]
        return out

    def _block(self, b):
        blk = self._cache.pop(b, None)
        if blk is None:
            lo = [i * n for i, n in zip(b, self.block)]
            hi = [min(s, l + n) for s, l, n in zip(self.shape, lo, self.block)]
            blk = np.asarray(self.vol[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
            used = sum(v.nbytes for v in self._cache.values())
            while self._cache and used + blk.nbytes > self.cache_bytes:
                old = next(iter(self._cache))  # least recently used
                used -= self._cache.pop(old).nbytes
        self._cache[b] = blk  # (re)inserted last: most recently used
        return blk

    def trilinear(self, xyz: np.ndarray) -> np.ndarray:
        """Raw values (float64) interpolated at points (n, 3) given as (x, y, z); NaN outside."""
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        zyx = xyz[:, ::-1]
        hi = np.asarray(self.shape) - 1
        inside = np.all((zyx >= 0) & (zyx <= hi), axis=1)
        out = np.full(len(zyx), np.nan)
        if not inside.any():
            return out
        q = zyx[inside]
        lo = np.minimum(np.floor(q).astype(np.int64), np.maximum(hi - 1, 0))
        f = q - lo
        val = np.zeros(len(q))
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    w = (f[:, 0] if dz else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1]) * \
                        (f[:, 2] if dx else 1 - f[:, 2])
                    idx = np.minimum(lo + np.array([dz, dy, dx]), hi)
                    val += w * self.gather(idx)
        out[inside] = val
        return out
