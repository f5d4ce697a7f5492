"""Series decimated for display: per column the extremes, so no peak is lost, and floats rounded
for JSON. Shared by the report's plots and its 3D view's clearance plot."""

from __future__ import annotations

import numpy as np

#: Display columns after decimation.
COLUMNS = 600


def envelope(x: np.ndarray, y: np.ndarray, bins: int = COLUMNS) -> tuple[list, list]:
    """Decimate one series over increasing ``x``: per bin of equal width in x the samples
    holding its smallest and its largest value, in x order, so no peak is lost (NaN: a gap).
    Returns (x, y) lists, rounded."""
    if len(x) <= 2 * bins:
        keep = np.arange(len(x))
    else:
        starts = np.unique(np.r_[0, np.searchsorted(x, np.linspace(x[0], x[-1], bins + 1)[1:-1])])
        starts = starts[starts < len(x)]
        bin_of = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, len(x)]))
        picks = []
        for fill, reduce in ((np.inf, np.minimum), (-np.inf, np.maximum)):
            data = np.where(np.isnan(y), fill, y)
            hits = np.flatnonzero(data == reduce.reduceat(data, starts)[bin_of])
            picks.append(hits[np.unique(bin_of[hits], return_index=True)[1]])
        keep = np.unique(np.concatenate(picks))
    return rounded(x[keep], 7), rounded(y[keep])


def rounded(values: np.ndarray, digits: int = 4) -> list:
    """Floats with ``digits`` significant digits; NaN and infinities as None (JSON null)."""
    values = np.asarray(values, dtype=float)
    finite = np.isfinite(values)
    scale = np.where(finite & (values != 0), 10.0 ** (digits - 1 - np.floor(np.log10(np.abs(np.where(
        finite & (values != 0), values, 1.0))))), 1.0)
    rounded = np.round(values * scale) / scale
    return [float(v) if ok else None for v, ok in zip(rounded, finite, strict=True)]
