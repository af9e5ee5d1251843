"""Rotor data for the FMU's ``resources/`` folder, written from a :class:`~calib.rotor.geometry.Rotor`.

The FMU reads ``resources/rotor.dat`` (format documented in
``fmu_models/core/rotor_data.c`` and ``fmu_models/README.md``) and the adapter reads
``resources/correction_grid.json`` to know where the correction nodes are.

The polars are those of the native BEM: :func:`calib.bem.polar_grid.tabulate_polars`
evaluated on a uniform α grid over -180..180 deg, so that the FMU (linear
interpolation on that grid) and the BEM use the same coefficients.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.rotor.geometry import Rotor

#: Default correction grid of the FMUs: α nodes [deg] spanning attached flow to deep
#: stall (where calibrations find the largest corrections) and η nodes over the blade.
DEFAULT_ALPHA_NODES_DEG = (-10.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0)
DEFAULT_ETA_NODES = (0.2, 0.4, 0.6, 0.8, 1.0)

#: Spanwise positions η = r/R of the spanwise outputs (nearest station is used).
OUTPUT_ETAS = (0.3, 0.5, 0.7, 0.9)

#: Tower-top height below the hub [m] when the rotor does not say (NREL 5-MW: 90 - 87.6 m).
TOWER_TOP_BELOW_HUB = 2.4

POLAR_STEP_DEG = 0.25


def default_grid() -> CorrectionGrid:
    """The FMUs' default correction grid (7 α nodes x 5 η nodes)."""
    return CorrectionGrid(np.array(DEFAULT_ALPHA_NODES_DEG), np.array(DEFAULT_ETA_NODES))


def zero_lift_angles(alpha_deg: np.ndarray, cl: np.ndarray) -> np.ndarray:
    """Zero-lift angle of attack per station [deg] (for the stall-delay models).

    Parameters
    ----------
    alpha_deg : ndarray, shape (n_grid,)
        Angle-of-attack grid [deg].
    cl : ndarray, shape (n_stations, n_grid)
        Lift coefficients [-].

    Returns
    -------
    ndarray, shape (n_stations,)
        The first upward zero crossing of C_L in [-20, 10] deg; 0 where there is none
        (e.g. a cylinder, where the stall-delay models do nothing anyway).
    """
    out = np.zeros(cl.shape[0])
    window = (alpha_deg >= -20.0) & (alpha_deg <= 10.0)
    a = alpha_deg[window]
    for i, row in enumerate(cl[:, window]):
        k = np.flatnonzero((row[:-1] <= 0.0) & (row[1:] > 0.0))
        if k.size:
            j = k[-1]
            out[i] = a[j] - row[j] * (a[j + 1] - a[j]) / (row[j + 1] - row[j])
    return out


def output_stations(rotor: Rotor, etas=OUTPUT_ETAS) -> np.ndarray:
    """Indices of the stations nearest to ``etas`` (distinct, interior) [-]."""
    interior = np.flatnonzero((rotor.r > rotor.hub_radius * (1 + 1e-9)) & (rotor.r < rotor.tip_radius * (1 - 1e-9)))
    idx = []
    for eta in etas:
        j = interior[np.argmin(np.abs(rotor.r[interior] / rotor.tip_radius - eta))]
        if j not in idx:
            idx.append(int(j))
    return np.array(idx, dtype=int)


def station_geometry(rotor: Rotor) -> dict:
    """Blade axis and spanwise integration weights per station, exactly as the native BEM.

    Returns
    -------
    dict of ndarray, shape (n_stations,)
        ``x_az``, ``y_az``, ``z_az`` [m] and ``cone`` [rad] from
        :func:`calib.bem.kinematics.curvature`; ``thrust``, ``torque``, ``flap_root`` weights
        from :func:`calib.bem.solver.integration_weights` (zero at stations on the hub or
        tip) and the path-length weight ``ds`` [m] (for the modal forces).
    """
    from calib.bem.kinematics import curvature
    from calib.bem.solver import integration_weights
    x_az, y_az, z_az, cone, _ = curvature(rotor.r, rotor.precurve, rotor.presweep,
                                          np.radians(rotor.precone_deg))
    w = integration_weights(rotor)
    cone_w = np.cos(cone)
    ds = np.divide(w["thrust"], cone_w, out=np.zeros_like(cone_w), where=cone_w != 0)
    return {"x_az": x_az, "y_az": y_az, "z_az": z_az, "cone": cone, "ds": ds,
            "thrust": w["thrust"], "torque": w["torque"], "flap_root": w["flap_root"]}


