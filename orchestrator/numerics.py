"""Small numerical helpers shared by scenes and analyses (no heavy imports: scenes use them)."""
from __future__ import annotations

import math

import numpy as np


def running_mean(x: np.ndarray, rows: int, mode: str = "same") -> np.ndarray:
    """Running mean over windows of ``rows`` consecutive samples — the one running mean of the
    project (the triaxial curves and the scene's shear-stage summary both use it). Centred
    (``same``) windows are the means of every run of ``rows`` consecutive samples, so their extremes
    equal those of ``valid`` windows: the smoothed peaks of the triaxial summary and analysis agree.

    mode : ``"same"``: one value per sample, windows centred (an even window is centred half a row
        early) and kept inside the series, so the first and last ``rows // 2`` values use the
        window at the end (same length as ``x``); ``"valid"``: the mean of every full window,
        ``len(x) - rows + 1`` values (the mean of all of ``x`` when it is shorter than one window).
    """
    x = np.asarray(x, float)
    rows = max(int(rows), 1)
    c = np.concatenate([[0.0], np.cumsum(x)])
    if mode == "valid":
        if x.size < rows:
            return np.array([np.mean(x)])
        return (c[rows:] - c[:-rows]) / rows
    if mode != "same":
        raise ValueError(f"running_mean mode must be 'same' or 'valid', got {mode!r}")
    if rows == 1 or x.size == 0:
        return x.copy()
    k = np.arange(x.size)
    lo = np.clip(k - rows // 2, 0, x.size)
    hi = np.clip(lo + rows, 0, x.size)
    lo = np.clip(hi - rows, 0, x.size)
    return (c[hi] - c[lo]) / (hi - lo)


#: contiguous blocks of a correlated series that :func:`block_sem` and :func:`block_drift` average
BLOCKS = 8


def block_sem(x: np.ndarray, blocks: int = BLOCKS) -> float:
    """Standard error of the mean of a correlated series (a steady-state window of μ_macro) from
    ``blocks`` contiguous block means (fewer when the series is shorter): blocks longer than the
    correlation time are nearly independent. NaN with fewer than two blocks. Unit: that of ``x``."""
    x = np.asarray(x, float)
    nb = min(int(blocks), x.size)
    if nb < 2:
        return float("nan")
    bm = np.array([b.mean() for b in np.array_split(x, nb)])
    return float(bm.std(ddof=1) / np.sqrt(nb))


def block_drift(x: np.ndarray, blocks: int = BLOCKS) -> tuple[float, float]:
    """(drift, its standard error) of a correlated series across its length, unit that of ``x``:
    a straight line fitted to ``blocks`` contiguous block means (as :func:`block_sem`), its change
    from the first block's centre to the last's, with the slope's standard error from the block
    means' scatter about the line (ordinary least squares). A steady series drifts by less than
    about two standard errors. NaN with fewer than three blocks."""
    x = np.asarray(x, float)
    nb = min(int(blocks), x.size)
    if nb < 3:
        return float("nan"), float("nan")
    bm = np.array([b.mean() for b in np.array_split(x, nb)])
    k = np.arange(nb, dtype=float)
    slope, icpt = np.polyfit(k, bm, 1)
    resid = bm - (icpt + slope * k)
    se = math.sqrt(float(resid @ resid) / (nb - 2) / float(((k - k.mean()) ** 2).sum()))
    return float(slope * (nb - 1)), float(se * (nb - 1))


def multiple_of(n: int, k: int) -> int:
    """``n`` rounded up to a multiple of ``k`` (both positive integers). The scenes put restart steps
    at the end of a wall-averaging window (LIGGGHTS fix ave/time): a run resumed there writes every
    window, while one straddling the restart step would be skipped by the resumed fix (measured: one
    row lost per resume)."""
    return -(-int(n) // int(k)) * int(k)
