"""Float comparisons that hold on any x86-64 CPU.

Bit-for-bit equality of computed floats depends on the CPU's vector width, the BLAS kernel
and summation orders, none of which the code pins down. Outside the one case where the same
code path runs twice on the same machine (an FMU reset and restored), tests compare with a
tolerance of a few units in the last place (ulps) of each column's magnitude.
"""

from __future__ import annotations

import numpy as np

#: Units in the last place allowed by :func:`assert_same_numbers`.
ULPS = 4


def assert_same_numbers(actual, desired, ulps: int = ULPS, err_msg: str = "") -> None:
    """Assert ``actual`` equals ``desired`` to ``ulps`` units in the last place.

    The tolerance is relative to each element and, for elements near zero, to the largest
    magnitude of its column (the last axis of a 2-D or higher array; the whole array
    otherwise), so a channel of small values is judged on its own scale.

    Parameters
    ----------
    actual, desired : array_like
        Arrays of the same shape.
    ulps : int
        Allowed difference in units of the last place (machine epsilon × magnitude).
    err_msg : str
        Added to the failure message.
    """
    actual, desired = np.asarray(actual, float), np.asarray(desired, float)
    assert actual.shape == desired.shape, f"shapes differ: {actual.shape} vs {desired.shape} {err_msg}"
    eps = ulps * np.finfo(float).eps
    mag = np.abs(np.where(np.isfinite(desired), desired, 0.0))
    scale = mag.max(axis=0, keepdims=True) if desired.ndim >= 2 else mag.max(initial=0.0)
    tol = eps * np.maximum(mag, scale)
    same_nan = np.isnan(actual) & np.isnan(desired)
    bad = ~same_nan & ~(np.abs(actual - desired) <= tol) & ~(actual == desired)
    if np.any(bad):
        k = tuple(np.argwhere(bad)[0])
        raise AssertionError(f"{int(bad.sum())} of {bad.size} values differ by more than {ulps} ulps; first at "
                             f"{k}: {actual[k]!r} vs {desired[k]!r} {err_msg}")
