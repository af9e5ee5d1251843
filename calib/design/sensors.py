"""Sensor groups of a campaign design: named sets of the model's channels, each with a cost.

Built-in groups: ``hub`` (power, thrust), ``torque``, ``root`` (root flap and edge moments),
``station@ETA`` (spanwise normal and tangential force per length at the radial station η),
``taps@ETA`` (the normal and tangential force coefficients a pressure-tap station gives), ``workflow`` (the workflow's stage channels, the default); any single model
channel is a group of itself. A group is written ``NAME`` or ``NAME:COST`` (cost per operating
point, default 1).
"""

from __future__ import annotations

from dataclasses import dataclass

from calib.errors import InputError

__all__ = ["SensorGroup", "parse_groups", "BUILT_IN"]

BUILT_IN = {"hub": ("power", "thrust"), "torque": ("torque",), "root": ("root_flap_moment", "root_edge_moment")}


@dataclass(frozen=True)
class SensorGroup:
    """A named set of channels measured together, with a cost per operating point [user units]."""

    name: str
    channels: tuple
    cost: float = 1.0


def available_words() -> str:
    """The group names a user may give, in words."""
    return (", ".join(BUILT_IN) + ", station@ETA (fn@ETA and ft@ETA at radial station ETA in (0, 1]), taps@ETA "
            "(the pressure-tap coefficients cn@ETA and ct@ETA), workflow "
            "(the stage channels), or a channel name of the model")


def parse_groups(specs, workflow_channels, source: str = "--sensors") -> list[SensorGroup]:
    """Sensor groups from ``NAME[:COST]`` texts; the default (none given) is ``workflow``.

    Raises
    ------
    InputError
        A cost that is not a number > 0, a malformed station, or a group given twice. Whether
        the model produces the channels is checked when it is built (:func:`check_groups`).
    """
    specs = list(specs or ["workflow"])
    out, seen = [], set()
    for text in specs:
        name, _, cost_text = str(text).strip().partition(":")
        name = name.strip()
        try:
            cost = float(cost_text) if cost_text else 1.0
            if not cost > 0:
                raise ValueError
        except ValueError:
            raise InputError(f"sensor group {text!r}: the cost after ':' must be a number > 0", source,
                             field=name) from None
        if name in seen:
            raise InputError(f"sensor group {name!r} given twice", source, field=name)
        seen.add(name)
        if name == "workflow":
            chans = tuple(workflow_channels)
        elif name in BUILT_IN:
            chans = BUILT_IN[name]
        elif name.startswith(("station@", "taps@")):
            kind, eta = name.split("@", 1)
            try:
                if not 0 < float(eta) <= 1:
                    raise ValueError
            except ValueError:
                raise InputError(f"sensor group {name!r}: the station must be a radial position η in (0, 1], "
                                 f"e.g. {kind}@0.47", source, field=name) from None
            chans = (f"fn@{eta}", f"ft@{eta}") if kind == "station" else (f"cn@{eta}", f"ct@{eta}")
        elif name:
            chans = (name,)
        else:
            raise InputError(f"empty sensor group in {text!r}; available: {available_words()}", source, field="sensors")
        out.append(SensorGroup(name, chans, cost))
    return out


def check_groups(groups, build, source: str = "--sensors"):
    """Build the model with every group's channels (``build(channels)``); a group whose channels
    the model cannot produce gets an :class:`InputError` naming it and the available groups."""
    channels = []
    for g in groups:
        try:
            build(list(g.channels))
        except InputError as exc:
            raise InputError(f"sensor group {g.name!r} ({', '.join(g.channels)}): the model cannot produce it "
                             f"({exc.message}); available: {available_words()}", source, field=g.name) from None
        channels += [c for c in g.channels if c not in channels]
    return build(channels), channels
