"""The mapping bound to the model description (calib.fmu.binding, calib.fmu.signals): checked and planned
without simulating.

The binding is pure: the bundled variant A's model description and mapping go in, parameters,
inputs, channels and a simulation plan come out; no FMU instance is created. The expectations
are the mapping file's own statements (its [parameters] table, its units), read independently
of the binding here.
"""

from __future__ import annotations

import tomllib
from dataclasses import replace

import numpy as np
import pytest

from calib.corrections import CorrectionGrid
from calib.fmu.archive import FmuInputError, check_archive, extract_once
from calib.fmu.binding import bind_inputs, bind_parameters, check_mapped_variables, fixed_assignments
from calib.fmu.channels import channel_specs
from calib.fmu.build import build_fmu, mapping_path
from calib.fmu.mapping import load_mapping
from calib.fmu.signals import PlanSite, make_plan
from calib.fmu.variables import Variables
from calib.measurements import sha256_of
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions

GRID = CorrectionGrid([0.0, 5.0, 10.0], [0.4, 0.9])


@pytest.fixture(scope="module")
def bound():
    from fmpy.model_description import read_model_description

    fmu = build_fmu("A", load_rotor("nrel5mw"), GRID)
    check_archive(fmu)
    md = read_model_description(str(fmu), validate=False)
    mapping = load_mapping(mapping_path("A"))
    return fmu, md, mapping, Variables(md, fmu.name, mapping.source), extract_once(fmu, sha256_of(fmu))


def test_parameters_are_the_mappings_with_its_bounds_and_units(bound):
    _, _, mapping, vs, unzip = bound
    table = tomllib.loads(mapping_path("A").read_text())["parameters"]
    pb = bind_parameters(mapping, vs, None, False, unzip)
    assert [q.name for q in pb.parameters] == list(table)
    for q in pb.parameters:
        row = table[q.name]
        assert (q.nominal, q.lower, q.upper, q.scale, q.unit) == (row["nominal"], row["lower"], row["upper"],
                                                                   row["scale"], row["unit"])
    # with the correction field: its nodes first (lift block, drag block), then the same parameters
    pf = bind_parameters(mapping, vs, None, True, unzip)
    assert pf.grid is not None and len(pf.parameters) == pf.grid.n_params + len(table)
    assert [q.name for q in pf.parameters[pf.grid.n_params:]] == list(table)
    # a parameter vector becomes one real assignment with the values in FMU units (here degrees and -)
    p = np.array([0.5, -1.0, 0.0, 1.2])
    [assignment] = pb.assignments(p)
    assert assignment.type == "real" and len(assignment.values) == len(assignment.vrs) == 4
    np.testing.assert_allclose(assignment.values, p, rtol=0, atol=1e-15)


def test_inputs_convert_conditions_and_refuse_an_unmapped_one(bound):
    _, _, mapping, vs, _ = bound
    ib = bind_inputs(mapping, vs)
    cond = OperatingConditions(np.array([8.0, 10.0]), np.array([9.0, 11.0]), np.array([0.0, 2.0]))
    rows = ib.assignments(mapping, cond)
    assert len(rows) == 2 and all(len(r) == 1 for r in rows)
    fields = list(ib.fields)
    assert {"wind_speed", "rotor_speed", "pitch"} <= set(fields)
    stripped = replace(mapping, inputs={k: v for k, v in mapping.inputs.items() if k != "pitch"})
    with pytest.raises(Exception, match="set pitch .* but the mapping maps no input for it"):
        bind_inputs(stripped, vs).assignments(stripped, cond)


def test_a_misspelt_variable_is_named_with_a_suggestion(bound):
    _, _, mapping, vs, _ = bound
    entry = mapping.parameters["stall_delay_strength"]
    bad = replace(mapping, parameters={**mapping.parameters,
                                       "stall_delay_strength": replace(entry, variable="stall_delay_strenght")})
    with pytest.raises(FmuInputError, match="'stall_delay_strenght' does not exist .* did you mean "
                                            "'stall_delay_strength'") as err:
        check_mapped_variables(bad, vs)
    assert err.value.field == "parameters.stall_delay_strength"


def test_a_setting_outside_the_fmus_range_is_refused(bound):
    _, _, mapping, vs, _ = bound
    assert fixed_assignments(mapping, vs, {}, {})        # the mapping's defaults are valid
    with pytest.raises(FmuInputError, match="outside its range"):
        fixed_assignments(mapping, vs, {}, {"max_internal_step": -1.0})


def test_the_plan_reads_what_the_channels_need_and_its_key_is_its_content(bound):
    fmu, md, mapping, vs, unzip = bound
    site = PlanSite(md.fmiVersion, md.coSimulation.modelIdentifier, md.guid, unzip, sha256_of(fmu),
                    fixed_assignments(mapping, vs, {}, {}), mapping.steady, True, True)
    no_radii = lambda name: None  # noqa: E731  (spanwise stations need an initialized FMU: not asked here)
    specs = channel_specs(mapping, ["power", "thrust_1p", "thrust_1p_phase"], no_radii, lambda: [], fmu.name)
    assert [(s[0], s[2], s[3], s[4]) for s in specs] == [("power", "mean", 0, "W"), ("thrust_1p", "amplitude", 1, "N"),
                                                         ("thrust_1p_phase", "phase", 1, "deg")]
    plan, keys = make_plan(mapping, vs, site, specs, None)
    assert {k[1] for k in keys if k[0] == "out"} >= {"power", "thrust", "azimuth"}
    again, _ = make_plan(mapping, vs, site, specs, None)
    assert again.key == plan.key
    other, _ = make_plan(mapping, vs, replace(site, steady=mapping.steady.replace(average_revolutions=4)), specs, None)
    assert other.key != plan.key
    with pytest.raises(Exception, match="'lift' is not provided by"):
        channel_specs(mapping, ["lift"], no_radii, lambda: ["power"], fmu.name)
