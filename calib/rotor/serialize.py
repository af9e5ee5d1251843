"""A rotor as plain data: :func:`rotor_to_dict` and :func:`rotor_from_dict`, an exact round trip.

A calibration result records the rotor its model ran (stations, chord, twist, precurve,
presweep, airfoil tables with their Reynolds numbers, hub and tip radius, blade count,
precone, tilt, hub height, the steady control schedule, name and provenance strings), so
that it rebuilds the model without the rotor files (:meth:`calib.models.bem_model.BemModel.spec`).

The dict holds only JSON types: arrays become lists of Python floats (ints for the airfoil
ids), which :mod:`json` writes with :func:`repr` and reads back bit for bit; NaN (an
unknown hub height, Reynolds number or thickness) is written as ``NaN``, which
:func:`json.loads` accepts. Layout (``format = "calib.rotor/1"``)::

    {"format", "name", "source", "r", "chord", "twist_deg", "airfoil_id", "precurve",
     "presweep", "precurve_tip", "presweep_tip", "hub_radius", "tip_radius", "n_blades",
     "precone_deg", "tilt_deg", "hub_height", "schedule": {OperatingSchedule fields} or null,
     "airfoils": [{"name", "relative_thickness", "notes",
                   "tables": [{"alpha_deg", "cl", "cd", "cm" (or null), "reynolds",
                               "source", "first_line"}]}]}

Lengths [m], angles [deg], coefficients [-], Reynolds numbers absolute [-].
:func:`calib.history.content_digest` of the rebuilt rotor equals that of the original
(tested for every rotor source kind).
"""

from __future__ import annotations

import dataclasses
import json
import numbers
import weakref

import numpy as np

from calib.errors import InputError
from calib.rotor.geometry import OperatingSchedule, Rotor
from calib.rotor.polar import Airfoil, PolarTable

FORMAT = "calib.rotor/1"

_ARRAYS = ("r", "chord", "twist_deg", "precurve", "presweep")
_SCALARS = ("precurve_tip", "presweep_tip", "hub_radius", "tip_radius", "precone_deg", "tilt_deg", "hub_height")
_TABLE_ARRAYS = ("alpha_deg", "cl", "cd")
_DIGESTS: "weakref.WeakKeyDictionary[Rotor, str]" = weakref.WeakKeyDictionary()


def _scalar(x):
    """A JSON number of the same Python kind (int stays int, numpy scalars become Python's)."""
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, numbers.Integral):
        return int(x)
    return float(x)


def _floats(a) -> list:
    return np.asarray(a, dtype=float).tolist()


def rotor_to_dict(rotor: Rotor) -> dict:
    """The rotor as a JSON-able dict (layout in the module notes).

    Parameters
    ----------
    rotor : Rotor

    Returns
    -------
    dict
        Only str, int, float, bool, None, list and dict; floats exact under :mod:`json`.
    """
    out = {"format": FORMAT, "name": str(rotor.name), "source": str(rotor.source)}
    out.update({k: _floats(getattr(rotor, k)) for k in _ARRAYS})
    out["airfoil_id"] = np.asarray(rotor.airfoil_id).astype(int).tolist()
    out.update({k: _scalar(getattr(rotor, k)) for k in _SCALARS})
    out["n_blades"] = int(rotor.n_blades)
    sched = rotor.schedule
    out["schedule"] = None if sched is None else {f.name: _scalar(getattr(sched, f.name))
                                                  for f in dataclasses.fields(sched)}
    out["airfoils"] = [{"name": str(af.name), "relative_thickness": _scalar(af.relative_thickness),
                        "notes": str(af.notes),
                        "tables": [{**{k: _floats(getattr(t, k)) for k in _TABLE_ARRAYS},
                                    "cm": None if t.cm is None else _floats(t.cm),
                                    "reynolds": float(t.reynolds), "source": str(t.source),
                                    "first_line": None if t.first_line is None else int(t.first_line)}
                                   for t in af.tables]}
                       for af in rotor.airfoils]
    return out


def _get(d: dict, key: str, where: str, source: str):
    if not isinstance(d, dict):
        raise InputError(f"expected a table, got {type(d).__name__}", source, field=where)
    if key not in d:
        raise InputError(f"missing key {key!r} of the recorded rotor", source, field=f"{where}.{key}")
    return d[key]


def rotor_from_dict(data: dict, source: str = "recorded rotor") -> Rotor:
    """The :class:`Rotor` of :func:`rotor_to_dict`'s dict.

    Parameters
    ----------
    data : dict
        As written by :func:`rotor_to_dict` (and read back from JSON).
    source : str
        Where the dict came from (named in errors, e.g. ``"result.json: provenance.model_spec.rotor_data"``).

    Raises
    ------
    InputError
        Unknown format, a missing key, or values the rotor refuses (the key named).
    """
    where = "rotor_data"
    fmt = _get(data, "format", where, source)
    if fmt != FORMAT:
        raise InputError(f"unknown rotor data format {fmt!r}, expected {FORMAT!r}", source, field=f"{where}.format")
    try:
        airfoils = []
        for i, af in enumerate(_get(data, "airfoils", where, source)):
            at = f"{where}.airfoils[{i}]"
            tables = []
            for j, t in enumerate(_get(af, "tables", at, source)):
                tt = f"{at}.tables[{j}]"
                cm = _get(t, "cm", tt, source)
                tables.append(PolarTable(*(_get(t, k, tt, source) for k in _TABLE_ARRAYS), cm,
                                         _get(t, "reynolds", tt, source), source=_get(t, "source", tt, source),
                                         first_line=_get(t, "first_line", tt, source)))
            airfoils.append(Airfoil(_get(af, "name", at, source), tuple(tables),
                                    _get(af, "relative_thickness", at, source), notes=_get(af, "notes", at, source)))
        sched = _get(data, "schedule", where, source)
        if sched is not None:
            keys = [f.name for f in dataclasses.fields(OperatingSchedule)]
            sched = OperatingSchedule(**{k: _get(sched, k, f"{where}.schedule", source) for k in keys})
        kwargs = {k: _get(data, k, where, source) for k in ("name",) + _ARRAYS + _SCALARS + ("n_blades",)}
        ids = np.asarray(_get(data, "airfoil_id", where, source), dtype=int)
        return Rotor(airfoil_id=ids, airfoils=tuple(airfoils), schedule=sched,
                     source=_get(data, "source", where, source), **kwargs)
    except InputError as exc:
        if exc.source == source:
            raise
        # an error of the rotor's own validation names the recorded rotor's provenance string
        raise InputError(f"the recorded rotor is not valid: {exc}", source, field=where) from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"the recorded rotor is not valid: {exc}", source, field=where) from None


def rotor_digest(rotor: Rotor) -> str:
    """:func:`calib.history.content_digest` of the rotor as recorded by :func:`rotor_to_dict`.

    The digest of ``rotor_from_dict(json.loads(json.dumps(rotor_to_dict(rotor))))``: equal
    to ``content_digest(rotor)`` (the round trip is exact), and still the recorded data's own
    digest for a rotor built with numpy scalars in its scalar fields, whose type (not value)
    the JSON round trip changes. Computed once per rotor object.

    Returns
    -------
    str
        SHA-256, hexadecimal.
    """
    from calib.history import content_digest

    digest = _DIGESTS.get(rotor)
    if digest is None:
        back = rotor_from_dict(json.loads(json.dumps(rotor_to_dict(rotor), allow_nan=True)), str(rotor.source))
        digest = _DIGESTS[rotor] = content_digest(back)
    return digest
