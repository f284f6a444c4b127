"""Small numerical helpers shared by scenes and analyses (no heavy imports: scenes use them)."""
from __future__ import annotations

import numpy as np


def running_mean(x, rows: int) -> np.ndarray:
    """Centred running mean over ``rows`` samples, every window full length (shifted inwards at
    the ends; the whole series when it is shorter than ``rows``). Its values are the means of
    every run of ``rows`` consecutive samples, so its extremes equal those of a 'valid'
    convolution: the smoothed peaks of the triaxial summary and of the triaxial analysis agree."""
    x = np.asarray(x, float)
    rows = max(int(rows), 1)
    if rows == 1 or x.size == 0:
        return x.copy()
    c = np.concatenate([[0.0], np.cumsum(x)])
    k = np.arange(x.size)
    lo = np.clip(k - rows // 2, 0, x.size)
    hi = np.clip(lo + rows, 0, x.size)
    lo = np.clip(hi - rows, 0, x.size)
    return (c[hi] - c[lo]) / (hi - lo)


def multiple_of(n: int, k: int) -> int:
    """``n`` rounded up to a multiple of ``k`` (both positive integers). The scenes put restart steps
    at the end of a wall-averaging window (LIGGGHTS fix ave/time): a run resumed there writes every
    window, while one straddling the restart step would be skipped by the resumed fix (measured: one
    row lost per resume)."""
    return -(-int(n) // int(k)) * int(k)
