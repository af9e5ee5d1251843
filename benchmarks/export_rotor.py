"""Write a calib rotor as JSON for ``ccblade_runner.py`` (runs in the MAIN venv).

    python benchmarks/export_rotor.py nrel5mw rotor.json

JSON fields: ``name``, ``source``, ``r``, ``chord``, ``twist_deg``, ``precurve``,
``presweep``, ``precurve_tip``, ``presweep_tip``, ``hub_radius``, ``tip_radius``,
``rotor_radius`` (the radius the native BEM uses for λ and the coefficients),
``n_blades``, ``precone_deg``, ``tilt_deg``, ``hub_height``, ``airfoil_id`` (per
station, index into ``airfoils``) and ``airfoils``: per airfoil its name and its raw
polar tables, each ``{"alpha_deg", "cl", "cd", "Re"}`` (``Re`` absolute, ``null`` when
unknown). The tables are the raw ones (no Viterna extension, no resampling).
"""

from __future__ import annotations

import json
import math
import os
import sys


def _floats(a) -> list[float]:
    return [float(v) for v in a]


def rotor_to_dict(rotor) -> dict:
    """The JSON-ready description of a :class:`calib.rotor.Rotor`."""
    airfoils = []
    for af in rotor.airfoils:
        tables = []
        for t in af.tables:
            re = float(t.reynolds)
            tables.append({"alpha_deg": _floats(t.alpha_deg), "cl": _floats(t.cl), "cd": _floats(t.cd),
                           "Re": re if math.isfinite(re) else None})
        airfoils.append({"name": af.name, "tables": tables})
    hub_height = float(rotor.hub_height)
    return {
        "name": rotor.name,
        "source": rotor.source,
        "r": _floats(rotor.r),
        "chord": _floats(rotor.chord),
        "twist_deg": _floats(rotor.twist_deg),
        "precurve": _floats(rotor.precurve),
        "presweep": _floats(rotor.presweep),
        "precurve_tip": float(rotor.precurve_tip),
        "presweep_tip": float(rotor.presweep_tip),
        "hub_radius": float(rotor.hub_radius),
        "tip_radius": float(rotor.tip_radius),
        "rotor_radius": float(rotor.rotor_radius),
        "n_blades": int(rotor.n_blades),
        "precone_deg": float(rotor.precone_deg),
        "tilt_deg": float(rotor.tilt_deg),
        "hub_height": hub_height if math.isfinite(hub_height) else None,
        "airfoil_id": [int(k) for k in rotor.airfoil_id],
        "airfoils": airfoils,
    }


def export_rotor(name: str, path) -> str:
    """Write the embedded rotor ``name`` (``calib.rotor.library.load_rotor``) to ``path``.

    Returns the path written.
    """
    from calib.rotor.library import load_rotor

    data = rotor_to_dict(load_rotor(name))
    path = os.fspath(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as fh:
        json.dump(data, fh)
    return path


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python benchmarks/export_rotor.py ROTOR_NAME OUT_JSON")
    print(export_rotor(sys.argv[1], sys.argv[2]))
