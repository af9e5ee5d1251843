"""Operating schedules a power curve is computed under, solved for one parameter vector.

Three kinds, chosen by name (:data:`SCHEDULE_KINDS`):

- ``variable_speed``: a variable-speed, pitch-to-feather turbine (the rotor's
  :class:`~calib.rotor.geometry.OperatingSchedule`). Region 2 at the tip-speed ratio of maximum
  C_P at fine pitch *of the model at hand* (``tsr_rule="optimal"``: re-found for every parameter
  vector, so the calibrated polars move it) or at the schedule's design value
  (``tsr_rule="design"``, as :func:`calib.bem.steady_control.steady_power_curve`), within the
  rotor-speed limits; region 3 at rated aerodynamic power by pitch (Jonkman et al., NREL/TP-500-38060, §7).
- ``fixed_speed``: one rotor speed and one pitch at every wind speed (a stall-regulated rotor
  such as the NREL Phase VI at 72 rpm and 3°).
- ``table``: rotor speed and pitch interpolated in a user table of wind speed.

Every solve goes through ``solve(p, conditions) -> BemResult`` (:meth:`calib.models.bem_model.BemModel.solve`)
batched over the wind speeds; the point status of every BEM solve is kept (never dropped).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["FixedSpeed", "ScheduledCurve", "SCHEDULE_KINDS", "TableSchedule", "VariableSpeed", "schedule_from_table"]

#: Status of a bin whose region-3 pitch did not reach rated power within the iteration limit.
PITCH_NOT_CONVERGED = 90
#: The tip-speed ratios the optimal λ is searched on, in units of the design λ (13 points, ±35 %) [-].
TSR_GRID = np.linspace(0.65, 1.35, 13)


@dataclass(frozen=True, eq=False)
class ScheduledCurve:
    """One power curve: the schedule solved for one parameter vector.

    Attributes
    ----------
    wind_speed, rotor_speed, pitch : ndarray, shape (n_bins,)
        [m/s], [rpm], [deg].
    power, thrust : ndarray, shape (n_bins,)
        Aerodynamic power [W] and rotor thrust [N]; NaN where ``status != 0``.
    cp, ct : ndarray, shape (n_bins,)
        [-].
    status : ndarray of int, shape (n_bins,)
        0 converged; the BEM's status, or :data:`PITCH_NOT_CONVERGED`.
    region : ndarray of int, shape (n_bins,)
        2 (speed tracking or fixed), 3 (pitched to rated power).
    tsr_opt : float
        Tip-speed ratio tracked in region 2 [-] (NaN for fixed-speed and table schedules).
    n_points : int
        BEM points solved to make the curve.
    """

    wind_speed: np.ndarray
    rotor_speed: np.ndarray
    pitch: np.ndarray
    power: np.ndarray
    thrust: np.ndarray
    cp: np.ndarray
    ct: np.ndarray
    status: np.ndarray
    region: np.ndarray
    tsr_opt: float = float("nan")
    n_points: int = 0

    @property
    def ok(self) -> np.ndarray:
        return self.status == 0


def _curve(v, rpm, pitch, res, region, tsr_opt, n_points, status=None):
    st = res.status.copy() if status is None else status
    bad = st != 0
    nan = lambda x: np.where(bad, np.nan, x)  # noqa: E731
    return ScheduledCurve(v, rpm, pitch, nan(res.power), nan(res.thrust), nan(res.cp), nan(res.ct), st, region,
                          tsr_opt, n_points)


@dataclass(frozen=True)
class FixedSpeed:
    """One rotor speed [rpm] and pitch [deg] at every wind speed (stall-regulated or fixed-pitch rotor)."""

    rotor_speed: float
    pitch: float
    generator_efficiency: float = 1.0
    kind: str = "fixed_speed"

    def solve(self, solve, p, wind_speed, air_density, guess=None, pitch_hint=None) -> ScheduledCurve:
        v = np.asarray(wind_speed, float)
        rpm, pitch = np.full(v.shape, float(self.rotor_speed)), np.full(v.shape, float(self.pitch))
        res = solve(p, OperatingConditions(v, rpm, pitch, air_density))
        return _curve(v, rpm, pitch, res, np.full(v.shape, 2), float("nan"), v.size)

    def setting(self, v):
        """Rotor speed [rpm] and pitch [deg] at the wind speeds ``v`` [m/s]."""
        return np.full(v.shape, float(self.rotor_speed)), np.full(v.shape, float(self.pitch))

    def describe(self) -> str:
        return f"fixed speed {self.rotor_speed:g} rpm, pitch {self.pitch:g}°"


@dataclass(frozen=True)
class TableSchedule:
    """Rotor speed and pitch interpolated (linearly, held at the ends) in a table of wind speed."""

    wind_speed: tuple
    rotor_speed: tuple
    pitch: tuple
    source: str = "table"
    generator_efficiency: float = 1.0
    kind: str = "table"

    def solve(self, solve, p, wind_speed, air_density, guess=None, pitch_hint=None) -> ScheduledCurve:
        v = np.asarray(wind_speed, float)
        rpm = np.interp(v, self.wind_speed, self.rotor_speed)
        pitch = np.interp(v, self.wind_speed, self.pitch)
        res = solve(p, OperatingConditions(v, rpm, pitch, air_density))
        return _curve(v, rpm, pitch, res, np.full(v.shape, 2), float("nan"), v.size)

    def setting(self, v):
        """Rotor speed [rpm] and pitch [deg] at the wind speeds ``v`` [m/s]."""
        return np.interp(v, self.wind_speed, self.rotor_speed), np.interp(v, self.wind_speed, self.pitch)

    def describe(self) -> str:
        return f"user table {self.source} ({len(self.wind_speed)} rows)"


def schedule_from_table(path) -> TableSchedule:
    """A :class:`TableSchedule` from a CSV with columns ``wind_speed`` [m/s], ``rotor_speed`` [rpm], ``pitch`` [deg].

    Raises
    ------
    InputError
        Missing file or column, a non-numeric cell, fewer than two rows or wind speeds not increasing.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"schedule table not found: {path}", "--schedule", field="schedule")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    need = ("wind_speed", "rotor_speed", "pitch")
    if not rows or any(k not in rows[0] for k in need):
        raise InputError(f"the schedule table needs the columns {', '.join(need)}; it has "
                         f"{', '.join(rows[0]) if rows else 'none'}", str(path), field="schedule")
    try:
        cols = {k: tuple(float(r[k]) for r in rows) for k in need}
    except (TypeError, ValueError) as exc:
        raise InputError(f"a cell of the schedule table is not a number ({exc})", str(path), field="schedule")
    v = np.array(cols["wind_speed"])
    if v.size < 2 or np.any(np.diff(v) <= 0):
        raise InputError("the schedule table needs at least two rows of increasing wind_speed", str(path),
                         field="schedule")
    return TableSchedule(cols["wind_speed"], cols["rotor_speed"], cols["pitch"], str(path))


