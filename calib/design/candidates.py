"""Candidate operating points of a campaign design: the operating envelope, a user grid or one
generated inside the envelope, fixed points matched to candidates, and a space-filling design of
the same size to compare against.

A candidate is a steady operating point (wind speed, rotor speed, pitch, air density, yaw). The
envelope is the box of tip-speed ratio λ = ΩR/V, pitch, rotor speed and yaw the workflow's data
(its measured table or its ``[conditions]`` grid) span: no candidate lies outside it, since the
model, its correction nodes and the noise model were set up there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.errors import InputError
from calib.types import CONDITION_FIELDS, OperatingConditions

__all__ = ["Envelope", "envelope_of", "generate", "user_grid", "check_inside", "match_points", "space_filling",
           "parse_range"]

#: Relative slack of the envelope checks (rounding of a stated grid).
SLACK = 1e-6


@dataclass(frozen=True)
class Envelope:
    """The operating envelope: closed ranges (low, high).

    Attributes
    ----------
    tsr : tuple
        Tip-speed ratio λ [-].
    pitch : tuple
        [deg]
    rotor_speed : tuple
        [rpm]
    yaw : tuple
        [deg]
    air_density : float
        [kg/m³] of the generated candidates.
    radius : float
        Rotor radius [m].
    """

    tsr: tuple
    pitch: tuple
    rotor_speed: tuple
    yaw: tuple
    air_density: float
    radius: float

    def words(self) -> str:
        """The envelope in words."""
        def r(x, unit):
            return f"{x[0]:.4g}" + (f"–{x[1]:.4g}" if x[1] > x[0] else "") + unit
        return (f"λ {r(self.tsr, '')}, pitch {r(self.pitch, ' deg')}, rotor speed {r(self.rotor_speed, ' rpm')}, "
                f"yaw {r(self.yaw, ' deg')}")


def envelope_of(conditions: OperatingConditions, radius: float) -> Envelope:
    """The box the operating points ``conditions`` span, for a rotor of ``radius`` [m]."""
    lam = conditions.tip_speed_ratio(radius)

    def span(a):
        a = np.asarray(a, float)[np.isfinite(a)]
        return (float(a.min()), float(a.max()))
    return Envelope(span(lam), span(conditions.pitch), span(conditions.rotor_speed), span(conditions.yaw),
                    float(np.median(conditions.air_density)), float(radius))


def _points(env: Envelope, lam, pitch, rpm, yaw) -> OperatingConditions:
    L, P, W, Y = (a.ravel() for a in np.meshgrid(lam, pitch, rpm, yaw, indexing="ij"))
    return OperatingConditions(W * np.pi / 30.0 * env.radius / L, W, P, env.air_density, Y)


def generate(env: Envelope, n_tsr: int = 25, n_pitch: int = 16, n_rotor_speed: int = 1) -> OperatingConditions:
    """A λ × pitch (× rotor speed) grid spanning the envelope, at its median yaw; a range of zero
    width gives one value. n_tsr · n_pitch · n_rotor_speed points (fewer where a range is a point)."""
    def axis(r, k):
        return np.array([r[0]]) if r[1] <= r[0] else np.linspace(r[0], r[1], max(int(k), 1))
    yaw = np.array([0.5 * (env.yaw[0] + env.yaw[1])])
    return _points(env, axis(env.tsr, n_tsr), axis(env.pitch, n_pitch), axis(env.rotor_speed, n_rotor_speed), yaw)


def parse_range(text: str, key: str, source: str = "--grid") -> np.ndarray:
    """``START:STOP:STEP`` (inclusive) or ``a,b,c`` as values; an :class:`InputError` naming ``key`` otherwise."""
    t = str(text).strip()
    try:
        if ":" in t:
            a, b, s = (float(x) for x in t.split(":"))
            if not s > 0 or b < a:
                raise ValueError
            return np.arange(a, b + 0.5 * s, s)
        vals = np.array([float(x) for x in t.split(",") if x.strip()], float)
        if vals.size == 0 or not np.all(np.isfinite(vals)):
            raise ValueError
        return vals
    except ValueError:
        raise InputError(f"{key} = {text!r}: expected START:STOP:STEP (STEP > 0, STOP >= START) or a list a,b,c",
                         source, field=key) from None


GRID_KEYS = ("tsr", "pitch", "rotor_speed", "wind_speed", "yaw")


def user_grid(spec: dict, env: Envelope, source: str = "--grid") -> OperatingConditions:
    """The candidates of a stated grid: ``tsr`` × ``pitch`` or ``wind_speed`` × ``rotor_speed`` × ``pitch``,
    each × ``yaw`` optionally; rotor speed and yaw default to the envelope's (its low end), pitch must be given.

    Parameters
    ----------
    spec : dict key -> str or sequence
        Keys of :data:`GRID_KEYS`; a value is a range text (:func:`parse_range`) or numbers.
    env : Envelope
    source : str
        Named in errors.
    """
    unknown = [k for k in spec if k not in GRID_KEYS]
    if unknown:
        raise InputError(f"unknown grid key {unknown[0]!r}; expected some of {', '.join(GRID_KEYS)}", source,
                         field=unknown[0])
    vals = {k: (parse_range(v, k, source) if isinstance(v, str) else np.atleast_1d(np.asarray(v, float)))
            for k, v in spec.items()}
    if "pitch" not in vals:
        raise InputError("a candidate grid needs pitch (and tsr, or wind_speed with rotor_speed)", source,
                         field="pitch")
    if ("tsr" in vals) == ("wind_speed" in vals):
        raise InputError("give exactly one of tsr and wind_speed in a candidate grid", source, field="tsr")
    rpm = vals.get("rotor_speed", np.array([env.rotor_speed[0]]))
    yaw = vals.get("yaw", np.array([env.yaw[0]]))
    if "tsr" in vals:
        return _points(env, vals["tsr"], vals["pitch"], rpm, yaw)
    V, W, P, Y = (a.ravel() for a in np.meshgrid(vals["wind_speed"], rpm, vals["pitch"], yaw, indexing="ij"))
    return OperatingConditions(V, W, P, env.air_density, Y)


def check_inside(cond: OperatingConditions, env: Envelope, source: str = "candidates") -> None:
    """Refuse a candidate outside the envelope, naming the first one and the range it leaves."""
    quantities = {"tsr": cond.tip_speed_ratio(env.radius), "pitch": cond.pitch, "rotor_speed": cond.rotor_speed,
                  "yaw": cond.yaw}
    units = {"tsr": "", "pitch": " deg", "rotor_speed": " rpm", "yaw": " deg"}
    for key, x in quantities.items():
        lo, hi = getattr(env, key)
        tol = SLACK * max(1.0, abs(lo), abs(hi))
        bad = np.flatnonzero(~((x >= lo - tol) & (x <= hi + tol)))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"candidate {k + 1} has {key} {x[k]:.4g}{units[key]}, outside the operating envelope "
                             f"{lo:.4g}–{hi:.4g}{units[key]} ({bad.size} candidate(s) outside; envelope: "
                             f"{env.words()})", source, line=k + 1, field=key)


def _coordinates(cond: OperatingConditions, radius: float) -> np.ndarray:
    """(λ, pitch, rotor speed, yaw) per point, shape (n, 4)."""
    return np.column_stack([cond.tip_speed_ratio(radius), cond.pitch, cond.rotor_speed, cond.yaw])


def match_points(points: OperatingConditions, candidates: OperatingConditions, radius: float,
                 source: str = "fixed points") -> np.ndarray:
    """The candidate index of each point (same λ, pitch, rotor speed, yaw within 1e-6 relative);
    an :class:`InputError` naming the first point that is no candidate and the nearest one."""
    P, C = _coordinates(points, radius), _coordinates(candidates, radius)
    span = np.maximum(np.ptp(C, axis=0), 1e-9 * np.maximum(1.0, np.abs(C).max(axis=0)))
    out = np.empty(len(points), int)
    for k, p in enumerate(P):
        d = np.max(np.abs(C - p) / span, axis=1)
        j = int(np.argmin(d))
        if d[j] > SLACK:
            c = C[j]
            raise InputError(f"fixed point {k + 1} (λ {p[0]:.4g}, pitch {p[1]:.4g} deg, rotor speed {p[2]:.4g} rpm, "
                             f"yaw {p[3]:.4g} deg) is not a candidate; the nearest is λ {c[0]:.4g}, pitch "
                             f"{c[1]:.4g} deg, rotor speed {c[2]:.4g} rpm, yaw {c[3]:.4g} deg", source, line=k + 1)
        out[k] = j
    return out


def space_filling(cond: OperatingConditions, radius: float, n: int, mask=None) -> np.ndarray:
    """``n`` candidates spread evenly over the (λ, pitch, rotor speed, yaw) box, each coordinate scaled
    to [0, 1]: the farthest-point (maximin) sequence from the candidate nearest the centre: the
    "uniform design of the same size" a design is compared with."""
    X = _coordinates(cond, radius)
    span = np.ptp(X, axis=0)
    X = (X - X.min(axis=0)) / np.where(span > 0, span, 1.0)
    ok = np.ones(len(X), bool) if mask is None else np.asarray(mask, bool)
    idx = np.flatnonzero(ok)
    first = idx[int(np.argmin(np.sum((X[idx] - 0.5) ** 2, axis=1)))]
    chosen = [int(first)]
    d = np.sum((X - X[first]) ** 2, axis=1)
    d[~ok] = -1.0
    for _ in range(min(n, idx.size) - 1):
        j = int(np.argmax(d))
        chosen.append(j)
        d = np.minimum(d, np.sum((X - X[j]) ** 2, axis=1))
        d[~ok] = -1.0
        d[chosen] = -1.0
    return np.array(chosen, int)


def concatenate(parts) -> OperatingConditions:
    """One OperatingConditions of several, in order."""
    return OperatingConditions(*(np.concatenate([np.broadcast_to(getattr(c, f), (len(c),)) for c in parts])
                                 for f in CONDITION_FIELDS))
