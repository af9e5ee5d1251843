"""Any vendor's co-simulation FMU behind the ForwardModel contract.

:class:`FmuModel` is built from an FMU file and a mapping file
(:mod:`calib.models.fmu_mapping`). At load time it checks, and refuses with
:class:`~calib.errors.InputError` naming the file and the item:

- the file is a zip archive whose entries all stay inside the extraction folder
  (no absolute paths, no ``..``, no links);
- the model description parses and offers co-simulation; a binary for this platform exists;
- every mapped variable exists, inputs are inputs, outputs are outputs, calibrated
  parameters and correction nodes are *tunable* parameters, settings and switches are
  parameters, array elements are inside their arrays, setting values inside the FMU's range;
- non-fatal findings of ``fmpy``'s validation are issued as warnings.

It extracts the FMU once (cached by the file's SHA-256), and hands workers a picklable
:class:`~calib.models.fmu_worker.SimulationPlan` (paths and value references, never an
instance). Simulations run through :func:`calib.models.fmu_worker.run_point` on the
model's executor (serial by default), in worker processes with a per-simulation timeout
that adapts to the measured cost of healthy runs; a point that crashed or hung is
quarantined by the model (planned here, whatever the executor): see
:class:`calib.models.fmu_faults.FaultLedger` and :meth:`FmuModel.fault_summary`.

Steady outputs: settle ``settle_revolutions``, then average ``average_revolutions`` whole
revolutions (``[steady]`` of the mapping); the status of a point says whether the two
halves of the window agree, whether the FMU failed, crashed or hung. Besides the means,
every mapped output ``x`` gives the azimuth harmonics ``x_1p``, ``x_2p``, ``x_3p``
(amplitude, unit of x) and ``x_1p_phase`` ... (deg), with x ≈ mean + Σ A_n cos(nψ + φ_n)
and ψ the azimuth of blade 1 (0 = up).

Jacobians are central differences with steps ``relative_step`` × each parameter's
``scale`` (one-sided inside a bound). With ``warm_start`` (``[jacobian]`` of the mapping,
or ``jacobian={"warm_start": True}``) the base run of each point saves its settled state and
every perturbed run restores it, sets the perturbed parameters and settles only
``perturbation_settle_revolutions`` before averaging ``perturbation_average_revolutions``
(docs/theory.md, FMUs). That is exact when a parameter step acts at once (quasi-steady physics) and
wrong by the lag where the FMU filters it (dynamic inflow): the bundled mappings keep it off
and say why. A point's runs are one executor task, so the state never leaves its worker
except serialized, to resume after a fault. FMI directional derivatives are not used: co-simulation FMUs give them for
inputs and states at one instant, not for the steady window averages with respect to
parameters; whether the FMU offers them is reported by :attr:`FmuModel.jacobian_method`
(the bundled FMUs and PythonFMU's do not).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
import tempfile
import warnings
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath
from typing import Sequence

import numpy as np

from calib.corrections import CorrectionGrid
from calib.errors import InputError, ModelError
from calib.measurements import sha256_of
from calib.models import fmu_worker as fw
from calib.models.fmu_mapping import Mapping, load_mapping
from calib.models.base import Capabilities
from calib.models.fmu_faults import FaultLedger
from calib.parametrizations.correction_field import CorrectionField, seen_from_extras
from calib.types import (CONDITION_FIELDS, STANDARD_AIR_DENSITY, Channel, Evaluation, OperatingConditions, Parameter,
                         Status, check_parameter_vector)

HARMONIC_SUFFIXES = {f"_{n}p": n for n in fw.HARMONIC_ORDERS}
NOT_CHANNELS = ("azimuth", "aero_failures")
CONDITION_DEFAULTS = {"pitch": 0.0, "air_density": STANDARD_AIR_DENSITY, "yaw": 0.0}
STATE_MAGIC = "calib-fmu-settled-states/1"


class FmuInputError(InputError):
    """Bad FMU or mapping (an :class:`InputError`)."""


# ----------------------------------------------------------------------------- archive
def check_archive(path: Path) -> list[str]:
    """Entry names of an FMU archive, refusing anything that is not a safe zip.

    Raises
    ------
    InputError
        Missing file, not a zip archive, an entry that would be written outside the
        extraction folder (absolute, drive letter, ``..``, a symbolic link), no
        ``modelDescription.xml``.
    """
    src = str(path)
    if not path.is_file():
        raise FmuInputError("FMU file not found", src)
    if not zipfile.is_zipfile(path):
        raise FmuInputError("not an FMU: the file is not a zip archive (an FMU is a zip holding modelDescription.xml, "
                            "binaries/ and resources/)", src)
    with zipfile.ZipFile(path) as z:
        infos = z.infolist()
    names = []
    for info in infos:
        name = info.filename
        posix = name.replace("\\", "/")
        parts = PurePosixPath(posix).parts
        unsafe = (posix.startswith("/") or (len(posix) > 1 and posix[1] == ":") or ".." in parts)
        is_link = stat.S_ISLNK(info.external_attr >> 16)
        if unsafe or is_link:
            what = "a symbolic link" if is_link else "a path outside the extraction folder"
            raise FmuInputError(f"zip entry {name!r} is {what}; refused (an FMU's entries must stay inside the folder "
                                "it is extracted to)", src, field=name)
        names.append(posix)
    if "modelDescription.xml" not in names:
        raise FmuInputError("not an FMU: the zip archive has no modelDescription.xml at its top level", src,
                            field="modelDescription.xml")
    return names


def extract_once(path: Path, sha: str) -> str:
    """Extract a checked FMU into the cache (``$CALIB_CACHE/fmu_extract/<sha>``), once."""
    from calib.fmu.build import cache_dir

    root = cache_dir().parent / "fmu_extract"
    target = root / sha[:24]
    if (target / ".complete").is_file():
        return str(target)
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f"{sha[:12]}-", dir=root))
    try:
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                dest = tmp / info.filename.replace("\\", "/")
                if info.is_dir():
                    dest.mkdir(parents=True, exist_ok=True)
                    continue
                dest.parent.mkdir(parents=True, exist_ok=True)
                with z.open(info) as fin, open(dest, "wb") as fout:
                    shutil.copyfileobj(fin, fout)
        (tmp / ".complete").write_text(str(path))
        try:
            os.replace(tmp, target)
        except OSError:        # another process extracted it meanwhile
            shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return str(target)


def platform_binary(md, names: Sequence[str], src: str) -> str:
    """Path inside the archive of the shared library for this platform (checked)."""
    import fmpy
    from fmpy import sharedLibraryExtension

    ident = md.coSimulation.modelIdentifier
    plat = fmpy.platform_tuple if md.fmiVersion.startswith("3") else fmpy.platform
    want = f"binaries/{plat}/{ident}{sharedLibraryExtension}"
    if want not in names:
        have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        raise FmuInputError(f"no binary for this platform: expected {want}; the FMU has binaries for "
                            f"{', '.join(have) or 'no platform'} (ask the vendor for a {plat} build, or "
                            "rebuild from sources)", src, field=want)
    return want


# ----------------------------------------------------------------------------- model
@dataclass(frozen=True)
class _Slot:
    """Where a package quantity sits in a flat vector of values written in one call."""

    vr: int
    size: int
    offset: int


class _Writer:
    """Builds one :class:`~calib.models.fmu_worker.Assignment` per FMI type for a set of
    variables, with array elements not mapped kept at their start values."""

    def __init__(self, model: "FmuModel"):
        self.model = model
        self.slots: dict[str, _Slot] = {}
        self.base: list[float] = []

    def slot(self, var, where: str) -> _Slot:
        if var.name not in self.slots:
            size = self.model._size(var)
            start = self.model._start_values(var, size)
            self.slots[var.name] = _Slot(var.valueReference, size, len(self.base))
            self.base.extend(start)
        return self.slots[var.name]

    def index(self, var, element, where: str) -> int:
        s = self.slot(var, where)
        if element is None:
            if s.size != 1:
                raise FmuInputError(f"variable {var.name!r} is an array of {s.size}; give 'element'",
                                    self.model.mapping.source, field=where)
            return s.offset
        if not 0 <= element < s.size:
            raise FmuInputError(f"element {element} is outside variable {var.name!r} ({s.size} elements)",
                                self.model.mapping.source, field=where)
        return s.offset + element

    def assignment(self, flat: np.ndarray, type_: str) -> fw.Assignment:
        return fw.Assignment(type_, tuple(s.vr for s in self.slots.values()), tuple(np.asarray(flat).tolist()))


def _type_class(var) -> str:
    if var.type in fw.REAL_TYPES:
        return "real"
    if var.type in fw.INTEGER_TYPES:
        return "integer"
    if var.type in fw.BOOLEAN_TYPES:
        return "boolean"
    return var.type


class FmuModel:
    """A co-simulation FMU (FMI 2.0 or 3.0) as a ForwardModel.

    Parameters
    ----------
    fmu : str or Path
        The ``.fmu`` file.
    mapping : str, Path or Mapping
        Its mapping file (:func:`calib.models.fmu_mapping.load_mapping`).
    channels : sequence of str, optional
        Output channels: mapped outputs (``power`` [W], ``thrust`` [N], moments [N m] ...),
        spanwise ``fn@<r/R>`` [N/m] (r/R of the FMU's output station, two decimals), and
        harmonics ``<output>_1p``, ``_2p``, ``_3p`` (amplitude) and ``<output>_1p_phase``
        ... [deg]. Default: ``power`` and ``thrust`` (those mapped).
    parameters : sequence of str, optional
        Mapped scalar parameters to calibrate (``[parameters]`` names); default all.
        The others keep the FMU's value.
    corrections : bool
        Calibrate the correction field of ``[corrections]`` (its node parameters come first,
        lift block then drag block, named as :meth:`calib.corrections.CorrectionGrid.parameters`).
    switches : dict, optional
        Effect -> ``True``/``False`` or a named model (``stall_delay = "snel"``), written at
        instantiation through ``[switches]``; unnamed effects keep the FMU's default.
    settings : dict, optional
        ``[settings]`` name -> value [package units], overriding the mapping's ``value``.
    steady, jacobian : dict, optional
        Overrides of the mapping's ``[steady]`` and ``[jacobian]`` tables.
    executor : Executor, optional
        Where simulations run (:mod:`calib.executors`); default serial.
    timeout : float
        Longest wall time of one simulation [s] (worker killed and rebuilt beyond it). Once
        healthy runs are measured the timeout in force adapts: 10 x their median wall time,
        at least 5 s, never above this (:func:`calib.models.fmu_worker.adaptive_timeout`).
    start_timeout : float
        Longest wall time for a worker process to start and for an FMU instance to be
        created [s] (timed apart from the simulations).
    isolate : bool
        Simulate in worker processes (default). ``False`` simulates in the calling
        process: faster to start, but a crash of the FMU ends the process and a hang is
        never interrupted.
    build : dict, optional
        How the FMU was built (``{"variant": "A", "rotor": {...}, "grid": {...}}``), kept in
        :meth:`spec` so that a saved result can rebuild the FMU.
    progress : callable(done, total), optional
        Called as operating points finish.

    Notes
    -----
    Faults: a point whose simulation crashed the FMU process, hung or got a fatal status is
    quarantined, not simulated again by later calls, retried once at most when a parameter
    has moved one scale from where it failed; an error status is not quarantined
    (:class:`calib.models.fmu_faults.FaultLedger` says why). :meth:`fault_summary` reports
    the timeout in force, the quarantined points and the errors.
    """

    def __init__(self, fmu, mapping, channels: Sequence[str] | None = None,
                 parameters: Sequence[str] | None = None, corrections: bool = True,
                 switches: dict | None = None, settings: dict | None = None, steady: dict | None = None,
                 jacobian: dict | None = None, executor=None, timeout: float = fw.DEFAULT_TIMEOUT, isolate: bool = True,
                 build: dict | None = None, progress=None, start_timeout: float = fw.DEFAULT_TIMEOUT):
        import fmpy
        from fmpy.model_description import read_model_description

        self.fmu_path = Path(fmu).resolve()
        src = str(self.fmu_path)
        self.mapping: Mapping = mapping if isinstance(mapping, Mapping) else load_mapping(mapping)
        msrc = self.mapping.source
        names = check_archive(self.fmu_path)
        try:
            md = read_model_description(src, validate=False)
        except Exception as exc:  # noqa: BLE001 - fmpy raises several kinds
            raise FmuInputError(f"modelDescription.xml cannot be read: {exc}", src, field="modelDescription.xml") \
                from None
        if md.coSimulation is None:
            raise FmuInputError("the FMU has no co-simulation interface (model exchange only); calib drives "
                                "co-simulation FMUs", src, field="modelDescription.xml")
        self.model_description = md
        self.binary = platform_binary(md, names, src)
        self._validation_warnings(src)
        m = self.mapping
        if m.fmi_version and m.fmi_version != md.fmiVersion:
            raise FmuInputError(f"the mapping is for FMI {m.fmi_version}, the FMU {self.fmu_path.name} is FMI "
                                f"{md.fmiVersion}", msrc, field="fmi_version")
        ident = md.coSimulation.modelIdentifier
        if m.model_identifier and m.model_identifier != ident:
            raise FmuInputError(f"the mapping is for model identifier {m.model_identifier!r}, the FMU "
                                f"{self.fmu_path.name} is {ident!r}", msrc, field="model_identifier")
        self.sha256 = sha256_of(self.fmu_path)
        self.unzip_dir = extract_once(self.fmu_path, self.sha256)
        self._vars = {v.name: v for v in md.modelVariables}
        self.guid = md.guid if md.fmiVersion.startswith("2") else md.instantiationToken
        cs = md.coSimulation
        self.can_get_state = bool(getattr(cs, "canGetAndSetFMUstate", False))
        self.can_serialize = bool(getattr(cs, "canSerializeFMUstate", False))
        self.offers_directional_derivatives = bool(getattr(cs, "providesDirectionalDerivative", False))

        steady_rule = m.steady.replace(**(steady or {})) if steady else m.steady
        jac = dict(vars(m.jacobian))
        for key, value in (jacobian or {}).items():
            if key not in jac:
                raise InputError(f"unknown jacobian option {key!r}; valid: {', '.join(jac)}", "FmuModel",
                                 field="jacobian")
            jac[key] = value
        self.relative_step = float(jac["relative_step"])
        self.warm_start = bool(jac["warm_start"])
        self.steady = steady_rule
        self.timeout = float(timeout)
        self.isolate = bool(isolate)
        self.build = build
        self.progress = progress
        self._options = {"parameters": None if parameters is None else list(parameters),
                         "corrections": bool(corrections), "switches": dict(switches or {}),
                         "settings": dict(settings or {}), "steady": dict(steady or {}),
                         "jacobian": dict(jacobian or {}), "timeout": self.timeout, "isolate": self.isolate}
        if executor is None:
            from calib.executors import SerialExecutor
            executor = SerialExecutor()
        self.executor = executor

        self._check_all_mapped_variables()
        self._fixed = self._fixed_assignments(switches or {}, settings or {})
        self._build_parameters(parameters, corrections)
        self._build_inputs()
        self._probed: dict | None = None
        self._build_channels(channels)
        self._plan = self._make_plan()
        self.start_timeout = float(start_timeout)
        self._faults = FaultLedger([q.name for q in self._parameters], [q.scale for q in self._parameters],
                                      self.timeout, self.start_timeout, self.fmu_path.name)

    # ------------------------------------------------------------------ load-time checks
    def _validation_warnings(self, src: str) -> None:
        try:
            from fmpy.validation import validate_fmu
            problems = validate_fmu(src)
        except Exception as exc:  # noqa: BLE001 - a validator crash is itself only a finding
            problems = [f"fmpy validation could not run: {exc}"]
        for problem in problems or []:
            warnings.warn(f"{src}: fmpy validate: {problem}", stacklevel=3)

    def _var(self, name: str, where: str):
        v = self._vars.get(name)
        if v is None:
            from difflib import get_close_matches
            close = get_close_matches(name, list(self._vars), n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise FmuInputError(f"variable {name!r} does not exist in {self.fmu_path.name}{hint}",
                                self.mapping.source, field=where)
        return v

    def _expect(self, var, where: str, causality: tuple, variability: tuple | None = None, what: str = ""):
        if var.causality not in causality:
            raise FmuInputError(f"variable {var.name!r} has causality {var.causality!r}; {what or 'expected'} "
                                f"{' or '.join(causality)}", self.mapping.source, field=where)
        if variability and var.variability not in variability:
            raise FmuInputError(f"variable {var.name!r} is not tunable (variability {var.variability!r}): it "
                                f"cannot change after initialization, so it cannot be calibrated (perturbed "
                                f"runs restart from a settled state); expected variability "
                                f"{' or '.join(variability)}", self.mapping.source, field=where)

    def _size(self, var) -> int:
        n = 1
        for d in var.dimensions or []:
            if d.start is not None:
                n *= int(d.start)
            else:
                ref = d.variable if d.variable is not None else None
                n *= int(float(ref.start)) if ref is not None and ref.start is not None else 1
        return n

    def _start_values(self, var, size: int) -> list:
        if var.start is None:
            return [0.0] * size
        vals = str(var.start).split()
        out = []
        for v in vals:
            out.append({"true": 1.0, "false": 0.0}.get(v.lower(), None) if v.lower() in ("true", "false")
                       else float(v))
        return (out * size)[:size] if len(out) == 1 else out[:size]

    def _check_all_mapped_variables(self) -> None:
        m = self.mapping
        for name, e in m.inputs.items():
            self._expect(self._var(e.variable, f"inputs.{name}"), f"inputs.{name}", ("input", "parameter"))
        for name, e in m.outputs.items():
            self._expect(self._var(e.variable, f"outputs.{name}"), f"outputs.{name}", ("output", "local"))
        for name, sp in m.spanwise.items():
            for v in (*sp.variables, *([sp.variable] if sp.variable else []), *sp.radius_variables,
                      *([sp.radius_variable] if sp.radius_variable else [])):
                self._expect(self._var(v, f"outputs.{name}"), f"outputs.{name}", ("output", "local"))
        for name, e in m.parameters.items():
            var = self._var(e.variable, f"parameters.{name}")
            self._expect(var, f"parameters.{name}", ("parameter", "input"), ("tunable", "continuous", "discrete"))
            if _type_class(var) != "real":
                raise FmuInputError(f"variable {var.name!r} is {var.type}; calibrated parameters must be real",
                                    m.source, field=f"parameters.{name}")
        for name, e in m.settings.items():
            self._expect(self._var(e.variable, f"settings.{name}"), f"settings.{name}", ("parameter",))
        for name, s in m.switches.items():
            self._expect(self._var(s.variable, f"switches.{name}"), f"switches.{name}", ("parameter",))
        if m.rotor_radius is not None and not isinstance(m.rotor_radius, float):
            self._expect(self._var(m.rotor_radius.variable, "rotor.radius"), "rotor.radius",
                         ("output", "local", "parameter", "calculatedParameter"))

    def _fixed_assignments(self, switches: dict, settings: dict) -> tuple:
        m = self.mapping
        groups: dict[str, _Writer] = {}
        values: dict[str, dict[int, float]] = {}

        def put(var, element, value, where):
            t = _type_class(var)
            if t not in ("real", "integer", "boolean"):
                raise FmuInputError(f"variable {var.name!r} has unsupported type {var.type}", m.source, field=where)
            w = groups.setdefault(t, _Writer(self))
            i = w.index(var, element, where)
            lo = float(var.min) if var.min is not None else -np.inf
            hi = float(var.max) if var.max is not None else np.inf
            v = float(value)
            if not (lo <= v <= hi):
                raise FmuInputError(f"value {value!r} (FMU units) for {var.name!r} is outside its range [{lo:g}, "
                                    f"{hi:g}]", m.source, field=where)
            values.setdefault(t, {})[i] = v

        unknown = [k for k in settings if k not in m.settings]
        if unknown:
            raise InputError(f"unknown setting(s) {', '.join(unknown)}; the mapping's [settings]: "
                             f"{', '.join(m.settings) or '(none)'}", m.source, field=f"settings.{unknown[0]}")
        for name, e in m.settings.items():
            value = settings.get(name, e.value)
            if value is None:
                continue
            var = self._var(e.variable, f"settings.{name}")
            put(var, e.element, float(e.to_fmu(float(value))), f"settings.{name}")
        unknown = [k for k in switches if k not in m.switches]
        if unknown:
            raise InputError(f"unknown switch(es) {', '.join(unknown)}; the mapping's [switches]: "
                             f"{', '.join(m.switches) or '(none)'}", m.source, field=f"switches.{unknown[0]}")
        for name, setting in switches.items():
            s = m.switches[name]
            var = self._var(s.variable, f"switches.{name}")
            put(var, None, float(s.value(setting, m.source)), f"switches.{name}")
        out = []
        for t, w in groups.items():
            flat = np.array(w.base, float)
            for i, v in values.get(t, {}).items():
                flat[i] = v
            out.append(w.assignment(flat, t))
        return tuple(out)

    def _build_parameters(self, names, corrections: bool) -> None:
        m = self.mapping
        w = _Writer(self)
        params, index, conv = [], [], []   # conv: (scale, offset, sign) package -> fmu
        self.grid = None
        if corrections and m.corrections is not None:
            c = m.corrections
            if c.grid_file:
                gpath = Path(self.unzip_dir) / c.grid_file
                if not gpath.is_file():
                    raise FmuInputError(f"correction grid file {c.grid_file!r} is not in the FMU", m.source,
                                        field="corrections.grid")
                info = json.loads(gpath.read_text())
                opts = {k: info[k] for k in ("cl_scale", "cd_scale", "cl_bound", "cd_bound") if k in info}
                grid = CorrectionGrid(info["alpha_nodes_deg"], info["eta_nodes"], **(opts | c.grid_options))
            else:
                grid = CorrectionGrid(c.alpha_nodes_deg, c.eta_nodes, **c.grid_options)
            self.grid = grid
            lift, drag = c.variable_names(grid.n_alpha, grid.n_eta)
            for block, vnames in (("lift", lift), ("drag", drag)):
                where = f"corrections.{block}"
                if c.layout == "array":
                    var = self._var(vnames[0], where)
                    self._expect(var, where, ("parameter",), ("tunable",))
                    if self._size(var) != grid.n_lift:
                        raise FmuInputError(f"array {var.name!r} has {self._size(var)} elements, the correction grid "
                                            f"{grid.n_lift} nodes", m.source, field=where)
                    index += [w.index(var, k, where) for k in range(grid.n_lift)]
                else:
                    for vn in vnames:
                        var = self._var(vn, where)
                        self._expect(var, where, ("parameter",), ("tunable",))
                        index.append(w.index(var, None, where))
                conv += [(c.scale, 0.0, 1)] * grid.n_lift
            params += list(grid.parameters())
        selected = list(m.parameters) if names is None else list(names)
        unknown = [n for n in selected if n not in m.parameters]
        if unknown:
            raise InputError(f"unknown parameter(s) {', '.join(unknown)}; the mapping's [parameters]: "
                             f"{', '.join(m.parameters) or '(none)'}", m.source, field=f"parameters.{unknown[0]}")
        for name in selected:
            e = m.parameters[name]
            where = f"parameters.{name}"
            var = self._var(e.variable, where)
            lo_f = float(var.min) if var.min is not None else -np.inf
            hi_f = float(var.max) if var.max is not None else np.inf
            fmu_range = np.sort(e.to_package(np.array([lo_f, hi_f])))
            start = self._start_values(var, self._size(var))[e.element or 0]
            nominal = float(e.to_package(start)) if np.isnan(e.nominal) else e.nominal
            lower = fmu_range[0] if np.isnan(e.lower) else e.lower
            upper = fmu_range[1] if np.isnan(e.upper) else e.upper
            if not (np.isfinite(lower) and np.isfinite(upper)):
                raise FmuInputError("no finite bounds: give 'lower' and 'upper' (the FMU declares no min/max)",
                                    m.source, field=where)
            if lower < fmu_range[0] - 1e-12 * abs(fmu_range[0]) or upper > fmu_range[1] + 1e-12 * abs(fmu_range[1]):
                raise FmuInputError(f"bounds [{lower:g}, {upper:g}] exceed the FMU's range [{fmu_range[0]:g}, "
                                    f"{fmu_range[1]:g}] (package units)", m.source, field=where)
            try:
                params.append(Parameter(name, nominal, lower, upper, e.typical, e.package_unit or "-", e.kind,
                                        description=e.description or f"FMU variable {e.variable}",
                                        prior_std=e.prior_std))
            except InputError as exc:
                raise FmuInputError(exc.message, m.source, field=where) from None
            index.append(w.index(var, e.element, where))
            conv.append((e.scale, e.offset, e.sign))
        self._parameters = tuple(params)
        self._param_writer = w
        self._param_index = np.array(index, int)
        cv = np.array(conv, float).reshape(-1, 3)
        self._param_conv = cv
        self._param_base = np.array(w.base, float)

    def _build_inputs(self) -> None:
        m = self.mapping
        w = _Writer(self)
        self._input_fields, idx, conv = [], [], []
        for name, e in m.inputs.items():
            var = self._var(e.variable, f"inputs.{name}")
            if _type_class(var) != "real":
                raise FmuInputError(f"input {var.name!r} is {var.type}; operating conditions need real inputs",
                                    m.source, field=f"inputs.{name}")
            idx.append(w.index(var, e.element, f"inputs.{name}"))
            conv.append((e.scale, e.offset, e.sign))
            self._input_fields.append(name)
        self._input_writer = w
        self._input_index = np.array(idx, int)
        self._input_conv = np.array(conv, float)
        self._input_base = np.array(w.base, float)

    # ------------------------------------------------------------------ channels
    def _probe(self) -> dict:
        """Rotor radius and output-station radii, read from an initialized instance (once)."""
        if self._probed is not None:
            return self._probed
        m = self.mapping
        reads = []
        for sp in m.spanwise.values():
            if sp.radius_variables:
                reads += [(self._vars[v].valueReference, 1) for v in sp.radius_variables]
            elif sp.radius_variable:
                var = self._vars[sp.radius_variable]
                reads.append((var.valueReference, self._size(var)))
        if m.rotor_radius is not None and not isinstance(m.rotor_radius, float):
            reads.append((self._vars[m.rotor_radius.variable].valueReference, 1))
        values = []
        if reads:
            plan = self._make_plan(signals_only=True)
            worker = fw.worker_for(plan, self.isolate, self.timeout)
            try:
                values = worker.probe(reads)
            except Exception as exc:  # noqa: BLE001
                raise ModelError(f"{self.fmu_path.name}: could not initialize the FMU to read radii: {exc}") from None
            finally:
                fw.close_workers(plan.key)
        k = 0
        radii = {}
        for name, sp in m.spanwise.items():
            if sp.radius_variables:
                radii[name] = np.array([values[k + i][0] for i in range(len(sp.radius_variables))])
                k += len(sp.radius_variables)
            elif sp.radius_variable:
                radii[name] = np.array(values[k])
                k += 1
        if m.rotor_radius is None:
            radius = None
        elif isinstance(m.rotor_radius, float):
            radius = m.rotor_radius
        else:
            radius = float(m.rotor_radius.to_package(values[k][0]))
        self._probed = {"radii": radii, "rotor_radius": radius}
        return self._probed

    def _spanwise_eta(self, name: str) -> np.ndarray | None:
        pr = self._probe()
        if name not in pr["radii"] or pr["rotor_radius"] is None:
            return None
        return pr["radii"][name] / pr["rotor_radius"]

    def available_channels(self) -> list[str]:
        """Channel names this FMU offers through its mapping (harmonics as patterns)."""
        base = [n for n in self.mapping.outputs if n not in NOT_CHANNELS]
        if "normal_force" in self.mapping.spanwise and self.mapping.rotor_radius is not None:
            eta = self._spanwise_eta("normal_force")
            if eta is not None:
                base += [f"fn@{e:.2f}" for e in eta]
        return base + [f"<output>{s}" for s in HARMONIC_SUFFIXES] + [f"<output>{s}_phase" for s in HARMONIC_SUFFIXES]

    def _signal_of(self, base: str, where: str):
        """(signal key, unit) of a base output name."""
        m = self.mapping
        if base in m.outputs and base not in NOT_CHANNELS:
            return ("out", base), m.outputs[base].channel_unit
        if base.startswith("fn@") and "normal_force" in m.spanwise:
            eta = self._spanwise_eta("normal_force")
            if eta is not None:
                labels = [f"{e:.2f}" for e in eta]
                label = base[3:]
                try:
                    label = f"{float(label):.2f}"
                except ValueError:
                    pass
                if label in labels:
                    return ("span", "normal_force", labels.index(label)), "N/m"
        return None, None

    def _build_channels(self, channels) -> None:
        m = self.mapping
        if channels is None:
            channels = [c for c in ("power", "thrust") if c in m.outputs] or \
                       [c for c in m.outputs if c not in NOT_CHANNELS][:1]
        if isinstance(channels, str):
            channels = [channels]
        if not channels:
            raise InputError("at least one channel is needed", "FmuModel", field="channels")
        specs = []
        for name in channels:
            base, kind, order = name, "mean", 0
            if name.endswith("_phase"):
                stem = name[: -len("_phase")]
                for suf, n in HARMONIC_SUFFIXES.items():
                    if stem.endswith(suf):
                        base, kind, order = stem[: -len(suf)], "phase", n
            else:
                for suf, n in HARMONIC_SUFFIXES.items():
                    if name.endswith(suf) and name[: -len(suf)]:
                        cand = name[: -len(suf)]
                        if self._signal_of(cand, "channels")[0] is not None:
                            base, kind, order = cand, "amplitude", n
            key, unit = self._signal_of(base, "channels")
            if key is None:
                raise InputError(f"channel {name!r} is not provided by {self.fmu_path.name} through "
                                 f"{Path(m.source).name}; available: {', '.join(self.available_channels())}",
                                 m.source, field="outputs")
            specs.append((name, key, kind, order, "deg" if kind == "phase" else unit))
        self._channel_specs = specs
        self._channels = tuple(Channel(n, u) for n, _, _, _, u in specs)

    # ------------------------------------------------------------------ plan
    def _make_plan(self, signals_only: bool = False) -> fw.SimulationPlan:
        m = self.mapping
        reads: dict[str, tuple[int, int, int]] = {}     # variable -> (vr, size, offset)
        count = 0

        def flat(var_name: str, element) -> int:
            nonlocal count
            if var_name not in reads:
                var = self._vars[var_name]
                size = self._size(var)
                reads[var_name] = (var.valueReference, size, count)
                count += size
            vr, size, off = reads[var_name]
            return off + (element or 0)

        signals, keys = [], {}
        checked = []

        def add(key, var_name, element, scale=1.0, offset=0.0, sign=1, wrap=None, check=False, name=None):
            if key in keys:
                if check and keys[key] not in checked:
                    checked.append(keys[key])
                return keys[key]
            keys[key] = len(signals)
            signals.append(fw.Signal(name or str(key), flat(var_name, element), scale, offset, sign, wrap))
            if check:
                checked.append(keys[key])
            return keys[key]

        if not signals_only:
            for _, key, _, _, _ in self._channel_specs:
                if key[0] == "out":
                    e = m.outputs[key[1]]
                    var = self._vars[e.variable]
                    if _type_class(var) != "real":
                        raise FmuInputError(f"output {var.name!r} is {var.type}; channels need real outputs", m.source,
                                            field=f"outputs.{key[1]}")
                    add(key, e.variable, e.element, e.scale, e.offset, e.sign, e.wrap, True, key[1])
                else:
                    sp = m.spanwise[key[1]]
                    vname = sp.variables[key[2]] if sp.variables else sp.variable
                    elem = None if sp.variables else key[2]
                    add(key, vname, elem, sp.scale, sp.offset, 1, None, True, f"{key[1]}[{key[2]}]")
            if "angle_of_attack" in m.spanwise and self.grid is not None:
                sp = m.spanwise["angle_of_attack"]
                n = len(sp.variables) if sp.variables else self._size(self._vars[sp.variable])
                for k in range(n):
                    vname = sp.variables[k] if sp.variables else sp.variable
                    add(("span", "angle_of_attack", k), vname, None if sp.variables else k, sp.scale, sp.offset,
                        1, None, False, f"angle_of_attack[{k}]")
        azimuth = None
        if m.azimuth is not None:
            e = m.azimuth
            azimuth = add(("out", "azimuth"), e.variable, e.element, e.scale, e.offset, e.sign, e.wrap or 360.0,
                          False, "azimuth")
        counters = []
        if "aero_failures" in m.outputs and not signals_only:
            e = m.outputs["aero_failures"]
            var = self._vars[e.variable]
            counters.append(fw.Counter("aero_failures", var.valueReference, _type_class(var)))
        plan = fw.SimulationPlan(
            key="", fmi_version=self.model_description.fmiVersion,
            model_identifier=self.model_description.coSimulation.modelIdentifier, guid=self.guid,
            unzip_dir=self.unzip_dir, fixed=self._fixed, read_vrs=tuple(v[0] for v in reads.values()),
            read_count=count, signals=tuple(signals), azimuth=azimuth, checked=tuple(checked),
            counters=tuple(counters), steady=self.steady, can_get_state=self.can_get_state,
            can_serialize=self.can_serialize)
        digest = hashlib.sha256(self.sha256.encode() + repr(plan).encode()).hexdigest()[:20]
        if not signals_only:
            self._keys_for_values = dict(keys)
        return fw.SimulationPlan(**{**plan.__dict__, "key": digest})

    # ------------------------------------------------------------------ contract
    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return self._parameters

    @property
    def channels(self) -> tuple[Channel, ...]:
        return self._channels

    @property
    def jacobian_method(self) -> str:
        """How :meth:`jacobian` differentiates, and why."""
        dd = ("the FMU offers directional derivatives, but of instantaneous outputs with respect to inputs and "
              "states, not of steady window averages with respect to parameters: not used"
              if self.offers_directional_derivatives else "the FMU offers no directional derivatives")
        warm = ("warm-started from the settled base state" if self.warm_start and self.can_get_state
                else "each perturbed run settled from scratch")
        return f"central differences, steps {self.relative_step:g} x parameter scale, {warm}; {dd}"

    def _fmu_parameter_values(self, p: np.ndarray) -> tuple:
        flat = self._param_base.copy()
        if p.size:
            c = self._param_conv
            flat[self._param_index] = (c[:, 2] * p - c[:, 1]) / c[:, 0]
        return (self._param_writer.assignment(flat, "real"),) if self._param_writer.slots else ()

    def _fmu_inputs(self, conditions: OperatingConditions) -> list[tuple]:
        m = self.mapping
        for name in CONDITION_FIELDS:
            if name in m.inputs:
                continue
            values = getattr(conditions, name)
            default = CONDITION_DEFAULTS.get(name)
            if default is None or np.any(values != default):
                raise InputError(f"the operating conditions set {name} (e.g. {values[values != default][0]:g}) but "
                                 f"the mapping maps no input for it; add inputs.{name} or drop it from the data",
                                 m.source, field=f"inputs.{name}")
        cols = np.column_stack([getattr(conditions, f) for f in self._input_fields])
        c = self._input_conv
        fmu = (c[:, 2] * cols - c[:, 1]) / c[:, 0]
        out = []
        for row in fmu:
            flat = self._input_base.copy()
            flat[self._input_index] = row
            out.append((self._input_writer.assignment(flat, "real"),))
        return out

    def _run(self, tasks: list, p, conditions) -> list:
        """Results of ``tasks`` at ``p``: quarantined points are not simulated (the ledger
        fills their results), the others run on the executor with the adaptive timeout."""
        run, results = self._faults.plan(tasks, p, len(self._plan.signals))
        policy = self._faults.policy()
        jobs = [(self._plan, tasks[k], self.isolate, policy) for k in run]
        done = self.executor.map(fw.run_point, jobs, self.progress) if jobs else []
        for k, r in zip(run, done):
            results[k] = r
        self._faults.record(tasks, results, run, p, conditions)
        return results

    def fault_summary(self) -> dict:
        """Faults met by this model's simulations so far, as a plain (JSON-able) dict.

        Returns
        -------
        dict
            ``timeout``: ``configured_s``, ``start_timeout_s``, ``multiple`` [-], ``floor_s``,
            ``in_force_s`` (the adaptive timeout now), ``median_healthy_s`` (None before any
            healthy run), ``healthy_runs``, ``changes`` (list of ``{call, timeout_s,
            median_healthy_s, healthy_runs}``, one per notable change, > 20 %);
            ``quarantine``: one dict per quarantined point: ``index`` (its position in the
            call where it failed), ``conditions`` (package units), ``status``,
            ``status_name``, ``fault`` ("crash", "timeout", "fatal"), ``run`` (which run failed),
            ``message``, ``p`` (parameters then), ``call``, ``timeout`` [s], ``faults``
            (simulations that faulted), ``skipped`` (calls that did not simulate it),
            ``retried``, ``retry_call``, ``retry_outcome`` (None, "failed again",
            "recovered"), ``active`` (still quarantined);
            ``errors``: points with an error status (fault "error": not quarantined; or
            "fatal": also quarantined): ``conditions``,
            ``count``, ``status``, ``status_name``, ``fault``, ``run``, ``message``, ``call``;
            ``counts``: ``calls``, ``points_simulated``, ``points_skipped``, ``crashes``,
            ``timeouts``, ``start_timeouts``, ``errors``, ``fatal`` (runs that met each),
            ``retries``;
            ``rules``: the quarantined fault kinds and the retry distance [parameter scales].
        """
        return {"fmu": self.fmu_path.name, **self._faults.summary()}

    def clear_quarantine(self) -> None:
        """Simulate quarantined points again from now on (e.g. a new stage with another
        model setting); the timeout statistics are kept."""
        self._faults.clear()

    def _values(self, outcomes: list) -> np.ndarray:
        """Channel values (n, n_channels) from run outcomes."""
        mean = np.array([o.mean for o in outcomes])
        harm = np.array([o.harmonics for o in outcomes])
        out = np.empty((len(outcomes), len(self._channel_specs)))
        for c, (_, key, kind, order, _) in enumerate(self._channel_specs):
            i = self._keys_for_values[key]
            if kind == "mean":
                out[:, c] = mean[:, i]
            elif kind == "amplitude":
                out[:, c] = np.abs(harm[:, i, order - 1])
            else:
                out[:, c] = np.degrees(np.angle(harm[:, i, order - 1]))
        return out

    def _extras(self, outcomes: list, results: list) -> dict:
        extras = {"restarts": np.array([r.restarts for r in results], int),
                  "wall_time": np.array([sum(o.wall for o in [r.base, *[x for x in r.perturbations if x]] if o)
                                         for r in results])}
        if self.grid is not None and "angle_of_attack" in self.mapping.spanwise:
            eta = self._spanwise_eta("angle_of_attack")
            keys = sorted((k for k in self._keys_for_values if k[0] == "span" and k[1] == "angle_of_attack"),
                          key=lambda k: k[2])
            idx = [self._keys_for_values[k] for k in keys]
            if eta is not None and idx:
                alpha = np.array([o.mean[idx] for o in outcomes])
                extras["alpha_deg"], extras["eta"] = alpha, eta
        return extras

    def _tasks(self, p, conditions, perturb: bool, start_states=None):
        p = check_parameter_vector(p, self._parameters, "FmuModel parameter vector")
        base = self._fmu_parameter_values(p)
        inputs = self._fmu_inputs(conditions)
        perturbations, steps = (), None
        if perturb:
            lower = np.array([q.lower for q in self._parameters])
            upper = np.array([q.upper for q in self._parameters])
            h = self.relative_step * np.array([q.scale for q in self._parameters])
            plus, minus = np.minimum(p + h, upper), np.maximum(p - h, lower)
            runs = []
            for j in range(p.size):
                for x in (plus[j], minus[j]):
                    q = p.copy()
                    q[j] = x
                    runs.append(self._fmu_parameter_values(q))
            perturbations, steps = tuple(runs), plus - minus
        if start_states is not None and len(start_states) != len(conditions):
            raise InputError(f"{len(start_states)} start states for {len(conditions)} operating points", "FmuModel",
                             field="start_states")
        tasks = [fw.PointTask(k, inputs[k], base, perturbations, float(conditions.rotor_speed[k]),
                              self.warm_start, start_state=None if start_states is None else start_states[k])
                 for k in range(len(conditions))]
        return p, tasks, steps

    def _evaluation(self, results, conditions) -> Evaluation:
        outcomes = [r.base for r in results]
        values = self._values(outcomes)
        status = np.array([o.status for o in outcomes], int)
        messages = [o.message for o in outcomes]
        needs_harmonics = any(kind != "mean" for _, _, kind, _, _ in self._channel_specs)
        if needs_harmonics:
            for k in np.flatnonzero((conditions.rotor_speed <= 0) & (status == Status.CONVERGED)):
                status[k] = Status.INVALID_INPUT
                messages[k] = "azimuth harmonics need a turning rotor (rotor speed 0)"
        values[status != Status.CONVERGED] = np.nan
        return Evaluation(values, status, tuple(messages), self._channels, self._extras(outcomes, results))

    def evaluate(self, p, conditions: OperatingConditions, start_states=None) -> Evaluation:
        """Steady channel values (n_points, n_channels) and a status per point at ``p``.

        ``start_states`` (from :meth:`load_states`, one per point or None) start each base
        run from a settled state of this build instead of from scratch: it then settles only
        ``perturbation_settle_revolutions``.
        """
        p, tasks, _ = self._tasks(p, conditions, perturb=False, start_states=start_states)
        return self._evaluation(self._run(tasks, p, conditions), conditions)

    def jacobian(self, p, conditions: OperatingConditions, start_states=None):
        """Central-difference sensitivities ``G[k, c, j] = d y[k, c] / d p[j]``.

        Returns
        -------
        evaluation : Evaluation
            At ``p`` (the base runs). A point whose perturbed run failed gets that run's
            status and message (and NaN values): its sensitivities are unknown.
        G : ndarray, shape (n_points, n_channels, n_params)
            NaN on failed points.
        """
        p, tasks, steps = self._tasks(p, conditions, perturb=True, start_states=start_states)
        results = self._run(tasks, p, conditions)
        ev = self._evaluation(results, conditions)
        n_par = p.size
        n_ch = len(self._channels)
        G = np.full((len(tasks), n_ch, n_par), np.nan)
        status, messages = ev.status.copy(), list(ev.messages)
        phase = np.array([kind == "phase" for _, _, kind, _, _ in self._channel_specs])
        for k, r in enumerate(results):
            if status[k] != Status.CONVERGED:
                continue
            runs = r.perturbations
            bad = [j for j, o in enumerate(runs) if o is None or not o.ok]
            if bad:
                j = bad[0]
                o = runs[j]
                status[k] = o.status if o is not None else Status.SIMULATION_FAILED
                sign = "+" if j % 2 == 0 else "-"
                messages[k] = (f"perturbed run ({sign}{self._parameters[j // 2].name}) failed: "
                               f"{o.message if o is not None else 'not run'}")
                continue
            y = self._values(runs)                      # (2 n_par, n_ch)
            d = y[0::2] - y[1::2]
            d[:, phase] = (d[:, phase] + 180.0) % 360.0 - 180.0
            G[k] = (d / steps[:, None]).T
        values = ev.values.copy()
        values[status != Status.CONVERGED] = np.nan
        ev = Evaluation(values, status, tuple(messages), ev.channels, ev.extras)
        return ev, G

    # ------------------------------------------------------------------ declared capabilities
    @property
    def has_correction_field(self) -> bool:
        """The mapping maps correction nodes and this model calibrates them (``corrections=True``)."""
        return bool(self._options["corrections"]) and self.mapping.corrections is not None

    @property
    def capabilities(self) -> Capabilities:
        """Rebuildable from its spec, finite-difference Jacobians, workers to close; a correction field
        when :attr:`has_correction_field` (named ``FmuFieldModel`` in results then), never refinable (the
        nodes are the FMU's own)."""
        field = self.has_correction_field
        return Capabilities("FmuFieldModel" if field else "FmuModel", correction_field=field, rebuildable=True,
                            derivatives="finite_difference", closes=True)

    def correction_field(self) -> CorrectionField:
        """The correction field of ``[corrections]`` (when :attr:`has_correction_field`).

        Nominal C_L, C_D are not known outside the FMU, so the C_D ≥ C_D,min bound and
        the corrected polars are not available; the ΔC bands and eigenshapes are.
        """
        if not self.has_correction_field:
            raise ModelError(f"{self.fmu_path.name}: its mapping maps no correction field (or corrections = false)")
        return CorrectionField(self._parameters, None, seen_from_extras)

    @property
    def rotor_radius(self) -> float | None:
        """Rotor radius [m] from the mapping's ``[rotor]`` (None without it)."""
        if self.mapping.rotor_radius is None:
            return None
        return self._probe()["rotor_radius"]

    def spec(self) -> dict:
        """JSON-able description; :func:`calib.models.registry.build_model` rebuilds the model."""
        mapping = Path(self.mapping.source).resolve()
        return {"kind": "fmu", "fmu": str(self.fmu_path), "fmu_sha256": self.sha256,
                "mapping": str(mapping), "mapping_sha256": sha256_of(mapping) if mapping.is_file() else None,
                "build": self.build, "channels": [c.name for c in self._channels], **self._options}

    @classmethod
    def from_spec(cls, spec: dict, base_dir=None) -> "FmuModel":
        """Rebuild from :meth:`spec` (rebuilding a bundled variant when its file is gone)."""
        def resolve(p):
            q = Path(p)
            return q if q.is_absolute() or base_dir is None else Path(base_dir) / q
        fmu = resolve(spec["fmu"]) if spec.get("fmu") else None
        if (fmu is None or not fmu.is_file()) and spec.get("build"):
            from calib.models.from_config import build_variant
            fmu = build_variant(spec["build"], "model spec", base_dir)
        if fmu is None:
            raise InputError("the spec names no FMU file", "model spec", field="fmu")
        opts = {k: spec[k] for k in ("parameters", "corrections", "switches", "settings", "steady", "jacobian",
                                     "timeout", "isolate") if k in spec}
        return cls(fmu, resolve(spec["mapping"]), spec.get("channels"), build=spec.get("build"), **opts)

    # ------------------------------------------------------------------ settled states
    def settled_states(self, p, conditions: OperatingConditions) -> list[bytes | None]:
        """Serialized settled base states, one per point (None where the run failed).

        With :meth:`save_states` they let a later run (the same FMU build) skip settling.
        """
        if not (self.can_get_state and self.can_serialize):
            raise ModelError(f"{self.fmu_path.name} cannot serialize its state")
        p, tasks, _ = self._tasks(p, conditions, perturb=False)
        results = self._run([replace(t, keep_state=True) for t in tasks], p, conditions)
        return [r.base_state if r.base is not None and r.base.ok else None for r in results]

    def save_states(self, path, states: list, conditions: OperatingConditions) -> Path:
        """Write settled states with this build's identity (GUID / token and SHA-256)."""
        path = Path(path)
        header = {"magic": STATE_MAGIC, "guid": self.guid, "fmu_sha256": self.sha256, "fmu": str(self.fmu_path),
                  "conditions": {k: v.tolist() for k, v in conditions.as_dict().items()},
                  "sizes": [0 if s is None else len(s) for s in states]}
        tmp = path.with_suffix(path.suffix + ".tmp")
        with open(tmp, "wb") as fh:
            fh.write(json.dumps(header).encode() + b"\n")
            for s in states:
                if s is not None:
                    fh.write(s)
        os.replace(tmp, path)
        return path

    def load_states(self, path) -> tuple[list, OperatingConditions]:
        """Read :meth:`save_states` output, refusing states of another FMU build.

        Raises
        ------
        InputError
            Not a state file, or a state saved by another build (named: its GUID and file).
        """
        path = Path(path)
        src = str(path)
        try:
            raw = path.read_bytes()
            head, _, body = raw.partition(b"\n")
            header = json.loads(head)
        except (OSError, ValueError):
            raise InputError("not a calib FMU state file", src) from None
        if not isinstance(header, dict) or header.get("magic") != STATE_MAGIC:
            raise InputError(f"not a calib FMU state file (expected magic {STATE_MAGIC!r})", src, field="magic")
        if header.get("guid") != self.guid or header.get("fmu_sha256") != self.sha256:
            raise InputError(f"state from another build: saved by the FMU with GUID {header.get('guid')} "
                             f"({header.get('fmu')}), this FMU {self.fmu_path.name} has GUID {self.guid}; settle "
                             "again with this build", src, field="guid")
        states, offset = [], 0
        for size in header["sizes"]:
            states.append(body[offset:offset + size] if size else None)
            offset += size
        if offset != len(body):
            raise InputError(f"state file truncated or padded ({len(body)} bytes of states, header says {offset})",
                             src, field="sizes")
        return states, OperatingConditions(**header["conditions"])

    def close(self) -> None:
        """Stop this model's worker processes in this process (workers elsewhere end with their executor)."""
        fw.close_workers(self._plan.key)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.fmu_path.name!r}, mapping={Path(self.mapping.source).name!r}, "
                f"{len(self._parameters)} parameters, channels={[c.name for c in self._channels]})")
