"""One integer key per cell of a regular grid: for remembering points once per cell (a static
surface is hit by the rays again every step)."""

from __future__ import annotations

import numpy as np

CELL_OFFSET = 1 << 20
"""Cells are numbered from here in each axis (about 5 km either side of the origin at 5 mm
cells), so the three numbers fit in one 63-bit key."""


def cell_keys(points: np.ndarray, size: float) -> np.ndarray:
    """The key of the ``size``-sized cell each of ``points`` (n, 3) lies in, shape (n,)."""
    cells = np.floor(np.asarray(points, dtype=float) / size).astype(np.int64) + CELL_OFFSET
    return (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]