def tabulated_polars(rotor: Rotor, step_deg: float = POLAR_STEP_DEG):
    """The native BEM's station polars on a uniform grid over [-180, 180] deg.

    Returns
    -------
    alpha_deg : ndarray, shape (n_grid,)
    cl, cd : ndarray, shape (n_stations, n_grid)
    """
    from calib.bem.polar_grid import tabulate_polars
    alpha, cl, cd = tabulate_polars(rotor, step_deg)
    alpha = np.asarray(alpha, float)
    step = np.diff(alpha)
    if not np.allclose(step, step[0], rtol=1e-9, atol=1e-12):  # resample onto a uniform grid
        uniform = np.linspace(-180.0, 180.0, int(round(360.0 / step_deg)) + 1)
        cl = np.array([np.interp(uniform, alpha, row) for row in cl])
        cd = np.array([np.interp(uniform, alpha, row) for row in cd])
        alpha = uniform
    if alpha[0] > -180.0 + 1e-9 or alpha[-1] < 180.0 - 1e-9:
        raise InputError(f"tabulated polars cover {alpha[0]:g}..{alpha[-1]:g} deg; the FMU needs -180..180",
                         rotor.source, field="airfoils")
    return alpha, np.asarray(cl, float), np.asarray(cd, float)


def rotor_resource_text(rotor: Rotor, grid: CorrectionGrid) -> str:
    """The text of ``rotor.dat`` for ``rotor`` and ``grid``."""
    if not np.isfinite(rotor.hub_height):
        raise InputError("the FMU needs a finite hub height (shear, tower shadow)", rotor.source,
                         field="hub_height")
    if rotor.n_stations > 96 or grid.n_lift > 512 or max(grid.n_alpha, grid.n_eta) > 64:
        raise InputError("the FMU supports at most 96 stations, 64 nodes per axis and 512 nodes",
                         rotor.source, field="r")
    alpha, cl, cd = tabulated_polars(rotor)
    alpha0 = zero_lift_angles(alpha, cl)
    out_idx = output_stations(rotor)
    geometry = station_geometry(rotor)
    f = lambda x: repr(float(x))  # noqa: E731  (round-trip exact)
    lines = ["calib_rotor_resource 1",
             f"# written by calib.fmu.resources from rotor '{rotor.name}' ({rotor.source})",
             f"name {rotor.name.replace(' ', '_') or 'rotor'}",
             f"n_blades {rotor.n_blades}",
             f"hub_radius {f(rotor.hub_radius)}", f"tip_radius {f(rotor.tip_radius)}",
             f"precone_deg {f(rotor.precone_deg)}", f"tilt_deg {f(rotor.tilt_deg)}",
             f"hub_height {f(rotor.hub_height)}",
             f"n_stations {rotor.n_stations}",
             "# r [m] chord [m] twist [deg] alpha0 [deg] x_az y_az z_az [m] cone [rad] ds [m] "
             "w_thrust [m] w_torque [m^2] w_root [m^2]"]
    for i in range(rotor.n_stations):
        row = (rotor.r[i], rotor.chord[i], rotor.twist_deg[i], alpha0[i]) + tuple(
            geometry[k][i] for k in ("x_az", "y_az", "z_az", "cone", "ds", "thrust", "torque", "flap_root"))
        lines.append(" ".join(f(v) for v in row))
    lines += [f"n_polar {alpha.size}", f"alpha_start_deg {f(alpha[0])}",
              f"alpha_step_deg {f((alpha[-1] - alpha[0]) / (alpha.size - 1))}", "cl"]
    lines += [" ".join(f(v) for v in row) for row in cl]
    lines.append("cd")
    lines += [" ".join(f(v) for v in row) for row in cd]
    lines.append(f"alpha_nodes {grid.n_alpha} " + " ".join(f(v) for v in grid.alpha_nodes_deg))
    lines.append(f"eta_nodes {grid.n_eta} " + " ".join(f(v) for v in grid.eta_nodes))
    lines.append(f"out_stations {out_idx.size} " + " ".join(str(int(i)) for i in out_idx))
    lines.append("end")
    return "\n".join(lines) + "\n"


def write_resources(rotor: Rotor, grid: CorrectionGrid, directory: str | Path) -> dict:
    """Write ``rotor.dat`` and ``correction_grid.json`` into ``directory``.

    Returns
    -------
    dict
        Facts the model description needs: ``n_nodes`` (lift nodes), ``out_stations``
        (indices), ``out_radius`` [m], ``out_eta`` [-], ``n_blades`` and ``rotor`` info.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "rotor.dat").write_text(rotor_resource_text(rotor, grid))
    grid_info = grid.to_dict() | {"lift_index": "i_alpha * n_eta + j_eta", "rotor": rotor.name}
    (directory / "correction_grid.json").write_text(json.dumps(grid_info, indent=1) + "\n")
    idx = output_stations(rotor)
    return {"n_nodes": grid.n_lift, "out_stations": idx, "out_radius": rotor.r[idx],
            "out_eta": rotor.r[idx] / rotor.tip_radius}


def rotor_facts(rotor: Rotor) -> dict:
    """Values the variable specs may reference as ``@rotor.<name>``."""
    return {"n_blades": int(rotor.n_blades), "tilt_deg": float(rotor.tilt_deg),
            "hub_height": float(rotor.hub_height), "precone_deg": float(rotor.precone_deg),
            "tower_height": float(rotor.hub_height - TOWER_TOP_BELOW_HUB),
            "tip_radius": float(rotor.tip_radius), "hub_radius": float(rotor.hub_radius)}
