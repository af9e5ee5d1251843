"""One configuration layer: TOML tables checked by one schema mechanism.

Every table a user writes (a workflow's sections, a ``calib diagnose`` configuration, the
``[model]`` of the native BEM or of an FMU, ``[executor]``, ``[validation]``, a mapping file's
tables) is checked by :func:`check_table` against a schema: a dict key -> :class:`Key` (accepted
types, required, choices, a value check). A schema of a settings dataclass is derived from its
fields and defaults by :func:`schema_of`, so the Python API and the TOML keys cannot drift, and
:func:`settings_from_table` builds the typed settings object from the checked table. Every error
is an :class:`~calib.errors.InputError` naming the file and the key path (``section.key``), with
"did you mean" for an unknown key.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

from calib.errors import InputError, unknown_key

#: a number (an integer or a float; true/false is not a number)
NUM = (int, float)
#: "auto" or a number
AUTO_OR_NUM = (int, float, str)
#: a number or true/false
NUM_OR_BOOL = (int, float, bool)

TYPE_NAMES = {str: "a string", dict: "a table", list: "an array", bool: "true/false", int: "an integer",
              NUM: "a number", AUTO_OR_NUM: "\"auto\" or a number", (list, str): "an array or \"auto\"",
              NUM_OR_BOOL: "a number or true/false"}


@dataclass(frozen=True)
class Key:
    """One key of a table's schema.

    Attributes
    ----------
    types : type or tuple of types
        Accepted TOML types (:data:`NUM` for numbers; ``bool`` is never a number here).
    required : bool
    choices : tuple, optional
        The accepted values (strings, usually).
    check : callable(value) -> str or None, optional
        A further rule: returns what was expected ("must be > 0") when the value breaks it.
    """

    types: Any
    required: bool = False
    choices: tuple | None = None
    check: Callable[[Any], str | None] | None = None


def type_ok(value, types) -> bool:
    """``value`` is one of ``types``, where true/false counts only where ``bool`` is accepted."""
    accepted = types if isinstance(types, tuple) else (types,)
    if object in accepted:          # any value (a later validation checks it)
        return True
    if isinstance(value, bool):
        return bool in accepted
    return isinstance(value, accepted)


def check_table(table, schema: dict, section: str, source: str, *, table_label: str | None = None) -> dict:
    """Check ``table`` against ``schema``; returns it.

    Parameters
    ----------
    table : dict
    schema : dict
        key -> :class:`Key` (the one schema form).
    section : str
        The table's key path ("" for the top level), which prefixes every key in the errors.
    source : str
        The file (or the API call) the table came from.
    table_label : str, optional
        How to call the table in the "must be a table" error (default: ``'section'``).

    Raises
    ------
    TypeError
        A schema entry is not a :class:`Key` (a programming error, not the user's).
    InputError
        The table is not a table; an unknown key (with "did you mean"); a value of another type, outside
        its choices or breaking its check; a required key missing. ``field`` is the key path.
    """
    where = f"{section}." if section else ""
    not_keys = [name for name, key in schema.items() if not isinstance(key, Key)]
    if not_keys:
        raise TypeError(f"schema entries must be calib.config.Key, not {schema[not_keys[0]]!r} "
                        f"(key {where}{not_keys[0]!r})")
    if not isinstance(table, dict):
        raise InputError(f"{table_label or repr(section)} must be a table, got {table!r:.60}", source,
                         field=section or None)
    for name, value in table.items():
        if name not in schema:
            raise InputError(unknown_key(name, sorted(schema), where), source, field=f"{where}{name}")
        key = schema[name]
        if not type_ok(value, key.types):
            raise InputError(f"'{where}{name}' must be {TYPE_NAMES.get(key.types, key.types)}, got {value!r}",
                             source, field=f"{where}{name}")
        if key.choices is not None and value not in key.choices:
            raise InputError(f"must be one of {', '.join(map(str, key.choices))}, got {value!r}", source,
                             field=f"{where}{name}")
        if key.check is not None:
            expected = key.check(value)
            if expected:
                raise InputError(f"{expected}, got {value!r}", source, field=f"{where}{name}")
    for name, key in schema.items():
        if key.required and name not in table:
            raise InputError(f"missing required key '{where}{name}'", source, field=f"{where}{name}")
    return table


def toml_type(default, override=None):
    """The TOML type of a dataclass field from its default value (``override`` wins)."""
    if override is not None:
        return override
    if isinstance(default, bool):
        return bool
    if isinstance(default, int):
        return int
    if isinstance(default, float):
        return NUM
    if isinstance(default, str):
        return str
    if isinstance(default, (tuple, list)):
        return list
    return None


def schema_of(cls, exclude=(), overrides: dict | None = None) -> dict[str, Key]:
    """The keys of a settings dataclass: one per field (same name), typed by its default or ``overrides``
    (a type, or a whole :class:`Key` with its rule)."""
    overrides = overrides or {}
    out = {}
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        override = overrides.get(f.name)
        if isinstance(override, Key):         # a type with a rule
            out[f.name] = override
            continue
        default = f.default if f.default is not dataclasses.MISSING else None
        out[f.name] = Key(toml_type(default, override))
    return out


def _field_value(annotation: str, value):
    """A TOML value as a settings field of ``annotation`` holds it: an array as a tuple where the
    field is a tuple, an integer as a float where the field is a float."""
    kinds = {part.strip() for part in str(annotation).split("|")}
    if isinstance(value, list) and any(k == "tuple" or k.startswith("tuple[") for k in kinds):
        return tuple(value)
    if isinstance(value, int) and not isinstance(value, bool) and kinds <= {"float", "None"} and "float" in kinds:
        return float(value)
    return value


def settings_from_table(cls, table, section: str, source: str, schema: dict | None = None, *,
                        table_label: str | None = None):
    """The settings dataclass ``cls`` built from a TOML table, checked first.

    Parameters
    ----------
    cls : type
        A settings dataclass; each of its fields is the TOML key of the same name.
    table : dict
        The table as read (its keys the user's).
    section : str
        The table's key path, which prefixes every key in the errors.
    source : str
        The file (or the API call) the table came from.
    schema : dict, optional
        The table's keys (:func:`check_table`); default :func:`schema_of` ``(cls)``. Keys of the
        schema that are not fields of ``cls`` are checked and left to the caller.
    table_label : str, optional
        How to call the table in the "must be a table" error (:func:`check_table`).

    Returns
    -------
    The ``cls`` instance; arrays become tuples and integers floats where the field says so
    (its own ``validate``, where it has one, is the caller's to run with its context).

    Raises
    ------
    InputError
        As :func:`check_table`; or the settings refused the values (the section named).
    """
    check_table(table, schema_of(cls) if schema is None else schema, section, source, table_label=table_label)
    try:
        return cls(**field_values(cls, table))
    except InputError:
        raise
    except (TypeError, ValueError) as exc:
        raise InputError(f"[{section}]: {exc}", source, field=section or None) from None


def field_values(cls, table: dict) -> dict:
    """The values of a checked ``table`` that are fields of the settings dataclass ``cls``, as the
    fields hold them (arrays as tuples, integers as floats where the field says so), by field name."""
    annotations = {f.name: f.type for f in dataclasses.fields(cls)}
    return {k: _field_value(annotations[k], v) for k, v in table.items() if k in annotations}


def in_open_unit_interval(value) -> str | None:
    """A :class:`Key` check: a number in (0, 1)."""
    return None if 0 < value < 1 else "must be a number in (0, 1)"


def names_list(value) -> str | None:
    """A :class:`Key` check: an array of names (strings)."""
    return None if all(isinstance(v, str) for v in value) else "must be an array of names"
