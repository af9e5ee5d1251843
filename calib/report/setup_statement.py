"""The set-up in force, and where each value came from: printed and reported by every command.

A rotor file's tilt of 5° applied silently to data from a rigid axisymmetric rotor shows up
only as an unexplained misfit. So ``calib run``, ``calib diagnose`` and ``calib predict``
state, before they compute anything, each quantity of the set-up with its value and its
origin: the workflow or config table and key that set it, the rotor files, the measurement
table (a column per point), or the default.
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: BEM settings a rotor file may set, as the workflow's [model] key names them.
_FILE_KEYS = ("tip_loss", "hub_loss", "shear_exponent")


@dataclass(frozen=True)
class SetupItem:
    """One quantity of the set-up in force.

    Attributes
    ----------
    quantity : str
        What it is (``"tilt"``, ``"air density"`` ...).
    value : str
        Its value in words, with the unit.
    origin : str
        Where it came from (``"[model] tilt"``, ``"rotor files"``, ``"default"`` ...).
    """

    quantity: str
    value: str
    origin: str

    def as_dict(self) -> dict:
        return {"quantity": self.quantity, "value": self.value, "origin": self.origin}


def _origin(key: str, table, section: str, file_keys=(), rotor_origin: str = "") -> str:
    if key in table:
        return f"[{section}] {key}"
    if key in file_keys:
        return rotor_origin
    return "default"


def _column(meas, name: str) -> tuple[str, str] | None:
    """(value, origin) of a condition read from the measurement table, or None."""
    if meas is None or name not in (meas.metadata.get("units") or {}):
        return None
    values = np.asarray(getattr(meas.conditions, name), float)
    lo, hi = float(values.min()), float(values.max())
    unit = {"yaw": "deg", "air_density": "kg/m^3"}[name]
    return (f"{lo:g} {unit}" if lo == hi else f"{lo:g} to {hi:g} {unit}"), f"measurement column '{name}'"


def rotor_origin(rotor_spec: dict | None) -> str:
    """Where the rotor came from: the embedded library or the files of ``[rotor]``."""
    spec = rotor_spec or {}
    if "name" in spec:
        return f"embedded rotor '{spec['name']}'"
    files = [spec[k] for k in ("openfast", "aerodyn", "aerodyn_blade", "windio") if isinstance(spec.get(k), str)]
    return f"rotor files ({Path(files[0]).name})" if files else "rotor files"


def bem_statement(setup, workflow, meas=None) -> list[SetupItem]:
    """The native BEM's set-up in force (:class:`calib.workflow.WorkflowSetup` of ``workflow``).

    Parameters
    ----------
    setup : calib.workflow.WorkflowSetup
        The resolved settings.
    workflow : calib.workflow.schema.Workflow
        The loaded workflow or config tables (which keys the user gave).
    meas : calib.measurements.Measurements, optional
        The measurement table, whose condition columns override the set-up per point.

    Returns
    -------
    list of SetupItem
    """
    model = workflow.model.given
    rot = rotor_origin(setup.rotor_spec)
    from_files = [k for k in _FILE_KEYS if setup.origins.get(k) == "rotor files"]
    s, rotor = setup.settings, setup.rotor
    items = [SetupItem("model", "native BEM", "[model] kind" if "kind" in model else "default"),
             SetupItem("rotor", f"{rotor.name}: R = {rotor.tip_radius:g} m, {rotor.n_blades} blades", rot)]
    for key, attr in (("tilt", "tilt_deg"), ("precone", "precone_deg")):
        items.append(SetupItem(key, f"{getattr(rotor, attr):g} deg", f"[model] {key}" if key in model else rot))
    items.append(SetupItem("tilt in the BEM", "used" if s.use_tilt else "ignored (use_tilt = false)",
                           _origin("use_tilt", model, "model")))
    items.append(SetupItem("shear exponent", f"{s.shear_exponent:g}",
                           _origin("shear_exponent", model, "model", from_files, rot)))
    yaw = _column(meas, "yaw") or (f"{setup.yaw:g} deg", _origin("yaw", model, "model"))
    items.append(SetupItem("yaw", *yaw))
    sectors = s.n_sectors if s.n_sectors is not None else \
        s.sectors_for(rotor, meas.conditions) if meas is not None else None
    how = "[model] n_sectors" if "n_sectors" in model else "default (1 if axisymmetric, else 4)"
    items.append(SetupItem("azimuth sectors", "?" if sectors is None else str(sectors), how))
    for key in ("tip_loss", "hub_loss"):
        items.append(SetupItem(key.replace("_", " "), "on" if getattr(s, key) else "off",
                               _origin(key, model, "model", from_files, rot)))
    items += _fluid_items(setup, rot, meas)
    items += _calibration_items(setup, workflow, model)
    return items


def _fluid_items(setup, rot: str, meas) -> list[SetupItem]:
    def origin(key):
        how = setup.origins.get(key, "default (air at 15 °C)")
        return rot if how == "rotor files" else how

    density = _column(meas, "air_density") or (f"{setup.density:g} kg/m^3", origin("density"))
    viscosity = (f"{setup.settings.kinematic_viscosity:.4g} m^2/s", origin("kinematic_viscosity"))
    return [SetupItem("air density", *density), SetupItem("kinematic viscosity", *viscosity)]


def _calibration_items(setup, workflow, model) -> list[SetupItem]:
    noise = setup.calibration.noise
    items = [SetupItem("noise model", str(noise), _origin("noise", workflow.calibration.given, "calibration"))]
    if not setup.is_fmu:
        nuisance = ", ".join(setup.nuisance) or "none"
        items.append(SetupItem("nuisance parameters", nuisance, _origin("nuisance", model, "model")))
    return items


def fmu_statement(setup, workflow, meas=None) -> list[SetupItem]:
    """An FMU model's set-up in force: the file and mapping, and what ``[model]`` overrides."""
    t = setup.model_table
    items = [SetupItem("model", f"FMU {t.fmu if t.fmu is not None else 'variant ' + str(t.variant)}", "[model]")]
    items.append(SetupItem("mapping", str(t.mapping if t.mapping is not None else "the bundled variant's"),
                           "[model] mapping" if t.mapping is not None else "default"))
    for key in ("switches", "settings", "parameters"):
        given = getattr(t, key)
        if given is not None:
            value = ", ".join(f"{k} = {v}" for k, v in given.items()) if isinstance(given, dict) else \
                ", ".join(map(str, given))
            items.append(SetupItem(f"FMU {key}", value or "none", f"[model] {key}"))
    if setup.rotor is not None and t.variant is not None:
        items.append(SetupItem("rotor", setup.rotor.name, rotor_origin(setup.rotor_spec)))
    if meas is not None:
        for name in ("yaw", "air_density"):
            column = _column(meas, name)
            if column:
                items.append(SetupItem(name.replace("_", " "), *column))
    items.append(SetupItem("rotor geometry, tilt, precone, shear, sectors", "as built into the FMU "
                           "(or its [model] settings)", "the FMU"))
    return items + _calibration_items(setup, workflow, frozenset())


