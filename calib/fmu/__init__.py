"""FMUs: any vendor's co-simulation FMU as a ForwardModel, and the bundled test FMUs.

The adapter, from the archive to the model:

- :mod:`calib.fmu.archive`      zip checks, the extraction cache, the platform binary;
- :mod:`calib.fmu.mapping`      the declarative mapping file (inputs, outputs, parameters, nodes);
- :mod:`calib.fmu.mapping_entries` its entries: a mapped variable each, with its unit conversion;
- :mod:`calib.fmu.rules`        its ``[steady]`` and ``[jacobian]`` tables: the run and difference rules;
- :mod:`calib.fmu.fmu_file`     the FMU opened: model description read, matched to the mapping, extracted;
- :mod:`calib.fmu.variables`    the FMU's variables as a mapping uses them: lookup, roles, types, sizes;
- :mod:`calib.fmu.binding`      the mapping bound to them: checks, settings, parameters, inputs (writes);
- :mod:`calib.fmu.signals`      what a simulation reads (signals, counters) and the plan that carries it;
- :mod:`calib.fmu.channels`     channel names -> mapped signals, run outcomes -> channel values;
- :mod:`calib.fmu.stations`     which variables give the output-station and rotor radii, and the radii;
- :mod:`calib.fmu.plan`         picklable plans, tasks and outcomes; the adaptive timeout rule;
- :mod:`calib.fmu.windows`      steady-window statistics (mean, halves, azimuth harmonics);
- :mod:`calib.fmu.simulator`    one FMU instance driven in this process through fmpy;
- :mod:`calib.fmu.worker`       worker processes supervised: timeouts, faults, restarts; the per-process cache;
- :mod:`calib.fmu.child`        the worker process itself: a simulator answering requests;
- :mod:`calib.fmu.pipe`         the pipe protocol between them (length-prefixed pickles);
- :mod:`calib.fmu.faults`       the fault ledger: quarantine and healthy wall times;
- :mod:`calib.fmu.states`       settled FMU states saved to and read from files;
- :mod:`calib.fmu.tally`        what the simulations cost: counts, model time, busy and wall time, efficiency;
- :mod:`calib.fmu.base_runs`    base runs kept for reuse (same plan, point and parameters: simulated once);
- :mod:`calib.fmu.differences`  central or forward differences: perturbed parameter vectors, sensitivities;
- :mod:`calib.fmu.model`        :class:`~calib.fmu.model.FmuModel`, the thin adapter;
- :mod:`calib.fmu.bundled`      the bundled FMU of a workflow (``[model] variant``), built on demand.

The bundled FMUs' builder: :mod:`calib.fmu.build` (compiles ``fmu_models/``),
:mod:`calib.fmu.variant_spec` (reads and expands a variant's ``variables.toml``),
:mod:`calib.fmu.model_description` (renders ``modelDescription.xml`` and the C table) and
:mod:`calib.fmu.resources`.

Nothing is imported here, so a worker process (``python -m calib.fmu.child``) loads fmpy and
numpy only, not the calibration stack.
"""
