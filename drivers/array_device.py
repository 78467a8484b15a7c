"""A device that streams arrays already in memory: counts made by a program (the gap benchmark's
richer simulator, a notebook) become a recording through the same recorder as any front-end."""

from __future__ import annotations

import numpy as np

from .base import Device
from .block import Block, StreamInfo


class ArrayDevice(Device):
    """Stream ``counts`` (int32, n_channels x n) with ``scale`` (n_channels,) SI per count at
    ``fs_hz`` in blocks of ``block_s`` seconds. ``gages`` are the report gage numbers of the
    rows, ``rig_toml`` the rig's text, ``extra`` what ``StreamInfo.extra`` should say."""

    kind = "array"

    def __init__(self, counts: np.ndarray, scale: np.ndarray, fs_hz: float, *, gages: tuple[int, ...],
                 rig_toml: str = "", extra: dict | None = None, block_s: float = 0.25) -> None:
        super().__init__()
        counts = np.asarray(counts)
        if counts.dtype != np.int32 or counts.ndim != 2:
            raise ValueError(f"array device: counts must be 2-D int32, got {counts.dtype} {counts.shape}")
        if len(gages) != counts.shape[0] or len(scale) != counts.shape[0]:
            raise ValueError(f"array device: {counts.shape[0]} rows but {len(gages)} gages and "
                             f"{len(scale)} scales")
        self.counts, self.scale = counts, np.asarray(scale, dtype=np.float64)
        self.fs_hz, self.gages, self.rig_toml = float(fs_hz), tuple(gages), rig_toml
        self.extra = dict(extra or {})
        self.block_n = max(1, int(round(block_s * fs_hz)))
        self._pos = 0
        self._seq = 0

    def _open(self) -> StreamInfo:
        names = tuple(f"g{g:02d}" for g in self.gages)
        return StreamInfo("array", self.fs_hz, names, ("m/s^2",) * len(names), self.gages,
                          self.rig_toml, self.extra)

    def _read(self, timeout: float | None) -> Block | None:
        if self._pos >= self.counts.shape[1]:
            return None
        a, b = self._pos, min(self._pos + self.block_n, self.counts.shape[1])
        blk = Block(self._seq, a, int(round(a * 1e9 / self.fs_hz)), self.fs_hz,
                    np.ascontiguousarray(self.counts[:, a:b]), self.scale)
        self._pos, self._seq = b, self._seq + 1
        return blk
