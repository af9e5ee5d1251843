"""Radii of the spanwise output stations and of the rotor, as a mapping reaches them in an FMU.

Only an initialized FMU knows them: :func:`radius_reads` lists the variables to read (value
reference and size), :func:`probe_radii` reads them from an instance initialized in a worker of
this process, and :func:`radii_from_reads` turns the values read into radii [m].
"""

from __future__ import annotations

import numpy as np

from calib.errors import ModelError
from calib.fmu import worker as fw
from calib.fmu.mapping import Mapping
from calib.fmu.signals import PlanSite, make_plan
from calib.fmu.variables import Variables


def radius_reads(m: Mapping, vs: Variables) -> list[tuple[int, int]]:
    """(value reference, size) of every radius variable the mapping names.

    Parameters
    ----------
    m : Mapping
        The mapping: spanwise outputs' ``radius_variables`` / ``radius_variable``, then ``[rotor] radius``
        when it is an FMU variable.
    vs : Variables
        The FMU's variables.

    Returns
    -------
    list of tuple
        In the order :func:`radii_from_reads` expects the values (empty when nothing is read).
    """
    reads = []
    for sp in m.spanwise.values():
        if sp.radius_variables:
            reads += [(vs.by_name[v].valueReference, 1) for v in sp.radius_variables]
        elif sp.radius_variable:
            var = vs.by_name[sp.radius_variable]
            reads.append((var.valueReference, vs.size(var)))
    if m.rotor_radius is not None and not isinstance(m.rotor_radius, float):
        reads.append((vs.by_name[m.rotor_radius.variable].valueReference, 1))
    return reads


def probe_radii(m: Mapping, vs: Variables, site: PlanSite, isolate: bool, timeout, fmu_name: str) -> dict:
    """The radii of :func:`radii_from_reads`, read from an FMU instance initialized for the purpose.

    Parameters
    ----------
    m : Mapping
        The mapping.
    vs : Variables
        The FMU's variables.
    site : PlanSite
        The FMU as a plan needs it (a plan reading the azimuth alone is made for the probe).
    isolate : bool
        Initialize the instance in a worker process (else in this process).
    timeout : float or TimeoutPolicy
        The worker's timeout (:func:`calib.fmu.worker.worker_for`).
    fmu_name : str
        The FMU's file name, for the error.

    Returns
    -------
    dict
        As :func:`radii_from_reads`; no instance is created when the mapping names no radius variable.

    Raises
    ------
    ModelError
        The instance could not be created or initialized, or the values not read. The probe's worker
        is closed in any case.
    """
    reads = radius_reads(m, vs)
    values = []
    if reads:
        plan, _ = make_plan(m, vs, site, [], None, signals_only=True)
        worker = fw.worker_for(plan, isolate, timeout)
        try:
            values = worker.probe(reads)
        except Exception as exc:  # noqa: BLE001
            raise ModelError(f"{fmu_name}: could not initialize the FMU to read radii: {exc}") from None
        finally:
            fw.close_workers(plan.key)
    return radii_from_reads(m, values)


def radii_from_reads(m: Mapping, values: list) -> dict:
    """Output-station radii and rotor radius from the values of :func:`radius_reads`.

    Parameters
    ----------
    m : Mapping
        The mapping whose :func:`radius_reads` were read.
    values : list of sequence of float
        One per read, its elements [FMU units].

    Returns
    -------
    dict
        ``radii``: spanwise output name -> station radii (ndarray) [FMU units, as read];
        ``rotor_radius``: [m] (the mapping's number or the converted variable; None without ``[rotor]``).
    """
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
    return {"radii": radii, "rotor_radius": radius}
