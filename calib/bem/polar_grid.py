"""Smooth, vectorized polar look-up for all blade stations at once.

Each station's polar (the airfoil table at the station's Reynolds number, extended
to ±180 deg when needed) is resampled once on a uniform α grid as values and slopes
of a shape-preserving cubic (PCHIP, Fritsch & Carlson 1980) through the table. A
look-up is then a cubic Hermite evaluation on that grid, gathered by station index:
no Python loop over stations, C¹-continuous in α, with exact α-derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator, RectBivariateSpline

from calib.rotor.geometry import Rotor
from calib.rotor.polar import PolarTable
from calib.types import STANDARD_AIR_DENSITY

GRID_STEP_DEG = 0.25


def _full_circle(table: PolarTable) -> PolarTable:
    if table.covers_full_circle:
        return table
    from calib.rotor.viterna import extrapolate_viterna
    return extrapolate_viterna(table)


AIR_KINEMATIC_VISCOSITY = 1.81e-5 / STANDARD_AIR_DENSITY
"""Kinematic viscosity of air at 15 °C and 1.225 kg/m^3 [m^2/s]."""


def station_reynolds(rotor: Rotor, kinematic_viscosity: float = AIR_KINEMATIC_VISCOSITY) -> np.ndarray | None:
    """Reference chord Reynolds number Re = W c / ν per station [-] at the design tip-speed ratio
    and rated rotor speed of the rotor's schedule (used only for airfoils with several tables).

    Parameters
    ----------
    rotor : Rotor
    kinematic_viscosity : float
        ν of the fluid [m^2/s].
    """
    if rotor.schedule is None:
        return None
    omega = rotor.schedule.max_rotor_speed * np.pi / 30.0
    w = omega * rotor.r * np.sqrt(1.0 + (1.0 / rotor.schedule.design_tsr * rotor.tip_radius / rotor.r) ** 2)
    return w * rotor.chord / kinematic_viscosity


def station_tables(rotor: Rotor, kinematic_viscosity: float = AIR_KINEMATIC_VISCOSITY) -> list[PolarTable]:
    """The polar table of every station (Reynolds-interpolated where an airfoil has several)."""
    re = station_reynolds(rotor, kinematic_viscosity)
    out = []
    for i, af in enumerate(rotor.airfoil_id):
        airfoil = rotor.airfoils[af]
        table = airfoil.at_reynolds(None if (re is None or len(airfoil.tables) == 1) else float(re[i]))
        out.append(_full_circle(table))
    return out


def tabulate_polars(rotor: Rotor, step_deg: float = GRID_STEP_DEG):
    """Station polars on a uniform α grid covering [-180, 180] deg.

    Returns
    -------
    alpha_grid_deg : ndarray, shape (n_grid,)
    cl, cd : ndarray, shape (n_stations, n_grid)
        Coefficient values [-] on the grid.
    """
    grid = SectionPolars.from_rotor(rotor, step_deg)
    return grid.alpha_grid_deg, grid.cl_nodes.copy(), grid.cd_nodes.copy()


@dataclass(frozen=True, eq=False)
class SectionPolars:
    """Cubic-Hermite look-up tables of C_L, C_D for every station.

    Attributes
    ----------
    alpha_grid_deg : ndarray, shape (n_grid,)
        Uniform grid from -180 to 180 deg.
    cl_nodes, cd_nodes : ndarray, shape (n_stations, n_grid)
        Values at the grid nodes [-].
    cl_slopes, cd_slopes : ndarray, shape (n_stations, n_grid)
        dC/dα at the grid nodes [1/deg].
    """

    alpha_grid_deg: np.ndarray
    cl_nodes: np.ndarray
    cd_nodes: np.ndarray
    cl_slopes: np.ndarray
    cd_slopes: np.ndarray

    @classmethod
    def from_rotor(cls, rotor: Rotor, step_deg: float = GRID_STEP_DEG,
                   smoothing: tuple[float, float] | None = None,
                   kinematic_viscosity: float = AIR_KINEMATIC_VISCOSITY) -> "SectionPolars":
        """Build the tables.

        Parameters
        ----------
        rotor : Rotor
        step_deg : float
            Grid step [deg].
        smoothing : (s_cl, s_cd), optional
            Replace the shape-preserving interpolant by a smoothing cubic spline in α [rad]
            with these residual-sum bounds (scipy ``RectBivariateSpline(..., s=...)`` over the
            table duplicated at two Reynolds numbers), the polar treatment of CCBlade's
            ``CCAirfoil`` (s = 0.01 for C_L and 0.001 for C_D in WISDEM 4.2.9, "to prevent
            spurious multiple solutions"). Use ``(0.01, 0.001)`` to reproduce CCBlade tables;
            the default (None) interpolates the data exactly.
        kinematic_viscosity : float
            ν of the fluid [m^2/s], for the Reynolds number of airfoils with several tables.
        """
        n = int(round(360.0 / step_deg))
        grid = np.linspace(-180.0, 180.0, n + 1)
        tables = station_tables(rotor, kinematic_viscosity)
        cache: dict[int, tuple] = {}
        rows = []
        for t in tables:
            key = id(t)
            if key not in cache:
                vals = []
                inside = (grid >= t.alpha_deg[0]) & (grid <= t.alpha_deg[-1])
                a = np.clip(grid, t.alpha_deg[0], t.alpha_deg[-1])
                for y, s in zip((t.cl, t.cd), smoothing or (None, None)):
                    if s is None:
                        f = PchipInterpolator(t.alpha_deg, y, extrapolate=True)
                        vals.append((f(a), np.where(inside, f.derivative()(a), 0.0)))
                    else:
                        rad = np.radians(t.alpha_deg)
                        spl = RectBivariateSpline(rad, [1e1, 1e15], np.c_[y, y],
                                                  kx=min(rad.size - 1, 3), ky=1, s=s)
                        ar = np.radians(a)
                        vals.append((spl.ev(ar, 1e6), np.where(inside, spl.ev(ar, 1e6, dx=1), 0.0)
                                     * np.pi / 180.0))
                cache[key] = (vals[0][0], vals[1][0], vals[0][1], vals[1][1])
            rows.append(cache[key])
        cl, cd, dcl, dcd = (np.array([r[j] for r in rows]) for j in range(4))
        return cls(grid, cl, cd, dcl, dcd)

    @property
    def step_deg(self) -> float:
        return float(self.alpha_grid_deg[1] - self.alpha_grid_deg[0])

    def lookup(self, alpha_deg, station):
        """C_L, C_D and their slopes at angles ``alpha_deg`` for stations ``station``.

        Parameters
        ----------
        alpha_deg : ndarray, shape (n,)
            Angle of attack [deg]; wrapped periodically into [-180, 180).
        station : ndarray of int, shape (n,)
            Station index of each entry.

        Returns
        -------
        cl, cd : ndarray, shape (n,)
            [-]
        dcl, dcd : ndarray, shape (n,)
            Slopes [1/deg].
        """
        h = self.step_deg
        a = np.mod(np.asarray(alpha_deg, float) + 180.0, 360.0)
        x = a / h
        i = np.minimum(x.astype(np.intp), self.alpha_grid_deg.size - 2)
        t = x - i
        t2, t3 = t * t, t * t * t
        h00, h10, h01, h11 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t, -2 * t3 + 3 * t2, t3 - t2
        d00, d10, d01, d11 = 6 * t2 - 6 * t, 3 * t2 - 4 * t + 1, -6 * t2 + 6 * t, 3 * t2 - 2 * t
        out = []
        for nodes, slopes in ((self.cl_nodes, self.cl_slopes), (self.cd_nodes, self.cd_slopes)):
            y0, y1 = nodes[station, i], nodes[station, i + 1]
            m0, m1 = slopes[station, i] * h, slopes[station, i + 1] * h
            out.append((h00 * y0 + h10 * m0 + h01 * y1 + h11 * m1,
                        (d00 * y0 + d10 * m0 + d01 * y1 + d11 * m1) / h))
        (cl, dcl), (cd, dcd) = out
        return cl, cd, dcl, dcd
