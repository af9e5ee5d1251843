"""Airfoil polars: tables of C_L, C_D (and C_M) against angle of attack.

Pure data with validation. Smooth interpolation for the BEM lives in
:mod:`calib.bem.polar_grid`; Viterna extrapolation to ±180 deg in
:mod:`calib.rotor.viterna`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.errors import InputError

MIN_POLAR_POINTS = 3  # the NREL 5-MW cylinder polars have 3 rows (-180, 0, 180 deg)


def _as_float_array(values, name: str, source: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"expected numbers, got {values!r} ({exc})", source, field=name) from None
    if arr.ndim != 1:
        raise InputError(f"expected a 1-D sequence, got shape {arr.shape}", source, field=name)
    return arr


@dataclass(frozen=True, eq=False)
class PolarTable:
    """One polar table at one Reynolds number.

    Parameters
    ----------
    alpha_deg : array_like, shape (n_alpha,)
        Angle of attack [deg], strictly increasing.
    cl, cd : array_like, shape (n_alpha,)
        Lift and drag coefficients [-].
    cm : array_like, shape (n_alpha,), optional
        Pitching-moment coefficient about the quarter chord [-].
    reynolds : float
        Chord Reynolds number [-] (absolute, not millions); NaN if unknown.
    source : str
        File or description the table came from (used in error messages).
    first_line : int, optional
        Line of the first table row in ``source`` (1-based), for error messages.
    """

    alpha_deg: np.ndarray
    cl: np.ndarray
    cd: np.ndarray
    cm: np.ndarray | None = None
    reynolds: float = float("nan")
    source: str = "<polar>"
    first_line: int | None = None

    def __post_init__(self):
        src = self.source
        alpha = _as_float_array(self.alpha_deg, "alpha", src)
        cl = _as_float_array(self.cl, "cl", src)
        cd = _as_float_array(self.cd, "cd", src)
        cm = None if self.cm is None else _as_float_array(self.cm, "cm", src)
        n = alpha.size
        for name, arr in (("cl", cl), ("cd", cd)) + ((("cm", cm),) if cm is not None else ()):
            if arr.size != n:
                raise InputError(f"has {arr.size} values but alpha has {n}", src, field=name)
        if n < MIN_POLAR_POINTS:
            raise InputError(f"polar table has {n} rows; at least {MIN_POLAR_POINTS} are needed",
                             src, line=self.first_line, field="alpha")
        for name, arr in (("alpha", alpha), ("cl", cl), ("cd", cd)) + ((("cm", cm),) if cm is not None else ()):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise InputError(f"non-finite value {arr[bad[0]]!r}", src, line=self._line(bad[0]), field=name)
        steps = np.diff(alpha)
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            i = bad[0] + 1
            raise InputError(
                f"alpha must be strictly increasing: {alpha[i]:g} deg follows {alpha[i - 1]:g} deg",
                src, line=self._line(i), field="alpha")
        object.__setattr__(self, "alpha_deg", alpha)
        object.__setattr__(self, "cl", cl)
        object.__setattr__(self, "cd", cd)
        object.__setattr__(self, "cm", cm)
        object.__setattr__(self, "reynolds", float(self.reynolds))

    def _line(self, row: int) -> int | None:
        return None if self.first_line is None else self.first_line + int(row)

    @property
    def covers_full_circle(self) -> bool:
        """True when the table spans -180..180 deg (within 0.5 deg)."""
        return bool(self.alpha_deg[0] <= -179.5 and self.alpha_deg[-1] >= 179.5)


@dataclass(frozen=True, eq=False)
class Airfoil:
    """An airfoil: one or more polar tables, sorted by Reynolds number.

    Parameters
    ----------
    name : str
        Airfoil name (e.g. ``"DU25_A17"``).
    tables : tuple of PolarTable
        At least one table. With several, :meth:`at_reynolds` interpolates linearly
        in Reynolds number (clamped at the ends of the covered range).
    relative_thickness : float
        t/c [-], NaN if unknown.
    """

    name: str
    tables: tuple[PolarTable, ...]
    relative_thickness: float = float("nan")
    notes: str = field(default="", compare=False)

    def __post_init__(self):
        tables = tuple(self.tables)
        if not tables:
            raise InputError("an airfoil needs at least one polar table", self.name, field="tables")
        if len(tables) > 1:
            res = np.array([t.reynolds for t in tables])
            if not np.all(np.isfinite(res)):
                raise InputError("with several tables every table needs a finite Reynolds number",
                                 tables[0].source, field="Re")
            tables = tuple(tables[i] for i in np.argsort(res))
            if np.any(np.diff(np.sort(res)) <= 0):
                raise InputError("two tables have the same Reynolds number", tables[0].source, field="Re")
        object.__setattr__(self, "tables", tables)

    @property
    def reynolds_numbers(self) -> np.ndarray:
        return np.array([t.reynolds for t in self.tables])

    def at_reynolds(self, reynolds: float | None = None) -> PolarTable:
        """The polar at one Reynolds number [-], linear in Re between tables.

        With one table (or ``reynolds=None``) the first/only table is returned.
        Outside the covered range the nearest table is used (no extrapolation in Re).
        """
        if len(self.tables) == 1 or reynolds is None:
            return self.tables[0]
        res = self.reynolds_numbers
        if reynolds <= res[0]:
            return self.tables[0]
        if reynolds >= res[-1]:
            return self.tables[-1]
        k = int(np.searchsorted(res, reynolds)) - 1
        lo, hi = self.tables[k], self.tables[k + 1]
        w = (reynolds - lo.reynolds) / (hi.reynolds - lo.reynolds)
        alpha = np.union1d(lo.alpha_deg, hi.alpha_deg)
        def mix(a, b):
            return (1 - w) * np.interp(alpha, lo.alpha_deg, a) + w * np.interp(alpha, hi.alpha_deg, b)
        cm = None if (lo.cm is None or hi.cm is None) else mix(lo.cm, hi.cm)
        return PolarTable(alpha, mix(lo.cl, hi.cl), mix(lo.cd, hi.cd), cm, reynolds,
                          source=f"{lo.source} + {hi.source} (Re interpolation)")
