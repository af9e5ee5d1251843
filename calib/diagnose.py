"""``calib diagnose --rotor ROTOR --data FILE.csv --out DIR [--config FILE.toml]``.

Reads the rotor (an embedded name, or a rotor file: ``.fst`` OpenFAST deck, ``.yaml``
windIO, ``.dat`` AeroDyn15 main file), the measurement table and, optionally, the
``[rotor]``, ``[model]``, ``[fluid]``, ``[grid]``, ``[calibration]`` and ``[diagnosis]``
tables of a workflow-style TOML file; runs :func:`calib.discrepancy.diagnose`; writes
``DIR/diagnosis.json`` and ``DIR/report.html``.
"""

from __future__ import annotations

from pathlib import Path

from calib.discrepancy import DiagnosisSettings, diagnose
from calib.errors import InputError
from calib.tomlfile import read_toml
from calib.measurements import read_measurements

CONFIG_TABLES = ("rotor", "model", "fluid", "grid", "calibration", "diagnosis")
DEFAULT_GRID = {"alpha_nodes_deg": "auto", "eta_nodes": [0.25, 0.5, 0.75, 1.0]}
DIAGNOSIS_KEYS = {f for f in DiagnosisSettings.__dataclass_fields__}


def _rotor_table(rotor: str) -> dict:
    suffix = Path(rotor).suffix.lower()
    if suffix == ".fst":
        return {"openfast": str(Path(rotor).resolve())}
    if suffix in (".yaml", ".yml"):
        return {"windio": str(Path(rotor).resolve())}
    if suffix == ".dat":
        return {"aerodyn": str(Path(rotor).resolve())}
    return {"name": rotor}


def run_diagnose(rotor: str | None, data: str, out: str, config: str | None = None, printer=print):
    """Run the discrepancy workflow from the command line's arguments; returns the Diagnosis."""
    from calib.report.diagnosis_report import write_diagnosis
    from calib.workflow import prepare

    cfg = {}
    src = "calib diagnose"
    base_dir = Path.cwd()
    if config:
        path = Path(config)
        cfg = read_toml(path, "config file")
        unknown = [k for k in cfg if k not in CONFIG_TABLES]
        if unknown:
            raise InputError(f"unknown table(s) {', '.join(unknown)}; valid: {', '.join(CONFIG_TABLES)}", config,
                             field=unknown[0])
        src, base_dir = str(path), path.parent
    if rotor is not None:
        cfg["rotor"] = _rotor_table(rotor)
    if "rotor" not in cfg:
        raise InputError("no rotor: give --rotor NAME_OR_FILE or a [rotor] table in --config", src, field="rotor")
    dcfg = dict(cfg.pop("diagnosis", {}))
    bad = [k for k in dcfg if k not in DIAGNOSIS_KEYS]
    if bad:
        raise InputError(f"unknown key 'diagnosis.{bad[0]}'; valid keys here: {', '.join(sorted(DIAGNOSIS_KEYS))}",
                         src, field=f"diagnosis.{bad[0]}")
    if "candidates" in dcfg:
        dcfg["candidates"] = tuple(dcfg["candidates"])
    dset = DiagnosisSettings(**dcfg).validate(src, "diagnosis.")
    meas = read_measurements(data)
    for note in meas.notes:
        printer(f"[calib diagnose] {Path(data).name}: {note}")
    wf = {"name": "diagnose", "rotor": cfg["rotor"], "grid": cfg.get("grid", DEFAULT_GRID),
          "stages": [{"name": "diagnose", "channels": list(meas.channels)}], "_source": src, "_dir": str(base_dir)}
    for key in ("model", "fluid", "calibration"):
        if key in cfg:
            wf[key] = cfg[key]
    from calib.workflow import _check_table
    for key in ("model", "fluid", "grid", "calibration"):
        if key in wf:
            _check_table(wf[key], key, src)
    setup = prepare(wf)
    grid = setup.grid(meas.conditions)
    diag = diagnose(setup.rotor, meas, grid, setup.settings, setup.calibration_settings, dset,
                    progress=lambda s: printer(f"[calib diagnose] {s}"), rotor_source=setup.rotor_spec)
    paths = write_diagnosis(diag, out)
    printer(f"[calib diagnose] named: {diag.effect}" + (f" ({', '.join(diag.effects)})" if diag.effects else ""))
    printer(f"[calib diagnose] report: {paths['report']}")
    return diag