def statement(setup, workflow, meas=None) -> list[SetupItem]:
    """The set-up in force of a workflow or a diagnosis (BEM or FMU): ``setup`` is the
    :class:`calib.workflow.WorkflowSetup` of the :class:`calib.workflow.schema.Workflow` ``workflow``."""
    return (fmu_statement if setup.is_fmu else bem_statement)(setup, workflow, meas)


def statement_lines(items: list[SetupItem]) -> list[str]:
    """One line per item: 'tilt: 5 deg (embedded rotor 'nrel5mw')'."""
    return [f"{i.quantity}: {i.value} ({i.origin})" for i in items]


def statement_html(items: list[SetupItem]) -> str:
    """The set-up in force as a report section (a table of quantity, value and origin)."""
    rows = "".join(f"<tr><td class=\"l\">{html.escape(i.quantity)}</td><td class=\"l\">{html.escape(i.value)}</td>"
                   f"<td class=\"l\">{html.escape(i.origin)}</td></tr>" for i in items)
    return ("<h2>Set-up in force</h2><p>Each value of the model's set-up and where it came from (a measurement "
            "column overrides the set-up per point).</p><div class=\"table\"><table><tr><th class=\"l\">quantity"
            f"</th><th class=\"l\">value</th><th class=\"l\">origin</th></tr>{rows}</table></div>")
