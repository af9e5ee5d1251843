"""Numbers in words for reports and messages."""

from __future__ import annotations

import math

#: p-values below this are written as "< 1e-16": double precision cannot tell them apart from 0.
P_FLOOR = 1e-16


def p_text(p: float) -> str:
    """A p-value for a reader: two significant digits, "< 1e-16" below the float floor (never "0")."""
    p = float(p)
    if math.isnan(p):
        return "n/a"
    return f"< {P_FLOOR:.0e}" if p < P_FLOOR else f"{p:.2g}"


def p_is(p: float) -> str:
    """"p = 0.031" or "p < 1e-16", for a sentence."""
    text = p_text(p)
    return f"p {text}" if text.startswith("<") else f"p = {text}"