@dataclass(frozen=True)
class VariableSpeed:
    """Variable-speed, pitch-to-feather schedule (region 2 / region 3).

    Parameters
    ----------
    rated_power : float
        Rated aerodynamic power [W].
    min_rotor_speed, max_rotor_speed : float
        [rpm]
    design_tsr : float
        Design tip-speed ratio [-]; with ``tsr_rule="optimal"`` the centre of the search.
    fine_pitch : float
        [deg]
    rotor_radius : float
        [m]
    tsr_rule : str
        ``"optimal"`` (region 2 at the model's own C_P-maximizing λ at fine pitch) or ``"design"``.
    generator_efficiency : float
        Electrical / aerodynamic power [-].
    pitch_tol_power : float
        Relative tolerance of rated power above rated [-].
    """

    rated_power: float
    min_rotor_speed: float
    max_rotor_speed: float
    design_tsr: float
    fine_pitch: float
    rotor_radius: float
    tsr_rule: str = "optimal"
    generator_efficiency: float = 1.0
    pitch_tol_power: float = 1e-4
    max_pitch: float = 45.0
    kind: str = "variable_speed"

    @classmethod
    def from_rotor(cls, rotor, tsr_rule: str = "optimal") -> "VariableSpeed":
        s = rotor.schedule
        if s is None:
            raise InputError("the rotor has no operating schedule: give --schedule fixed (with --rotor-speed "
                             "and --pitch) or a table CSV", rotor.source, field="schedule")
        if not 0 < s.min_rotor_speed <= s.max_rotor_speed or not s.rated_power > 0:
            raise InputError(f"the rotor's schedule cannot be followed: rotor speed limits {s.min_rotor_speed:g}–"
                             f"{s.max_rotor_speed:g} rpm, rated power {s.rated_power:g} W (need 0 < min <= max, "
                             "rated > 0)", rotor.source, field="schedule")
        if np.isfinite(s.cut_in) and s.cut_in > 0:
            need = s.design_tsr * s.cut_in / float(rotor.rotor_radius) * 30 / np.pi
            if s.max_rotor_speed < need * (1 - 1e-9):
                raise InputError(f"the rotor's schedule cannot be followed: the speed limit {s.max_rotor_speed:g} rpm is "
                                 f"below the {need:.4g} rpm the design tip-speed ratio {s.design_tsr:g} asks at cut-in "
                                 f"({s.cut_in:g} m/s, R = {float(rotor.rotor_radius):g} m); a limit in rad/s instead of "
                                 "rpm?", rotor.source, field="schedule.max_rotor_speed")
        if tsr_rule not in ("optimal", "design"):
            raise InputError(f"unknown tsr rule {tsr_rule!r}; valid: optimal, design", "VariableSpeed",
                             field="tsr_rule")
        return cls(s.rated_power, s.min_rotor_speed, s.max_rotor_speed, s.design_tsr, s.fine_pitch,
                   float(rotor.rotor_radius), tsr_rule, s.generator_efficiency)

    def check_reachable(self, wind_speed, air_density, source: str = "schedule") -> None:
        """Refuse a rated power the rotor cannot produce in the bins: above the Betz limit
        16/27 · ½ρπR²V³ at the highest bin (Betz 1920; no rotor exceeds it).

        Raises
        ------
        InputError
            Naming the rated power, the Betz power and the highest bin.
        """
        v_max = float(np.max(wind_speed))
        betz = 16 / 27 * 0.5 * air_density * np.pi * self.rotor_radius ** 2 * v_max ** 3
        if self.rated_power > betz:
            raise InputError(f"the rated power {self.rated_power / 1e6:.4g} MW is above what the rotor can produce in the "
                             f"bins: the Betz limit at the highest bin {v_max:g} m/s is {betz / 1e6:.4g} MW "
                             f"(R = {self.rotor_radius:g} m, ρ = {air_density:g} kg/m³); check the rated power's unit",
                             source, field="schedule.rated_power")

    def describe(self) -> str:
        lam = ("the C_P-maximizing tip-speed ratio of each parameter vector (re-found per draw)"
               if self.tsr_rule == "optimal" else f"the design tip-speed ratio {self.design_tsr:g}")
        return (f"variable speed: region 2 at {lam} within {self.min_rotor_speed:g}–{self.max_rotor_speed:g} rpm, "
                f"fine pitch {self.fine_pitch:g}°; region 3 at rated aerodynamic power "
                f"{self.rated_power / 1e6:.4g} MW by pitch")

    def optimal_tsr(self, solve, p, air_density) -> tuple[float, int]:
        """λ of maximum C_P at fine pitch [-] on the design λ × :data:`TSR_GRID`, refined by a parabola; BEM points."""
        lam = self.design_tsr * TSR_GRID
        omega = self.max_rotor_speed * np.pi / 30
        res = solve(p, OperatingConditions(omega * self.rotor_radius / lam, np.full(lam.size, self.max_rotor_speed),
                                           np.full(lam.size, self.fine_pitch), air_density))
        cp = np.where(res.ok, res.cp, -np.inf)
        k = int(np.argmax(cp))
        if not np.isfinite(cp[k]):
            return float("nan"), lam.size
        if 0 < k < lam.size - 1 and np.all(np.isfinite(cp[k - 1:k + 2])):
            x, y = lam[k - 1:k + 2], cp[k - 1:k + 2]
            a, b, _ = np.polyfit(x, y, 2)
            if a < 0:
                return float(np.clip(-b / (2 * a), x[0], x[2])), lam.size
        return float(lam[k]), lam.size

    def solve(self, solve, p, wind_speed, air_density, guess=None, pitch_hint=None) -> ScheduledCurve:
        """The schedule at parameters ``p``.

        ``guess`` (a :class:`ScheduledCurve`, e.g. the central one) starts the region-3 pitch search;
        without it the pitch is bracketed by bisection. ``pitch_hint`` = (pitch [deg], dP/dβ [W/deg]),
        arrays over the bins (NaN where unknown; e.g. the central pitch moved by the linearized
        dβ/dp, :func:`calib.powercurve.linearized.delta_method`), replaces the guess's pitch and takes
        the first step by Newton instead of a 0.5° probe; the search still iterates to the tolerance.
        """
        v = np.asarray(wind_speed, float)
        n_points = 0
        if self.tsr_rule == "optimal":
            tsr, n_points = self.optimal_tsr(solve, p, air_density)
            if not np.isfinite(tsr):
                tsr = self.design_tsr      # every point of the search failed: the status below says so
        else:
            tsr = self.design_tsr
        rpm = np.clip(tsr * v / self.rotor_radius * 30 / np.pi, self.min_rotor_speed, self.max_rotor_speed)
        pitch = np.full(v.shape, float(self.fine_pitch))
        res = solve(p, OperatingConditions(v, rpm, pitch, air_density))
        n_points += v.size
        above, rated = np.flatnonzero(res.ok & (res.power > self.rated_power)), None
        if above.size:
            g = None if guess is None else np.interp(v[above], guess.wind_speed, guess.pitch)
            slope = None
            if pitch_hint is not None and g is not None:
                hint_pitch, slope = (np.asarray(x, float)[above] for x in pitch_hint)
                g = np.where(np.isfinite(hint_pitch), hint_pitch, g)
            b, r, ok, n = self.pitch_to_rated(solve, p, v[above], rpm[above], air_density, g, slope)
            n_points += n
            rated = (b, r, ok)
        power, thrust, cp, ct, status, region = scheduled_arrays(res, pitch, above, rated)
        return ScheduledCurve(v, rpm, pitch, power, thrust, cp, ct, status, region, tsr, n_points)

    def pitch_to_rated(self, solve, p, v, rpm, rho, guess, slope=None, max_iter=12, per_point=False):
        """Pitch [deg] at which the aerodynamic power equals rated, per point (vectorized).

        Without a guess: bisection on [fine pitch, max pitch] to 0.05°, then secant steps from its
        bracket. With a guess: from the guess, a first step by Newton with ``slope`` (dP/dβ [W/deg],
        where finite and negative) or a 0.5° probe, then secant steps. Only the points not yet within
        ``pitch_tol_power`` are solved again; a point at a pitch limit whose next step points out of
        the range again stops there (not converged). Returns the pitch, the BEM result at it (a
        :class:`_Rows`), whether |P / P_rated − 1| ≤ ``pitch_tol_power`` and the number of points solved.
        With ``per_point``, ``p`` is an array over the points (a batched solve's draw index per point,
        :func:`calib.powercurve.batch.batched_solver`) and is indexed like the points.
        """
        n_pts = 0
        P_r, tol = self.rated_power, self.pitch_tol_power * self.rated_power
        n = v.size

        def f(beta, k):
            nonlocal n_pts
            n_pts += beta.size
            return solve(p[k] if per_point else p, OperatingConditions(v[k], rpm[k], beta, rho))

        every = np.arange(n)
        b_old, y_old = np.full(n, np.nan), np.full(n, np.nan)
        if guess is None:
            lo, hi = np.full(n, float(self.fine_pitch)), np.full(n, self.max_pitch)
            while np.max(hi - lo) > 0.05:
                mid = 0.5 * (lo + hi)
                r = f(mid, every)
                too_much = ~r.ok | (r.power > P_r)
                lo, hi = np.where(too_much, mid, lo), np.where(too_much, hi, mid)
            r = f(np.concatenate([lo, hi]), np.concatenate([every, every]))
            b_old, y_old, b = lo, r.power[:n] - P_r, hi
            rows = _Rows.of(r, slice(n, None))
        else:
            b = np.clip(np.asarray(guess, float), self.fine_pitch, self.max_pitch)
            rows = _Rows.of(f(b, every), slice(None))
        y = rows.power - P_r
        slope = np.full(n, np.nan) if slope is None else np.asarray(slope, float)
        stuck = np.zeros(n, bool)
        for _ in range(max_iter):
            a = np.flatnonzero((rows.status == 0) & (np.abs(y) > tol) & ~stuck)
            if not a.size:
                break
            d = y[a] - y_old[a]
            secant = np.isfinite(d) & (np.abs(d) > 1e-9 * P_r)
            newton = ~secant & np.isfinite(slope[a]) & (slope[a] < 0)
            step = np.where(secant, -y[a] * (b[a] - b_old[a]) / np.where(secant, d, 1.0),
                            np.where(newton, -y[a] / np.where(newton, slope[a], -1.0), 0.5))
            b2 = np.clip(b[a] + np.clip(step, -5.0, 5.0), self.fine_pitch, self.max_pitch)
            # at a pitch limit and the step points out of the range again: rated power is not
            # reachable from here (e.g. power rising with pitch in deep stall); the point stops
            out = (b2 == b[a]) & ((b2 == self.fine_pitch) | (b2 == self.max_pitch))
            stuck[a[out]] = True
            a, b2 = a[~out], b2[~out]
            if not a.size:
                break
            r = f(b2, a)
            b_old[a], y_old[a] = b[a], y[a]
            b[a], y[a] = b2, r.power - P_r
            rows.put(a, r)
        ok = (rows.status == 0) & (np.abs(y) <= tol)
        return b, rows, ok, n_pts


