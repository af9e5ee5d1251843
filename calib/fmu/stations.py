"""Radii of the spanwise output stations and of the rotor, as a mapping reaches them in an FMU.

Only an initialized FMU knows them: :func:`radius_reads` lists the variables to read (value
reference and size) and :func:`radii_from_reads` turns the values read into radii [m]. Reading
them (an instance, in a worker) is :class:`calib.fmu.model.FmuModel`'s affair.
"""

from __future__ import annotations

import numpy as np

from calib.fmu.mapping import Mapping
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
