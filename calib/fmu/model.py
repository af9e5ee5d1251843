"""Any vendor's co-simulation FMU behind the ForwardModel contract.

:class:`FmuModel` is built from an FMU file and a mapping file
(:mod:`calib.fmu.mapping`). At load time it opens the FMU (:func:`calib.fmu.fmu_file.open_fmu`:
a zip archive whose entries all stay inside the extraction folder, a model description with
co-simulation, a binary for this platform; ``fmpy``'s non-fatal findings issued as warnings) and
binds the mapping to it (:mod:`calib.fmu.binding`: every mapped variable exists, inputs are
inputs, outputs are outputs, calibrated parameters and correction nodes are *tunable*
parameters, settings and switches are parameters, array elements are inside their arrays,
setting values inside the FMU's range), refusing with :class:`~calib.errors.InputError`
naming the file and the item.

It extracts the FMU once (cached by its SHA-256) and hands workers a picklable
:class:`~calib.fmu.plan.SimulationPlan` (never an instance). Simulations run through
:func:`calib.fmu.worker.run_point` on the model's executor (serial by default), in worker processes
with a timeout adapted to the healthy runs; a point that crashed or hung is quarantined by the model
(:class:`calib.fmu.faults.FaultLedger`, :meth:`FmuModel.fault_summary`).

Steady outputs: settle ``settle_revolutions``, then average ``average_revolutions`` whole
revolutions (``[steady]`` of the mapping); the status of a point says whether the two
halves of the window agree, whether the FMU failed, crashed or hung. Besides the means,
every mapped output ``x`` gives the azimuth harmonics ``x_1p``, ``x_2p``, ``x_3p``
(amplitude, unit of x) and ``x_1p_phase`` ... (deg), with x ≈ mean + Σ A_n cos(nψ + φ_n)
and ψ the azimuth of blade 1 (0 = up).

Jacobians: finite differences (forward at 0.1 × scale by default, or central; :class:`calib.fmu.rules.JacobianRule`), cold or warm-started from the settled
base state (:mod:`calib.fmu.differences`); a cold run (base or perturbed) simulated before at the same point
and parameter values, by any model of the same plan, is reused (:mod:`calib.fmu.base_runs`); what the
simulations cost is counted (:meth:`FmuModel.simulation_summary`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from calib.errors import InputError, ModelError
from calib.measurements import sha256_of
from calib.fmu import plan as fp
from calib.fmu import worker as fw
from calib.fmu.base_runs import BaseRunCache
from calib.fmu.binding import bind_inputs, bind_parameters, check_mapped_variables, fixed_assignments
from calib.fmu.bundled import spec_files
from calib.fmu.channels import channel_specs, evaluation_of, offered_channels
from calib.fmu.differences import method_words, perturbed_vectors, sensitivities
from calib.fmu.fmu_file import FmuFile, open_fmu
from calib.fmu.mapping import Mapping, load_mapping
from calib.fmu.rules import check_differences
from calib.fmu.signals import PlanSite, make_plan
from calib.fmu.states import read_states, write_states
from calib.fmu.stations import probe_radii
from calib.fmu.variables import Variables
from calib.models.base import Capabilities
from calib.fmu.faults import FaultLedger
from calib.fmu.tally import SimulationTally
from calib.parametrizations.correction_field import CorrectionField, seen_from_extras
from calib.types import Channel, Evaluation, OperatingConditions, Parameter, check_parameter_vector


class FmuModel:
    """A co-simulation FMU (FMI 2.0 or 3.0) as a ForwardModel.

    Parameters
    ----------
    fmu : str or Path
        The ``.fmu`` file.
    mapping : str, Path or Mapping
        Its mapping file (:func:`calib.fmu.mapping.load_mapping`).
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
        at least 5 s, never above this (:func:`calib.fmu.plan.adaptive_timeout`).
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
    base_runs : BaseRunCache, optional
        Runs simulated before, shared with other models (:mod:`calib.fmu.base_runs`); default its own.

    Notes
    -----
    Faults: a point whose simulation crashed the FMU process, hung or got a fatal status is
    quarantined, not simulated again by later calls, retried once at most when a parameter
    has moved one scale from where it failed; an error status is not quarantined
    (:class:`calib.fmu.faults.FaultLedger` says why). :meth:`fault_summary` reports
    the timeout in force, the quarantined points and the errors.
    """

    def __init__(self, fmu, mapping, channels: Sequence[str] | None = None,
                 parameters: Sequence[str] | None = None, corrections: bool = True,
                 switches: dict | None = None, settings: dict | None = None, steady: dict | None = None,
                 jacobian: dict | None = None, executor=None, timeout: float = fp.DEFAULT_TIMEOUT, isolate: bool = True,
                 build: dict | None = None, progress=None, start_timeout: float = fp.DEFAULT_TIMEOUT,
                 base_runs: BaseRunCache | None = None):
        self.fmu_path = Path(fmu).resolve()
        self.mapping: Mapping = mapping if isinstance(mapping, Mapping) else load_mapping(mapping)
        self._keep_file(open_fmu(self.fmu_path, self.mapping, warn_stacklevel=2))
        self._read_rules(steady, jacobian)
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
        self._bind(channels, parameters, corrections, switches or {}, settings or {})
        self.start_timeout = float(start_timeout)
        self._faults = FaultLedger([q.name for q in self._parameters], [q.scale for q in self._parameters],
                                   self.timeout, self.start_timeout, self.fmu_path.name)
        self._tally = SimulationTally()
        self.base_runs = base_runs if base_runs is not None else BaseRunCache()

    # ------------------------------------------------------------------ load-time steps
    def _keep_file(self, f: FmuFile) -> None:
        """Keep what :func:`~calib.fmu.fmu_file.open_fmu` found (model description, identity, capabilities)
        as attributes, and the FMU's variables as this model's mapping uses them."""
        self.model_description = f.model_description
        self.binary = f.binary
        self.sha256 = f.sha256
        self.unzip_dir = f.unzip_dir
        self.guid = f.guid
        self.can_get_state = f.can_get_state
        self.can_serialize = f.can_serialize
        self.offers_directional_derivatives = f.offers_directional_derivatives
        self._variables = Variables(f.model_description, self.fmu_path.name, self.mapping.source)

    def _read_rules(self, steady: dict | None, jacobian: dict | None) -> None:
        """The steady window and the difference rule: the mapping's ``[steady]`` and ``[jacobian]``
        with this model's overrides (an unknown jacobian option refused, naming the valid ones)."""
        m = self.mapping
        steady_rule = m.steady.replace(**(steady or {})) if steady else m.steady
        jac = dict(vars(m.jacobian))
        for key, value in (jacobian or {}).items():
            if key not in jac:
                raise InputError(f"unknown jacobian option {key!r}; valid: {', '.join(jac)}", "FmuModel",
                                 field="jacobian")
            jac[key] = value
        self.relative_step = float(jac["relative_step"])
        self.warm_start = bool(jac["warm_start"])
        self.differences = check_differences(jac["differences"], "FmuModel")
        self.steady = steady_rule

    def _bind(self, channels, parameters, corrections: bool, switches: dict, settings: dict) -> None:
        """Bind the mapping to the FMU (:mod:`calib.fmu.binding`): the mapped variables checked, the fixed
        assignments, the calibrated parameters and the inputs, the channels and the plan that reads them."""
        m, vs, md = self.mapping, self._variables, self.model_description
        check_mapped_variables(m, vs)
        self._site = PlanSite(md.fmiVersion, md.coSimulation.modelIdentifier, self.guid, self.unzip_dir, self.sha256,
                              fixed_assignments(m, vs, switches, settings), self.steady, self.can_get_state,
                              self.can_serialize)
        self._params = bind_parameters(m, vs, parameters, corrections, self.unzip_dir)
        self.grid = self._params.grid
        self._parameters = self._params.parameters
        self._inputs = bind_inputs(m, vs)
        self._probed: dict | None = None
        self._channel_specs = channel_specs(m, channels, self._spanwise_eta, self.available_channels,
                                            self.fmu_path.name)
        self._channels = tuple(Channel(n, u) for n, _, _, _, u in self._channel_specs)
        self._plan, self._keys_for_values = make_plan(m, vs, self._site, self._channel_specs, self.grid)

    # ------------------------------------------------------------------ channels
    def _probe(self) -> dict:
        """Rotor radius and output-station radii, read from an initialized instance (once):
        :func:`calib.fmu.stations.probe_radii`."""
        if self._probed is None:
            self._probed = probe_radii(self.mapping, self._variables, self._site, self.isolate, self.timeout,
                                       self.fmu_path.name)
        return self._probed

    def _spanwise_eta(self, name: str) -> np.ndarray | None:
        pr = self._probe()
        if name not in pr["radii"] or pr["rotor_radius"] is None:
            return None
        return pr["radii"][name] / pr["rotor_radius"]

    def available_channels(self) -> list[str]:
        """Channel names this FMU offers through its mapping (harmonics as patterns)."""
        return offered_channels(self.mapping, self._spanwise_eta)

    # ------------------------------------------------------------------ contract
    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return self._parameters

    @property
    def channels(self) -> tuple[Channel, ...]:
        return self._channels

    @property
    def jacobian_method(self) -> str:
        """How :meth:`jacobian` differentiates, and why (:func:`calib.fmu.differences.method_words`)."""
        return method_words(self.differences, self.relative_step, self.warm_start and self.can_get_state,
                            self.offers_directional_derivatives)

    def _fmu_parameter_values(self, p: np.ndarray) -> tuple:
        return self._params.assignments(p)

    def _fmu_inputs(self, conditions: OperatingConditions) -> list[tuple]:
        return self._inputs.assignments(self.mapping, conditions)

    def _run(self, tasks: list, p, conditions) -> list:
        """Results of ``tasks`` at ``p``: quarantined points are not simulated (the ledger
        fills their results), the others run on the executor with the adaptive timeout."""
        run, results = self._faults.plan(tasks, p, len(self._plan.signals))
        policy = self._faults.policy()
        cold, canon = not (self.warm_start and self.can_get_state), self._params.canonical
        send, *reused = self.base_runs.split(self._plan.key, tasks, run, results, cold, canon)
        self._tally.add_reused(*reused)
        jobs = [(self._plan, tasks[k], self.isolate, policy) for k in send]
        done = self._tally.timed_map(self.executor, fw.run_point, jobs, self.progress)
        for k, r in zip(send, done):
            results[k] = r
            self.base_runs.put_result(self._plan.key, tasks[k], r, cold, canon)
        self._faults.record(tasks, results, run, p, conditions)
        return results

    def fault_summary(self) -> dict:
        """Faults met by this model's simulations so far, as a plain (JSON-able) dict.

        Returns
        -------
        dict
            ``fmu`` (the file's name), then :meth:`calib.fmu.faults.FaultLedger.summary`: ``timeout``
            (configured, in force, the healthy runs' median and its changes), ``quarantine`` (one dict
            per quarantined point: conditions, fault, message, retries), ``errors`` (points with an
            error status), ``counts`` (calls, points simulated and skipped, runs per kind of fault),
            ``rules`` (quarantined fault kinds, retry distance); ``simulations`` (:meth:`simulation_summary`).
        """
        return {"fmu": self.fmu_path.name, **self._faults.summary(), "simulations": self.simulation_summary()}

    def simulation_summary(self) -> dict:
        """What this model's simulations cost so far: :meth:`calib.fmu.tally.SimulationTally.summary` (counts,
        model time, busy worker and wall time [s], parallel efficiency)."""
        return self._tally.summary()

    def clear_quarantine(self) -> None:
        """Simulate quarantined points again from now on (e.g. a new stage); the timeout statistics are kept."""
        self._faults.clear()

    def _tasks(self, p, conditions, perturb: bool, start_states=None):
        p = check_parameter_vector(p, self._parameters, "FmuModel parameter vector")
        base = self._fmu_parameter_values(p)
        inputs = self._fmu_inputs(conditions)
        perturbations, steps = (), None
        if perturb:
            vectors, steps = perturbed_vectors(p, self._parameters, self.relative_step, self.differences)
            perturbations = tuple(self._fmu_parameter_values(q) for q in vectors)
        if start_states is not None and len(start_states) != len(conditions):
            raise InputError(f"{len(start_states)} start states for {len(conditions)} operating points", "FmuModel",
                             field="start_states")
        tasks = [fp.PointTask(k, inputs[k], base, perturbations, float(conditions.rotor_speed[k]),
                              self.warm_start, start_state=None if start_states is None else start_states[k])
                 for k in range(len(conditions))]
        return p, tasks, steps

    def _evaluation(self, results, conditions) -> Evaluation:
        """The :class:`~calib.types.Evaluation` of ``results`` (:func:`calib.fmu.channels.evaluation_of`), with
        the angles of attack at the stations when this model calibrates a correction field."""
        aoa = self.grid is not None and "angle_of_attack" in self.mapping.spanwise
        return evaluation_of(results, conditions, self._channel_specs, self._keys_for_values, self._channels,
                             self._spanwise_eta("angle_of_attack") if aoa else None)

    def evaluate(self, p, conditions: OperatingConditions, start_states=None) -> Evaluation:
        """Steady channel values (n_points, n_channels) and a status per point at ``p``.

        ``start_states`` (from :meth:`load_states`, one per point or None) start each base
        run from a settled state of this build instead of from scratch: it then settles only
        ``perturbation_settle_revolutions``.
        """
        p, tasks, _ = self._tasks(p, conditions, perturb=False, start_states=start_states)
        return self._evaluation(self._run(tasks, p, conditions), conditions)

    def jacobian(self, p, conditions: OperatingConditions, start_states=None):
        """Finite-difference sensitivities ``G[k, c, j] = d y[k, c] / d p[j]`` (central, or forward against
        the base run with ``jacobian={"differences": "forward"}``).

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
        return sensitivities(results, self._evaluation(results, conditions), steps, self._channel_specs,
                             self._keys_for_values, [q.name for q in self._parameters], self.differences)

    # ------------------------------------------------------------------ declared capabilities
    @property
    def has_correction_field(self) -> bool:
        """The mapping maps correction nodes and this model calibrates them (``corrections=True``)."""
        return bool(self._options["corrections"]) and self.mapping.corrections is not None

    @property
    def capabilities(self) -> Capabilities:
        """Rebuildable from its spec, finite-difference Jacobians, workers to close; a correction field
        when :attr:`has_correction_field` (named ``FmuFieldModel`` in results then), never refinable (the
        nodes are the FMU's own); the difference step its ``relative_step``."""
        field = self.has_correction_field
        return Capabilities("FmuFieldModel" if field else "FmuModel", correction_field=field, rebuildable=True,
                            derivatives="finite_difference", closes=True, difference_step=self.relative_step)

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
        """Rebuild from :meth:`spec` (rebuilding a bundled variant when its file is gone:
        :func:`calib.fmu.bundled.spec_files`)."""
        fmu, mapping = spec_files(spec, base_dir)
        opts = {k: spec[k] for k in ("parameters", "corrections", "switches", "settings", "steady", "jacobian",
                                     "timeout", "isolate") if k in spec}
        return cls(fmu, mapping, spec.get("channels"), build=spec.get("build"), **opts)

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
        """Write settled states with this build's identity (GUID / token and SHA-256): :func:`calib.fmu.states.write_states`."""
        return write_states(path, states, conditions, self.guid, self.sha256, self.fmu_path)

    def load_states(self, path) -> tuple[list, OperatingConditions]:
        """Read :meth:`save_states` output, refusing states of another FMU build (:func:`calib.fmu.states.read_states`)."""
        return read_states(path, self.guid, self.sha256, self.fmu_path.name)

    def close(self) -> None:
        """Stop this model's worker processes in this process (workers elsewhere end with their executor)."""
        fw.close_workers(self._plan.key)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.fmu_path.name!r}, mapping={Path(self.mapping.source).name!r}, "
                f"{len(self._parameters)} parameters, channels={[c.name for c in self._channels]})")