@dataclass(eq=False)
class _Rows:
    """Power, thrust, C_P, C_T and status of some points, updated in place by index."""

    power: np.ndarray
    thrust: np.ndarray
    cp: np.ndarray
    ct: np.ndarray
    status: np.ndarray

    @classmethod
    def of(cls, res, sl) -> "_Rows":
        return cls(res.power[sl].copy(), res.thrust[sl].copy(), res.cp[sl].copy(), res.ct[sl].copy(),
                   res.status[sl].copy())

    def put(self, k, res) -> None:
        for name in ("power", "thrust", "cp", "ct", "status"):
            getattr(self, name)[k] = getattr(res, name)


SCHEDULE_KINDS = {"variable_speed": VariableSpeed, "fixed_speed": FixedSpeed, "table": TableSchedule}
"""Schedule kinds by name."""


def scheduled_arrays(res, pitch: np.ndarray, above: np.ndarray, rated=None) -> tuple:
    """Power [W], thrust [N], C_P, C_T, status, region (2/3) per point: ``res`` solved at fine pitch, the points
    ``above`` rated from ``rated`` = (pitch [deg], result, converged) of the pitch search (``pitch`` updated in
    place); failed points NaN (:data:`PITCH_NOT_CONVERGED` where the pitch search did not converge)."""
    power, thrust, cp, ct = res.power.copy(), res.thrust.copy(), res.cp.copy(), res.ct.copy()
    status = res.status.copy()
    region = np.full(status.shape, 2)
    if rated is not None:
        b, r, ok = rated
        pitch[above] = b
        power[above], thrust[above], cp[above], ct[above] = r.power, r.thrust, r.cp, r.ct
        status[above] = np.where(r.status != 0, r.status, np.where(ok, 0, PITCH_NOT_CONVERGED))
        region[above] = 3
    bad = status != 0
    for x in (power, thrust, cp, ct):
        x[bad] = np.nan
    return power, thrust, cp, ct, status, region
