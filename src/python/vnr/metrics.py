"""Quality metrics of a volume against a reference, exactly as `vnr eval` computes them.

Both arrays are in original units with the same shape (nz, ny, nx). The reference is normalised as vnr
normalises a volume (its finite min/max, or value_range, mapping to [0, 1], clamped); the other array
is mapped with the same range, unclamped, as `vnr eval` compares a model's output.
"""
from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

from ._vnr import _error_stats, _ssim

__all__ = ["psnr", "ssim", "mse", "max_abs_error"]


def _pair(a, b):
    a = np.ascontiguousarray(a)
    b = np.ascontiguousarray(b)
    if a.shape != b.shape:
        raise ValueError(f"the arrays differ in shape: {a.shape} and {b.shape}")
    return a, b


def psnr(a, b, value_range: Optional[Tuple[float, float]] = None) -> float:
    """PSNR in dB of b against the reference a: 10 log10(1 / mse) over normalised values (999 when they
    are equal), as `vnr eval` reports it."""
    return _error_stats(*_pair(a, b), value_range)[0]


def mse(a, b, value_range: Optional[Tuple[float, float]] = None) -> float:
    """Mean squared error over normalised values (`vnr eval --report`'s "mse")."""
    return _error_stats(*_pair(a, b), value_range)[1]


def max_abs_error(a, b, value_range: Optional[Tuple[float, float]] = None) -> float:
    """Largest absolute difference over normalised values."""
    return _error_stats(*_pair(a, b), value_range)[2]


def ssim(a, b, value_range: Optional[Tuple[float, float]] = None) -> float:
    """Mean 3-D SSIM (7x7x7 uniform window, K1 = 0.01, K2 = 0.03) of b against a, as `vnr eval`."""
    return _ssim(*_pair(a, b), value_range)
