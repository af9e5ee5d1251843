"""The workflow keys' reference, generated from the settings dataclasses (so it cannot drift).

Each settings dataclass (:class:`calib.calibration.settings.CalibrationSettings`,
:class:`calib.bem.BemSettings`, :class:`calib.diagnosis.core.DiagnosisSettings`,
:class:`calib.workflow.validation.ValidationSettings`) documents its fields in the numpydoc ``Parameters``
section of its docstring; :func:`settings_markdown` turns fields, defaults and those descriptions
into the table of the documentation's settings page (``docs/hooks.py`` calls it when the site is
built), and :func:`undocumented_fields` lists any field without a description (a test keeps it
empty).
"""

from __future__ import annotations

import dataclasses
import inspect
import re


def parameter_docs(cls) -> dict[str, tuple[str, str]]:
    """name -> (type, description) from the ``Parameters`` section of ``cls``'s docstring.

    Entries are ``name : type`` lines (several names may share one: ``a, b : bool``) followed by
    indented description lines; the section ends at the next underlined heading or the end.
    """
    doc = inspect.getdoc(cls) or ""
    m = re.search(r"^Parameters\n-+\n(.*?)(?:^\S[^\n]*\n-+\n|\Z)", doc, re.S | re.M)
    if not m:
        return {}
    out, names, typ, desc = {}, [], "", []

    def flush():
        for n in names:
            out[n] = (typ, " ".join(" ".join(desc).split()))

    for line in m.group(1).splitlines():
        if line and not line.startswith(" "):
            flush()
            head, _, typ = line.partition(" : ")
            names, typ, desc = [n.strip() for n in head.split(",") if n.strip()], typ.strip(), []
        elif line.strip():
            desc.append(line.strip())
    flush()
    return out


def undocumented_fields(cls, exclude=("verbose",)) -> list[str]:
    """The dataclass fields of ``cls`` that its docstring does not describe."""
    docs = parameter_docs(cls)
    return [f.name for f in dataclasses.fields(cls) if f.name not in docs and f.name not in exclude]


def _default(f) -> str:
    if f.default is not dataclasses.MISSING:
        value = f.default
    elif f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
    else:
        return "(required)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if value is None:
        return "(none)"
    return str(value)


def settings_markdown(cls, section: str, exclude=("verbose",)) -> str:
    """A Markdown table of the ``[section]`` keys: key, default, type, meaning."""
    docs = parameter_docs(cls)
    rows = ["| key | default | type | meaning |", "|---|---|---|---|"]
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        typ, desc = docs.get(f.name, ("", "(undocumented)"))
        cell = desc.replace("|", "\\|")
        rows.append(f"| `{section}.{f.name}` | `{_default(f)}` | {typ.replace('|', ' or ')} | {cell} |")
    return "\n".join(rows) + "\n"
