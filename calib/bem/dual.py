"""Forward-mode dual numbers for exact partial derivatives of the BEM equations.

A :class:`Dual` carries a value array ``v`` of shape (n,) and a derivative array
``d`` of shape (n, k): the partials of ``v`` with respect to ``k`` seeded inputs.
The BEM section equations are written once, generically, and evaluated either on
plain arrays (solver iterations) or on duals (sensitivities), so the derivatives
are exact for the implemented equations and never drift from them.
"""

from __future__ import annotations

import numpy as np


class Dual:
    """Value with first derivatives, vectorized over sections."""

    __slots__ = ("v", "d")
    __array_priority__ = 100.0
    __array_ufunc__ = None  # make ndarray (op) Dual defer to Dual's reflected operators

    def __init__(self, v, d):
        self.v = v
        self.d = d

    @staticmethod
    def seed(values, k: int, which: int) -> "Dual":
        v = np.asarray(values, dtype=float)
        d = np.zeros(v.shape + (k,))
        d[..., which] = 1.0
        return Dual(v, d)

    # arithmetic -------------------------------------------------------------
    def __add__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v + o.v, self.d + o.d)
        return Dual(self.v + o, self.d)

    __radd__ = __add__

    def __sub__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v - o.v, self.d - o.d)
        return Dual(self.v - o, self.d)

    def __rsub__(self, o):
        return Dual(o - self.v, -self.d)

    def __neg__(self):
        return Dual(-self.v, -self.d)

    def __mul__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v * o.v, self.d * o.v[..., None] + o.d * self.v[..., None])
        o = np.asarray(o)
        return Dual(self.v * o, self.d * (o[..., None] if o.ndim else o))

    __rmul__ = __mul__

    def __truediv__(self, o):
        if isinstance(o, Dual):
            q = self.v / o.v
            return Dual(q, (self.d - o.d * q[..., None]) / o.v[..., None])
        o = np.asarray(o)
        return Dual(self.v / o, self.d / (o[..., None] if o.ndim else o))

    def __rtruediv__(self, o):
        q = o / self.v
        return Dual(q, -self.d * (q / self.v)[..., None])

    def __pow__(self, n):
        return Dual(self.v ** n, self.d * (n * self.v ** (n - 1))[..., None])

    def _chain(self, value, slope):
        return Dual(value, self.d * slope[..., None])


def _unary(np_func, slope_func):
    def f(x):
        if isinstance(x, Dual):
            return x._chain(np_func(x.v), slope_func(x.v))
        return np_func(x)
    return f


sin = _unary(np.sin, np.cos)
cos = _unary(np.cos, lambda v: -np.sin(v))
exp = _unary(np.exp, np.exp)
log = _unary(np.log, lambda v: 1.0 / v)
sqrt = _unary(np.sqrt, lambda v: 0.5 / np.sqrt(v))
arccos = _unary(np.arccos, lambda v: -1.0 / np.sqrt(1.0 - v * v))
absolute = _unary(np.abs, np.sign)


def where(cond, a, b):
    """Elementwise choice that keeps the derivative of the chosen branch."""
    if not isinstance(a, Dual) and not isinstance(b, Dual):
        return np.where(cond, a, b)
    k = (a if isinstance(a, Dual) else b).d.shape[-1]
    av, ad = (a.v, a.d) if isinstance(a, Dual) else (np.asarray(a, float), np.zeros(np.shape(a) + (k,)))
    bv, bd = (b.v, b.d) if isinstance(b, Dual) else (np.asarray(b, float), np.zeros(np.shape(b) + (k,)))
    return Dual(np.where(cond, av, bv), np.where(np.asarray(cond)[..., None], ad, bd))


def value(x):
    """The value part of a Dual or plain array."""
    return x.v if isinstance(x, Dual) else x
