"""What an FMU simulation is asked and what it answers: plans, tasks, outcomes, the timeout rule.

Picklable values only (paths, names, numbers; never an FMU instance): an executor sends them to
worker processes (:mod:`calib.fmu.worker`), which run them with a :class:`~calib.fmu.simulator.Simulator`.
:func:`adaptive_timeout` is the rule by which a simulation counts as hung: a multiple of the median
wall time of the healthy runs measured so far, within a floor and the configured ceiling.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.types import Status

HARMONIC_ORDERS = (1, 2, 3)
REAL_TYPES = ("Real", "Float64")
INTEGER_TYPES = ("Integer", "Int32", "Enumeration")
BOOLEAN_TYPES = ("Boolean",)

#: Time a simulation (and a worker's start) may take before it counts as hung [s], unless configured
DEFAULT_TIMEOUT = 60.0
#: Adaptive timeout: this multiple of the median wall time of healthy base runs [-] ...
TIMEOUT_MULTIPLE = 10.0
#: ... but never below this [s] (and never above the configured timeout)
TIMEOUT_FLOOR = 5.0
#: Healthy base-run wall times kept for the median (the most recent ones)
HEALTHY_WALLS_KEPT = 99
#: A quarantined point is retried (once) when a parameter has moved this many of its scales
RETRY_DISTANCE = 1.0
#: Faults that quarantine a point (expensive: a new process, a wait for the timeout)
QUARANTINE_FAULTS = ("crash", "timeout", "fatal")
#: fmi2Fatal / fmi3Fatal: no FMI call of any instance is allowed afterwards
FMI_FATAL = 4




# ----------------------------------------------------------------------------- plan and tasks
@dataclass(frozen=True)
class Assignment:
    """Values written to FMI variables of one type in one call.

    ``vrs`` are value references; ``values`` holds one value per scalar (FMI 2) or all
    elements of the arrays in order (FMI 3).
    """

    type: str                 # "real" | "integer" | "boolean"
    vrs: tuple[int, ...]
    values: tuple


@dataclass(frozen=True)
class Signal:
    """A signal read at every communication step, converted to package units."""

    name: str
    index: int                # position in the flat vector of Real / Float64 values read per step
    scale: float = 1.0
    offset: float = 0.0
    sign: int = 1
    wrap: float | None = None


@dataclass(frozen=True)
class Counter:
    """An integer output read at the start and end of the averaging window (e.g. solver failures)."""

    name: str
    vr: int
    type: str


@dataclass(frozen=True)
class SimulationPlan:
    """Everything a worker needs to simulate (picklable; no instance, no open library).

    Attributes
    ----------
    key : str
        Identity of the plan (FMU content hash and settings); workers are cached by it.
    fixed : tuple of Assignment
        Settings and switches, written after every reset before initialization.
    read_vrs, read_count : tuple of int, int
        Real outputs read per step in one call and the number of values they return.
    signals : tuple of Signal
    azimuth : int or None
        Index of the blade-1 azimuth signal [deg] in ``signals`` (harmonics and phases).
    checked : tuple of int
        Signals whose two half-window means must agree (convergence check).
    """

    key: str
    fmi_version: str
    model_identifier: str
    guid: str
    unzip_dir: str
    fixed: tuple[Assignment, ...]
    read_vrs: tuple[int, ...]
    read_count: int
    signals: tuple[Signal, ...]
    azimuth: int | None
    checked: tuple[int, ...]
    counters: tuple[Counter, ...]
    steady: object            # calib.fmu.rules.SteadyRule
    can_get_state: bool
    can_serialize: bool
    instance_name: str = "calib"


@dataclass(frozen=True)
class PointTask:
    """The runs of one operating point: the base run, then perturbed runs.

    Attributes
    ----------
    index : int
        Position of the point in the batch.
    inputs : tuple of Assignment
        The operating condition (FMU values).
    base : tuple of Assignment
        The parameter values of the base run.
    perturbations : tuple of tuple of Assignment
        Parameter values of each perturbed run (all parameters, perturbed ones changed).
    rotor_speed : float
        [rpm], for the window.
    warm : bool
        Start perturbed runs from the base run's settled state (if the FMU can save it).
    base_state : bytes or None
        A serialized settled base state to resume from (the base run is then skipped).
    skip : int
        Number of perturbed runs already done (resume after a fault).
    keep_state : bool
        Return the serialized settled base state even without perturbations.
    start_state : bytes or None
        A serialized settled state (this build) the base run starts from instead of from
        scratch; it then settles only ``perturbation_settle_revolutions``.
    known_base : RunOutcome or None
        The outcome of this base run, simulated before (:mod:`calib.fmu.base_runs`): not simulated
        again (perturbed runs then start cold).
    known_runs : tuple of (RunOutcome or None), optional
        Per perturbed run, its outcome when a cold run at the same parameters was simulated before
        (:mod:`calib.fmu.base_runs`): not simulated again. Only for cold perturbed runs (``warm`` off).
    """

    index: int
    inputs: tuple[Assignment, ...]
    base: tuple[Assignment, ...]
    perturbations: tuple[tuple[Assignment, ...], ...] = ()
    rotor_speed: float = 0.0
    warm: bool = True
    base_state: bytes | None = None
    skip: int = 0
    keep_state: bool = False
    start_state: bytes | None = None
    known_base: "RunOutcome | None" = None
    known_runs: "tuple | None" = None


@dataclass
class RunOutcome:
    """Result of one simulation (a base or a perturbed run).

    Attributes
    ----------
    status : int
        :class:`calib.types.Status`.
    message : str
    mean : ndarray, shape (n_signals,)
        Window means in package units (NaN on failure).
    halves : ndarray, shape (2, n_signals)
    harmonics : ndarray of complex, shape (n_signals, 3)
        c_1, c_2, c_3 (see the module docstring); NaN at standstill.
    counters : dict
        Increase of each counter over the averaging window.
    steps : int
        Communication steps taken.
    wall : float
        [s], including ``instantiation``.
    fault : str
        ``""`` (no fault: converged, or a status computed from the outputs), ``"error"`` (an
        FMI call returned an error status or raised), ``"fatal"`` (an FMI call returned
        fmi2Fatal / fmi3Fatal: the worker process is replaced), ``"crash"`` (the process
        hosting the FMU died), ``"timeout"`` (the run hung), ``"start-timeout"`` (creating
        the instance exceeded the start timeout), ``"quarantined"`` (not simulated: see
        :class:`FaultLedger`).
    instantiation : float
        Part of ``wall`` spent creating the FMU instance [s] (0 when the instance was reused).
    simulated : float
        Model time simulated, settling included [s] (0 when the run failed).
    reused : bool
        The outcome of an earlier identical run, not simulated again (:mod:`calib.fmu.base_runs`).
    """

    status: int
    message: str
    mean: np.ndarray
    halves: np.ndarray
    harmonics: np.ndarray
    counters: dict = field(default_factory=dict)
    steps: int = 0
    wall: float = 0.0
    fault: str = ""
    instantiation: float = 0.0
    simulated: float = 0.0
    reused: bool = False

    @classmethod
    def failed(cls, n_signals: int, status: int, message: str, wall: float = 0.0, fault: str = "") -> "RunOutcome":
        nan = np.full(n_signals, np.nan)
        return cls(int(status), message, nan, np.full((2, n_signals), np.nan),
                   np.full((n_signals, len(HARMONIC_ORDERS)), np.nan + 0j), {}, 0, wall, fault)

    @property
    def ok(self) -> bool:
        return self.status == Status.CONVERGED


@dataclass
class PointResult:
    """The runs of one :class:`PointTask` (``perturbations[j]`` None if never run).

    ``timeout`` is the simulation timeout in force when the task ended [s] (None in
    process: no timeout); ``busy`` the wall time the executor's worker spent on the task [s]
    (:func:`calib.fmu.worker.run_point`).
    """

    index: int
    base: RunOutcome | None
    perturbations: list
    restarts: int = 0
    base_state: bytes | None = None
    timeout: float | None = None
    busy: float = 0.0

    def outcomes(self) -> list:
        """The runs made, base first (perturbed runs never run left out)."""
        return [o for o in (self.base, *self.perturbations) if o is not None]


# ----------------------------------------------------------------------------- adaptive timeout
def adaptive_timeout(healthy_walls, configured: float, multiple: float = TIMEOUT_MULTIPLE,
                     floor: float = TIMEOUT_FLOOR) -> float:
    """Simulation timeout from the wall times of healthy runs.

    ``min(configured, max(floor, multiple * median(healthy_walls)))``; ``configured`` while
    no healthy run has been measured.

    Parameters
    ----------
    healthy_walls : sequence of float
        Wall times of converged base runs (cold, full window, instantiation excluded) [s].
    configured : float
        The user's timeout [s]: the rule never exceeds it.
    multiple : float
        [-]; 10 covers the spread of a healthy point's cost over the operating range and
        the slowdown of a loaded machine, and still stops a hang after ten healthy runs' worth.
    floor : float
        [s]; scheduling hiccups of a shared machine (seconds) must not kill a healthy run of
        a fast FMU (milliseconds).
    """
    walls = np.asarray(healthy_walls, float)
    if walls.size == 0:
        return float(configured)
    return float(min(configured, max(floor, multiple * float(np.median(walls)))))


@dataclass(frozen=True)
class TimeoutPolicy:
    """The timeouts a worker applies (picklable; sent with every task).

    Attributes
    ----------
    configured : float
        The user's timeout of one simulation [s] (the upper limit).
    multiple, floor : float
        Of :func:`adaptive_timeout` [-], [s].
    walls : tuple of float
        Healthy base-run wall times measured so far by the model (the planning process) [s].
    start_timeout : float
        Longest wall time for a worker process to start and for an FMU instance to be
        created [s]: instantiation is timed apart from the simulations.
    """

    configured: float
    multiple: float = TIMEOUT_MULTIPLE
    floor: float = TIMEOUT_FLOOR
    walls: tuple = ()
    start_timeout: float = DEFAULT_TIMEOUT

    def timeout(self, more=()) -> float:
        """The simulation timeout [s] from ``walls`` and ``more`` (a worker's own measurements)."""
        return adaptive_timeout((*self.walls, *more), self.configured, self.multiple, self.floor)


def policy_of(timeout) -> TimeoutPolicy:
    return timeout if isinstance(timeout, TimeoutPolicy) else TimeoutPolicy(float(timeout))


