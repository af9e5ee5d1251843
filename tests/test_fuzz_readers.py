"""Fuzzed inputs: every reader either parses a malformed file into a valid object or refuses it
with :class:`~calib.errors.InputError` naming the file and the line or key; never another
exception, never a hang, never a silent NaN.

Each strategy starts from the real files shipped with the package and the tests (the OpenFAST
r-test deck, ``calib/data``, ``workflows/*.toml``, ``fmu_models/variant_*/mapping.toml``, the
windIO files) and mutates them: truncation, deleted / duplicated / swapped lines, garbled,
swapped or deleted tokens, NaN / inf / huge numbers, random bytes, other encodings, empty and
binary files; TOML and YAML files also get structural mutations (missing keys, wrong types,
unknown keys, non-finite numbers). Examples are derandomized, so CI runs the same cases;
``CALIB_FUZZ_EXAMPLES=4000 CALIB_FUZZ_RANDOM=1`` runs a longer campaign with fresh examples.

The plain tests at the end are regressions for the defects the fuzzing found, and for those
found by probes written while fixing them (pathological sizes: long names, many columns,
YAML alias bombs, regular-expression backtracking), each failing on the code before its fix.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import json
import math
import os
import re
import shutil
import signal
import tempfile
import tomllib
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calib.errors import InputError
from calib.measurements import Measurements, read_measurements
from calib.fmu.mapping import load_mapping
from calib.rotor.aerodyn import read_aerodyn_blade, read_aerodyn_polar
from calib.rotor.aerodyn_main import read_aerodyn_main
from calib.rotor.geometry import Rotor
from calib.rotor.openfast import read_elastodyn, read_openfast
from calib.rotor.polar import Airfoil
from calib.rotor.windio import read_windio
from calib.tomlfile import read_toml
from calib.workflow import Workflow, load_workflow
from calib.workflow.sections import Stage

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "calib" / "data"
DECK = ROOT / "tests" / "data" / "openfast"
#: examples per reader; CALIB_FUZZ_EXAMPLES=5000 CALIB_FUZZ_RANDOM=1 runs a longer, non-repeating campaign
N_EXAMPLES = int(os.environ.get("CALIB_FUZZ_EXAMPLES", 200))
#: a reader must finish one example well under a second (hypothesis deadline) ...
DEADLINE_MS = 1000
#: ... and is stopped (the example fails as a hang) after this many seconds
HANG_SECONDS = 5.0

FUZZ = settings(max_examples=N_EXAMPLES, deadline=DEADLINE_MS, derandomize=not os.environ.get("CALIB_FUZZ_RANDOM"),
                database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])


# ============================================================================ checks
class ReaderHang(BaseException):
    """A reader ran longer than HANG_SECONDS (BaseException: no reader may swallow it)."""


@contextlib.contextmanager
def time_limit(seconds: float = HANG_SECONDS):
    def on_alarm(signum, frame):
        raise ReaderHang(f"reader still running after {seconds} s")
    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


#: messages about a whole file (no line or key to name): the file itself is the place
_WHOLE_FILE = re.compile(r"empty file|not a text|not UTF|not valid UTF|not a UTF-8|binary|NUL bytes|"
                         r"top level|not found|no data rows|control character", re.I)


def check_error(exc: InputError, files) -> None:
    """The error names one of ``files`` and a line or a key (or is about the whole file)."""
    assert isinstance(exc, InputError), f"{type(exc).__name__}: {exc}"
    names = {Path(f).name for f in files}
    assert exc.source is not None, f"no file named: {exc}"
    assert any(n in exc.source for n in names), f"source {exc.source!r} is none of {sorted(names)}: {exc}"
    assert exc.line is not None or exc.field is not None or _WHOLE_FILE.search(exc.message), \
        f"neither line nor key named: {exc}"
    assert exc.message.strip()


def call_reader(fn, files):
    """``fn()`` under the hang guard; returns its result, or None after a well-formed InputError."""
    try:
        with time_limit():
            return fn()
    except InputError as exc:
        check_error(exc, files)
        return None


def assert_finite(obj, where: str = "result", allow_nan=()) -> None:
    """No NaN or inf anywhere in ``obj`` (dataclasses, dicts, sequences, arrays, numbers)."""
    if where in allow_nan:
        return
    if isinstance(obj, (bool, str, bytes, Path)) or obj is None:
        return
    if isinstance(obj, (int, np.integer)):
        return
    if isinstance(obj, (float, np.floating)):
        assert math.isfinite(obj), f"{where} = {obj!r}"
        return
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "fc":
            assert np.all(np.isfinite(obj)), f"{where} has non-finite values"
        elif obj.dtype == object:
            for k, v in enumerate(obj.ravel()):
                assert_finite(v, f"{where}[{k}]", allow_nan)
        return
    if dataclasses.is_dataclass(obj):
        for f in dataclasses.fields(obj):
            assert_finite(getattr(obj, f.name), f"{where}.{f.name}", allow_nan)
        return
    if isinstance(obj, dict):
        for k, v in obj.items():
            assert_finite(v, f"{where}.{k}", allow_nan)
        return
    if isinstance(obj, (list, tuple)):
        for k, v in enumerate(obj):
            assert_finite(v, f"{where}[{k}]", allow_nan)
        return


# ============================================================================ mutations
NASTY_TOKENS = ["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e999", "-1e999", "1e308", "-1e308", "1e-320",
                "0", "-0", "-1", "-1e6", "2", "3", "99999999999999999999", "1e30", "1e300", "0.5", "abc", "",
                '"', '""', "'", "True", "F", "default", "unused", "[", "]", "{", "}", "=", ",", ";", "\t", "#",
                "!", "-", "---", "\x00", "\x7f", "é", "°", "\u2028", "\ufeff", "1,5", "1.2.3", "0x10", "1_0",
                "null", "~", "*", "&a", ": x", "- x", "'''", '"""', "[[x]]", "[x]", "x = 1", "@", "..", "/", "\\",
                "9" * 400, "1" * 5000, "x" * 300, "NA", "#N/A", "1e5", "-180", "180", "1.0e-3"]
_TOKEN = re.compile(r"[^\s,;=\[\]{}\"':]+")
_TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=8)


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def _pick(draw, seq):
    return draw(st.integers(0, len(seq) - 1))


def _truncate(draw, data):
    return data[:draw(st.integers(0, len(data)))]


def _delete_line(draw, data):
    lines = _lines(data)
    del lines[_pick(draw, lines)]
    return b"".join(lines)


def _duplicate_line(draw, data):
    lines = _lines(data)
    i = _pick(draw, lines)
    lines.insert(i, lines[i])
    return b"".join(lines)


def _swap_lines(draw, data):
    lines = _lines(data)
    i, j = _pick(draw, lines), _pick(draw, lines)
    lines[i], lines[j] = lines[j], lines[i]
    return b"".join(lines)


def _keyword_lines(lines):
    """Lines of the form ``value  Keyword ...`` (OpenFAST) or ``key = value`` (TOML) or ``key:`` (YAML)."""
    out = []
    for i, ln in enumerate(lines):
        t = ln.decode("utf-8", "replace").split()
        if len(t) >= 2 and (t[1][:1].isalpha() or t[1] == "=") or (t and t[0].endswith(":")):
            out.append(i)
    return out


def _on_token(draw, data, change, keyword_lines=False):
    lines = _lines(data)
    candidates = _keyword_lines(lines) if keyword_lines else []
    i = candidates[_pick(draw, candidates)] if candidates else _pick(draw, lines)
    text = lines[i].decode("utf-8", "surrogateescape")
    toks = list(_TOKEN.finditer(text))
    if not toks:
        return data
    text = change(draw, text, toks)
    lines[i] = text.encode("utf-8", "surrogateescape")
    return b"".join(lines)


def _garble(draw, text, toks):
    m = toks[_pick(draw, toks)]
    new = draw(st.sampled_from(NASTY_TOKENS) | _TEXT)
    return text[:m.start()] + new + text[m.end():]


def _swap_tokens(draw, text, toks):
    a, b = sorted((toks[_pick(draw, toks)], toks[_pick(draw, toks)]), key=lambda m: m.start())
    if a.start() == b.start():
        return text
    return text[:a.start()] + b.group() + text[a.end():b.start()] + a.group() + text[b.end():]


def _delete_token(draw, text, toks):
    m = toks[_pick(draw, toks)]
    return text[:m.start()] + text[m.end():]


def _garble_token(draw, data):
    return _on_token(draw, data, _garble)


def _garble_keyword_value(draw, data):
    return _on_token(draw, data, _garble, keyword_lines=True)


def _swap_token(draw, data):
    return _on_token(draw, data, _swap_tokens)


def _delete_one_token(draw, data):
    return _on_token(draw, data, _delete_token, keyword_lines=draw(st.booleans()))


def _insert_bytes(draw, data):
    i = draw(st.integers(0, len(data)))
    return data[:i] + draw(st.binary(min_size=1, max_size=16)) + data[i:]


def _binary(draw, data):
    return draw(st.sampled_from([b"", b"\x00" * 64, b"PK\x03\x04" + bytes(range(256)), b"\x89PNG\r\n\x1a\n"]))


def _random_bytes(draw, data):
    return draw(st.binary(max_size=200))


def _reencode(draw, data):
    text = data.decode("utf-8", "replace")
    i = draw(st.integers(0, len(text)))
    text = text[:i] + draw(st.sampled_from(["é", "°", "µ", "€", "ñ"])) + text[i:]
    codec = draw(st.sampled_from(["latin-1", "cp1252", "utf-16", "utf-16-le", "utf-16-be", "utf-8-sig", "utf-32"]))
    return text.encode(codec, errors="replace")


def _line_ends(draw, data):
    return data.replace(b"\n", draw(st.sampled_from([b"\r\n", b"\r", b"\n\n", b"\x0b"])))


BYTE_OPS = [_truncate, _delete_line, _duplicate_line, _swap_lines, _garble_token, _garble_token,
            _garble_keyword_value, _garble_keyword_value, _swap_token, _delete_one_token, _insert_bytes,
            _binary, _random_bytes, _reencode, _line_ends]


class Case(tuple):
    """(index of the seed, mutated bytes), shown as a short diff against the seed when an example fails."""

    def __new__(cls, k, data, seed, ops):
        self = super().__new__(cls, (k, data))
        self.seed, self.ops = seed, ops
        return self

    def __repr__(self):
        a = self.seed.decode("utf-8", "replace").splitlines()
        b = self[1].decode("utf-8", "replace").splitlines()
        diff = list(difflib.unified_diff(a, b, lineterm="", n=0))[2:]
        shown = "\n".join(x[:160] for x in diff[:14]) + ("\n..." if len(diff) > 14 else "")
        return f"Case(seed {self[0]}, ops {self.ops}, {len(self[1])} bytes, diff:\n{shown})"


@st.composite
def mutated_bytes(draw, seeds: list[bytes]):
    """(index of the seed, its bytes after 1-3 mutations)."""
    k = _pick(draw, seeds)
    data, ops = seeds[k], []
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(BYTE_OPS))
        ops.append(op.__name__.lstrip("_"))
        data = op(draw, data)
    return Case(k, data, seeds[k], ops)


# ---------------------------------------------------------------- structural (TOML, YAML)
NASTY_VALUES = [float("nan"), float("inf"), float("-inf"), 1e308, -1e308, 0, 0.0, -1, -1.0, 2 ** 63 - 1, -2 ** 63,
                1.5, 1e-300, "", "x", "nan", "auto", "default", True, False, [], {}, [float("nan")], [1, "a"],
                [float("inf"), 1.0], {"x": 1}, [{"x": 1}], "../missing.dat", "\x00", "é"]


def _paths(node, prefix=()):
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for k, v in enumerate(node):
            out.append(prefix + (k,))
            out += _paths(v, prefix + (k,))
    return out


def _parent(tree, path):
    node = tree
    for k in path[:-1]:
        node = node[k]
    return node


def _mutate_tree(draw, tree):
    paths = _paths(tree)
    if not paths:
        return {"x": draw(st.sampled_from(NASTY_VALUES))}
    leaves = [p for p in paths if not isinstance(_parent(tree, p)[p[-1]], (dict, list))]
    pool = leaves if leaves and draw(st.booleans()) else paths  # values half of the time: deep checks
    path = pool[_pick(draw, pool)]
    parent, key = _parent(tree, path), path[-1]
    op = draw(st.sampled_from(["delete", "nasty", "nasty", "nasty", "unknown_key", "wrap", "scale", "swap"]))
    value = parent[key]
    if op == "delete":
        del parent[key]
    elif op == "nasty":
        parent[key] = json.loads(json.dumps(draw(st.sampled_from(NASTY_VALUES)), allow_nan=True))
    elif op == "unknown_key" and isinstance(value, dict):
        value[draw(st.sampled_from(["unknown", "Name", "x y", ""]))] = draw(st.sampled_from(NASTY_VALUES[:8]))
    elif op == "wrap":
        parent[key] = [value]
    elif op == "scale" and isinstance(value, (int, float)) and not isinstance(value, bool):
        parent[key] = value * draw(st.sampled_from([-1, 0, 1e300, -1e300, 1e-300, 10]))
    elif op == "scale" and isinstance(value, list) and value:
        value[_pick(draw, value)] = draw(st.sampled_from([float("nan"), float("inf"), -1.0, 0.0, 1e300, "1"]))
    elif op == "swap" and isinstance(parent, dict) and len(parent) > 1:
        other = list(parent)[_pick(draw, list(parent))]
        parent[key], parent[other] = parent[other], value
    return tree


def _toml_key(k) -> str:
    return json.dumps(str(k), ensure_ascii=True).replace("\x7f", "\\u007f")


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=True).replace("\x7f", "\\u007f")
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(type(v))


def to_toml(tree: dict) -> bytes:
    """A TOML document of ``tree`` (every table inline: enough for mutated files)."""
    return "".join(f"{_toml_key(k)} = {_toml_value(v)}\n" for k, v in tree.items()).encode()


def _copy(tree):
    return json.loads(json.dumps(tree, allow_nan=True))


@st.composite
def mutated_toml(draw, seeds: list[bytes]):
    """A mutated TOML file: byte-level mutations, or 1-3 structural ones re-serialized."""
    if draw(st.booleans()):
        return draw(mutated_bytes(seeds))
    k = _pick(draw, seeds)
    tree = _copy(tomllib.loads(seeds[k].decode()))
    for _ in range(draw(st.integers(1, 3))):
        tree = _mutate_tree(draw, tree)
    return Case(k, to_toml(tree), to_toml(tomllib.loads(seeds[k].decode())), ["structural"])


def _read(paths) -> list[bytes]:
    return [Path(p).read_bytes() for p in paths]


@contextlib.contextmanager
def replaced(path: Path, data: bytes):
    """``path`` holds ``data`` inside the block and its original bytes afterwards."""
    original = path.read_bytes()
    path.write_bytes(data)
    try:
        yield path
    finally:
        path.write_bytes(original)


@pytest.fixture(scope="module")
def work_dir():
    d = Path(tempfile.mkdtemp(prefix="calib_fuzz_"))
    yield d
    shutil.rmtree(d, ignore_errors=True)


# ============================================================================ measurements
CSV_SEEDS = sorted((ROOT / "tests" / "data" / "measurements").glob("*.csv")) + \
    sorted((ROOT / "tests" / "data" / "measurements").glob("*.tsv")) + \
    [DATA / "demo_campaign" / "nrel5mw_campaign.csv", ROOT / "workflows" / "data" / "own_turbine_field.csv"]
CSV_BYTES = _read(CSV_SEEDS)


def check_measurements(m: Measurements) -> None:
    assert isinstance(m, Measurements)
    assert m.values.shape == (m.n_points, len(m.channels)) and m.n_points >= 1
    assert_finite(m.values, "values")
    for f in ("wind_speed", "rotor_speed", "pitch", "air_density", "yaw"):
        assert_finite(np.asarray(getattr(m.conditions, f)), f)
    assert np.all(m.conditions.wind_speed > 0)
    if m.sigma is not None:
        assert_finite(m.sigma, "sigma")
        assert np.all(m.sigma > 0)


@FUZZ
@given(case=mutated_bytes(CSV_BYTES), drop=st.booleans(), no_channels=st.booleans())
def test_fuzz_read_measurements(work_dir, case, drop, no_channels):
    k, data = case
    path = work_dir / CSV_SEEDS[k].name
    path.write_bytes(data)
    m = call_reader(lambda: read_measurements(path, drop_incomplete_rows=drop, allow_no_channels=no_channels),
                    [path])
    if m is not None:
        check_measurements(m)


# ============================================================================ AeroDyn 15
BLADE_SEEDS = [DATA / "nrel5mw" / "NRELOffshrBsline5MW_AeroDyn_blade.dat",
               DATA / "iea3p4" / "IEA-3.4-130-RWT_AeroDyn15_blade.dat",
               DATA / "iea15" / "IEA-15-240-RWT_AeroDyn15_blade.dat",
               DECK / "5MW_Baseline" / "NRELOffshrBsline5MW_AeroDyn_blade.dat"]
POLAR_SEEDS = sorted((DATA / "nrel5mw" / "Airfoils").glob("*.dat")) + \
    [DATA / "iea3p4" / "Airfoils" / "IEA-3.4-130-RWT_AeroDyn15_Polar_10.dat",
     DATA / "iea15" / "Airfoils" / "IEA-15-240-RWT_AeroDyn15_Polar_30.dat",
     DATA / "reference" / "S809_AD15.dat", ROOT / "tests" / "data" / "bad_inputs" / "two_tables_AD15.dat"]
BLADE_BYTES, POLAR_BYTES = _read(BLADE_SEEDS), _read(POLAR_SEEDS)


@FUZZ
@given(case=mutated_bytes(BLADE_BYTES))
def test_fuzz_read_aerodyn_blade(work_dir, case):
    k, data = case
    path = work_dir / BLADE_SEEDS[k].name
    path.write_bytes(data)
    blade = call_reader(lambda: read_aerodyn_blade(path), [path])
    if blade is not None:
        assert_finite({k: v for k, v in blade.items() if k != "source"}, "blade")
        n = blade["span"].size
        assert n >= 2 and np.all(np.diff(blade["span"]) > 0) and np.all(blade["chord"] > 0)
        assert blade["af_id"].dtype.kind == "i" and np.all(blade["af_id"] >= 1)


def check_airfoil(af: Airfoil) -> None:
    assert isinstance(af, Airfoil) and af.tables
    for t in af.tables:
        assert_finite(t, "table")
        assert t.alpha_deg.size >= 3 and np.all(np.diff(t.alpha_deg) > 0)


@FUZZ
@given(case=mutated_bytes(POLAR_BYTES))
def test_fuzz_read_aerodyn_polar(work_dir, case):
    k, data = case
    path = work_dir / POLAR_SEEDS[k].name
    path.write_bytes(data)
    af = call_reader(lambda: read_aerodyn_polar(path), [path])
    if af is not None:
        check_airfoil(af)


# ---------------------------------------------------------------- OpenFAST deck
FST = Path("5MW_Land_DLL_WTurb") / "5MW_Land_DLL_WTurb.fst"
DECK_FILES = [FST, Path("5MW_Land_DLL_WTurb") / "NRELOffshrBsline5MW_Onshore_ElastoDyn.dat",
              Path("5MW_Land_DLL_WTurb") / "NRELOffshrBsline5MW_Onshore_AeroDyn15.dat",
              Path("5MW_Baseline") / "NRELOffshrBsline5MW_InflowWind_12mps.dat",
              Path("5MW_Baseline") / "NRELOffshrBsline5MW_AeroDyn_blade.dat",
              Path("5MW_Baseline") / "Airfoils" / "DU25_A17.dat",
              Path("5MW_Baseline") / "Airfoils" / "Cylinder1.dat"]
DECK_BYTES = _read([DECK / f for f in DECK_FILES])


@pytest.fixture(scope="module")
def deck_copy(work_dir):
    """A copy of the r-test deck (the fuzz tests mutate one file of it at a time)."""
    d = work_dir / "deck"
    shutil.copytree(DECK, d)
    return d


def _deck_files(deck: Path):
    return [deck / f for f in DECK_FILES] + sorted((deck / "5MW_Baseline" / "Airfoils").glob("*.dat"))


def check_rotor(rotor: Rotor) -> None:
    assert isinstance(rotor, Rotor)
    # documented "unknown": the t/c of an airfoil, the Re of a single table (windIO without 're')
    unknown = {f"rotor.airfoils[{k}].relative_thickness" for k in range(len(rotor.airfoils))}
    unknown |= {f"rotor.airfoils[{k}].tables[0].reynolds" for k, af in enumerate(rotor.airfoils)
                if len(af.tables) == 1}
    assert_finite(rotor, "rotor", allow_nan=unknown)
    assert np.all(np.diff(rotor.r) > 0) and np.all(rotor.chord > 0)
    for af in rotor.airfoils:
        check_airfoil(af)


@FUZZ
@given(case=mutated_bytes(DECK_BYTES))
def test_fuzz_read_openfast_deck(deck_copy, case):
    k, data = case
    with replaced(deck_copy / DECK_FILES[k], data):
        def read():
            deck = read_openfast(deck_copy / FST)
            return deck, deck.rotor()
        out = call_reader(read, _deck_files(deck_copy))
    if out is not None:
        deck, rotor = out
        check_rotor(rotor)
        assert_finite(deck.elastodyn, "elastodyn")
        assert deck.air_density is None or (math.isfinite(deck.air_density) and deck.air_density > 0)
        assert deck.kinematic_viscosity is None or deck.kinematic_viscosity > 0
        assert math.isfinite(rotor.hub_height)


@FUZZ
@given(case=mutated_bytes(DECK_BYTES[1:2]))
def test_fuzz_read_elastodyn(deck_copy, case):
    _, data = case
    with replaced(deck_copy / DECK_FILES[1], data) as path:
        ed = call_reader(lambda: read_elastodyn(path), [path])
    if ed is not None:
        assert_finite(ed, "elastodyn")
        assert ed.n_blades >= 1 and 0 < ed.hub_radius < ed.tip_radius
        assert math.isfinite(ed.hub_height)


AD_MAIN = [DECK_FILES[2], Path("nrel5mw_main") / "NREL5MW_AD15_main_input.dat",
           Path("iea3p4_main") / "IEA-3.4-130-RWT_AeroDyn15.dat"]


@pytest.fixture(scope="module")
def main_copies(deck_copy):
    shutil.copytree(DATA / "nrel5mw", deck_copy / "nrel5mw_main")
    shutil.copytree(DATA / "iea3p4", deck_copy / "iea3p4_main")
    return deck_copy


@FUZZ
@given(case=mutated_bytes([(DECK / DECK_FILES[2]).read_bytes(),
                           (DATA / "nrel5mw" / "NREL5MW_AD15_main_input.dat").read_bytes(),
                           (DATA / "iea3p4" / "IEA-3.4-130-RWT_AeroDyn15.dat").read_bytes()]))
def test_fuzz_read_aerodyn_main(main_copies, case):
    k, data = case
    with replaced(main_copies / AD_MAIN[k], data) as path:
        ad = call_reader(lambda: read_aerodyn_main(path), [path])
    if ad is not None:
        assert_finite(ad, "aerodyn")
        assert ad.blade_file.is_file() and all(f.is_file() for f in ad.airfoil_files)
        for rho in (ad.air_density, ad.kinematic_viscosity):
            assert rho is None or rho > 0


# ============================================================================ windIO
WINDIO_SEEDS = [DATA / "iea3p4" / "IEA-3.4-130-RWT_windIO.yaml", DATA / "iea15" / "IEA-15-240-RWT_windIO.yaml"]


def _thin(curve: dict, n: int) -> dict:
    """About ``n`` of the curve's points, the ends included."""
    g, v = curve["grid"], curve["values"]
    keep = sorted(set(range(0, len(g), max(1, len(g) // n))) | {len(g) - 1})
    return {"grid": [g[i] for i in keep], "values": [v[i] for i in keep]}


def _trimmed_windio(path: Path) -> dict:
    """What read_windio reads of a windIO file, its curves thinned to ~12 points (fast to parse)."""
    d = yaml.load(path.read_text(encoding="utf-8"), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    comp = d["components"]
    bem = dict(comp["blade"]["outer_shape_bem"])
    for key in ("chord", "twist", "pitch_axis"):
        bem[key] = _thin(bem[key], 12)
    bem["reference_axis"] = {k: _thin(c, 12) for k, c in bem["reference_axis"].items()}
    used = set(bem["airfoil_position"]["labels"])
    airfoils = []
    for a in d["airfoils"]:
        if a["name"] not in used:
            continue
        a = {k: v for k, v in a.items() if k != "coordinates"}
        a["polars"] = [{k: (_thin(v, 12) if k in ("c_l", "c_d", "c_m") else v) for k, v in polar.items()}
                       for polar in a["polars"]]
        airfoils.append(a)
    return {"name": d.get("name"), "assembly": d["assembly"],
            "components": {"blade": {"outer_shape_bem": bem}, "hub": comp["hub"],
                           "nacelle": {"drivetrain": comp["nacelle"]["drivetrain"]}},
            "airfoils": airfoils, "control": d.get("control"), "environment": d.get("environment")}


_Dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
WINDIO_TREES = [_trimmed_windio(p) for p in WINDIO_SEEDS]
WINDIO_BYTES = [yaml.dump(t, Dumper=_Dumper, sort_keys=False).encode() for t in WINDIO_TREES]


@st.composite
def mutated_windio(draw):
    if draw(st.booleans()):
        return draw(mutated_bytes(WINDIO_BYTES))
    k = _pick(draw, WINDIO_TREES)
    tree = _copy(WINDIO_TREES[k])
    for _ in range(draw(st.integers(1, 3))):
        tree = _mutate_tree(draw, tree)
    return Case(k, yaml.dump(tree, Dumper=_Dumper, sort_keys=False).encode(), WINDIO_BYTES[k], ["structural"])


@FUZZ
@given(case=mutated_windio())
def test_fuzz_read_windio(work_dir, case):
    k, data = case
    path = work_dir / WINDIO_SEEDS[k].name
    path.write_bytes(data)
    rotor = call_reader(lambda: read_windio(path), [path])
    if rotor is not None:
        check_rotor(rotor)
        for af in rotor.airfoils:  # Re NaN documents an unknown Reynolds number of a single table
            assert len(af.tables) == 1 or np.all(np.isfinite(af.reynolds_numbers))


# ============================================================================ TOML: workflows, mappings
def _is_workflow(path: Path) -> bool:
    try:
        return "stages" in tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        return False


WORKFLOW_SEEDS = [p for p in sorted((ROOT / "workflows").glob("*.toml")) if _is_workflow(p)]  # not diagnose configs
MAPPING_SEEDS = sorted((ROOT / "fmu_models").glob("variant_*/mapping.toml")) + \
    [ROOT / "tests" / "data" / "fmu" / "generic_rotor_mapping.toml"]
TOML_SEEDS = WORKFLOW_SEEDS + MAPPING_SEEDS + sorted((ROOT / "fmu_models").glob("variant_*/variables.toml"))
WORKFLOW_BYTES, MAPPING_BYTES, TOML_BYTES = _read(WORKFLOW_SEEDS), _read(MAPPING_SEEDS), _read(TOML_SEEDS)


@FUZZ
@given(case=mutated_bytes(TOML_BYTES))
def test_fuzz_read_toml(work_dir, case):
    k, data = case
    path = work_dir / TOML_SEEDS[k].name
    path.write_bytes(data)
    out = call_reader(lambda: read_toml(path), [path])
    assert out is None or isinstance(out, dict)


@FUZZ
@given(case=mutated_toml(WORKFLOW_BYTES))
def test_fuzz_load_workflow(work_dir, case):
    k, data = case
    path = work_dir / WORKFLOW_SEEDS[k].name
    path.write_bytes(data)
    wf = call_reader(lambda: load_workflow(path), [path])
    if wf is not None:
        assert isinstance(wf, Workflow) and wf.stages and all(isinstance(s, Stage) for s in wf.stages)
        assert_finite(wf, "workflow")


@FUZZ
@given(case=mutated_toml(MAPPING_BYTES))
def test_fuzz_load_mapping(work_dir, case):
    k, data = case
    path = work_dir / MAPPING_SEEDS[k].name
    path.write_bytes(data)
    m = call_reader(lambda: load_mapping(path), [path])
    if m is not None:
        # nominal / lower / upper / prior_std absent from the file: NaN means "the FMU's start, min, max"
        absent = {f"mapping.parameters.{n}.{f}" for n in m.parameters for f in ("nominal", "lower", "upper",
                                                                                 "prior_std")
                  if f not in m.raw["parameters"][n]}
        assert_finite(m, "mapping", allow_nan=absent | {"mapping.raw"})


# ---------------------------------------------------------------- diagnose --config
def _diagnose_seeds() -> list[bytes]:
    """``calib diagnose --config`` files: the shipped ones (workflows/diagnose), and the tables a
    diagnosis reads from each workflow plus a [diagnosis] table."""
    seeds = [b'[model]\nuse_tilt = false\n[diagnosis]\ncandidates = ["pitch_offset", "wind_speed_scale", "tip_loss"]\n'
             b'[grid]\nalpha_nodes_deg = "auto"\neta_nodes = [0.3, 0.6, 1.0]\n']
    for path in WORKFLOW_SEEDS:
        wf = tomllib.loads(path.read_text(encoding="utf-8"))
        cfg = {k: wf[k] for k in ("rotor", "model", "fluid", "grid", "calibration") if k in wf}
        cfg["diagnosis"] = {"candidates": ["pitch_offset", "tip_loss"], "max_effects": 1, "significance": 0.01,
                            "ambiguity_bic": 6.0, "recalibrate": True}
        seeds.append(to_toml(cfg))
    return seeds + [p.read_bytes() for p in sorted((ROOT / "workflows" / "diagnose").glob("*.toml"))]


DIAGNOSE_BYTES = _diagnose_seeds()


class _Prepared(Exception):
    """The configuration passed every check of calib.diagnosis.command; the model set-up is not run here."""


@pytest.fixture(scope="module")
def diagnose_ready(work_dir):
    """One unmutated run first: run_diagnose imports the report modules on its first call (not a reader's time)."""
    _run_diagnose_checks(work_dir, DIAGNOSE_BYTES[0])
    return work_dir


def _run_diagnose_checks(work_dir, data: bytes) -> None:
    """calib.diagnosis.command.run_diagnose up to the model set-up (prepare), which is not run here."""
    from calib.diagnosis.command import run_diagnose

    path = work_dir / "diagnose_config.toml"
    path.write_bytes(data)
    csv = ROOT / "tests" / "data" / "measurements" / "semicolon.csv"
    with mock.patch("calib.workflow.prepare", side_effect=_Prepared):
        try:
            call_reader(lambda: run_diagnose(None, str(csv), str(work_dir / "diagnose_out"), str(path),
                                             printer=lambda line: None), [path])
        except _Prepared:
            pass


DIAGNOSE_NO_TABLE = [to_toml({k: v for k, v in tomllib.loads(d.decode()).items() if k != "diagnosis"})
                     for d in DIAGNOSE_BYTES]


@FUZZ
@given(case=mutated_toml(DIAGNOSE_NO_TABLE))
def test_fuzz_diagnose_config(diagnose_ready, case):
    """Config files without [diagnosis]: the tables calib diagnose shares with workflows."""
    _run_diagnose_checks(diagnose_ready, case[1])


@FUZZ
@given(case=mutated_toml(DIAGNOSE_BYTES))
def test_fuzz_diagnose_config_diagnosis_table(diagnose_ready, case):
    """The [diagnosis] table itself ('diagnosis = 1.5' and 'significance = [1]' raised TypeError)."""
    _run_diagnose_checks(diagnose_ready, case[1])


# ============================================================================ regressions
# One plain test per defect the fuzzing (or a probe written while fixing it) found in the readers.
def _deck(tmp_path) -> Path:
    shutil.copytree(DECK, tmp_path / "deck")
    return tmp_path / "deck"


def _sub(path: Path, pattern: str, replacement: str) -> None:
    text = path.read_text()
    new = re.sub(pattern, replacement, text, count=1, flags=re.M)
    assert new != text, pattern
    path.write_text(new)


# ---------------------------------------------------------------- measurements
def test_measurement_file_name_too_long_is_an_input_error(tmp_path):
    # was OSError [Errno 36] from Path.is_file
    with pytest.raises(InputError, match="cannot read the file|file not found") as exc:
        read_measurements(tmp_path / ("x" * 300 + ".csv"))
    assert "x" * 300 in exc.value.source


def test_measurement_cell_over_the_csv_size_limit_names_its_line(tmp_path):
    # was _csv.Error: field larger than field limit (131072)
    path = tmp_path / "m.csv"
    path.write_text("wind_speed,rotor_speed,pitch,power\n8,9,0,1\n8,9,0," + "4" * 200000 + "\n")
    with pytest.raises(InputError, match="cannot split the line") as exc:
        read_measurements(path)
    assert exc.value.line == 3


def test_measurement_unit_conversion_overflow_is_refused(tmp_path):
    # 1e305 MW was read as power = inf W
    path = tmp_path / "m.csv"
    path.write_text("wind_speed,rotor_speed,pitch,power [MW]\n8,9,0,1\n8,9,0,1e305\n")
    with pytest.raises(InputError, match="too large") as exc:
        read_measurements(path)
    assert (exc.value.line, exc.value.field) == (3, "power")


@pytest.mark.parametrize("column, value", [("air_density", "-1.2"), ("rotor_speed", "-9")])
def test_measurement_negative_density_or_rotor_speed_is_refused(tmp_path, column, value):
    # both were accepted as conditions
    path = tmp_path / "m.csv"
    row = {"wind_speed": "8", "rotor_speed": "9", "pitch": "0", "air_density": "1.2", "power": "1"}
    row[column] = value
    path.write_text(",".join(row) + "\n" + ",".join(row.values()) + "\n")
    with pytest.raises(InputError, match="must be") as exc:
        read_measurements(path)
    assert (exc.value.line, exc.value.field) == (2, column)


# ---------------------------------------------------------------- AeroDyn 15, ElastoDyn, .fst
def test_polar_reynolds_number_overflow_or_negative_is_refused(tmp_path):
    # Re = 1e305 (millions) became reynolds = inf; Re = -1 was accepted
    src = DATA / "nrel5mw" / "Airfoils" / "DU25_A17.dat"
    for value in ("1e305", "-1"):
        path = tmp_path / "DU25_A17.dat"
        path.write_text(src.read_text())
        _sub(path, r"^\s*\S+\s+Re\b", f" {value}   Re")
        with pytest.raises(InputError, match="positive Reynolds") as exc:
            read_aerodyn_polar(path)
        assert exc.value.field == "Re" and exc.value.line is not None


def test_blade_airfoil_id_too_large_names_the_blade_line(tmp_path):
    # BlAFID = 1e300 passed the integer check, overflowed the int cast (RuntimeWarning) and was
    # refused only by the Rotor, without a line
    path = tmp_path / "blade.dat"
    path.write_text(BLADE_SEEDS[0].read_text())
    _sub(path, r"^(\s*0\.0+E\+00(?:\s+\S+){5}\s+)1\b", r"\g<1>1e300")
    with pytest.raises(InputError, match="airfoil id must be a positive integer") as exc:
        read_aerodyn_blade(path)
    assert exc.value.field == "BlAFID" and exc.value.line == 7


def test_referenced_file_name_too_long_names_the_referring_line(tmp_path):
    # was OSError [Errno 36] File name too long from Path.is_file
    deck = _deck(tmp_path)
    ad = deck / DECK_FILES[2]
    ad.write_text(ad.read_text().replace("../5MW_Baseline/NRELOffshrBsline5MW_AeroDyn_blade.dat", "b" * 300))
    with pytest.raises(InputError, match="cannot use the file name") as exc:
        read_aerodyn_main(ad)
    assert exc.value.field == "ADBlFile(1)" and exc.value.line is not None and ad.name in exc.value.source


def test_elastodyn_hub_height_overflow_is_refused(tmp_path):
    # TowerHt = Twr2Shft = 1e308 gave hub_height = inf
    deck = _deck(tmp_path)
    ed = deck / DECK_FILES[1]
    _sub(ed, r"^\s*\S+\s+TowerHt\b", " 1e308 TowerHt")
    _sub(ed, r"^\s*\S+\s+Twr2Shft\b", " 1e308 Twr2Shft")
    with pytest.raises(InputError, match="hub height") as exc:
        read_elastodyn(ed)
    assert exc.value.field == "TowerHt" and exc.value.line is not None


def test_elastodyn_blade_count_beyond_three_is_refused(tmp_path):
    # NumBl = 99999999999999999999 was accepted
    deck = _deck(tmp_path)
    ed = deck / DECK_FILES[1]
    _sub(ed, r"^\s*\S+\s+NumBl\b", " 99999999999999999999 NumBl")
    with pytest.raises(InputError, match="1 to 3 blades") as exc:
        read_elastodyn(ed)
    assert exc.value.field == "NumBl" and exc.value.line is not None


# ---------------------------------------------------------------- windIO
def _windio(tmp_path, edit) -> Path:
    tree = _copy(WINDIO_TREES[0])
    edit(tree)
    path = tmp_path / "turbine.yaml"
    path.write_text(yaml.dump(tree, Dumper=_Dumper, sort_keys=False))
    return path


def test_windio_not_utf8_names_the_line(tmp_path):
    # was UnicodeDecodeError from the YAML reader
    path = tmp_path / "turbine.yaml"
    path.write_bytes(WINDIO_BYTES[0].replace(b"assembly:", b"assembly:\n# \xe9\n", 1))
    with pytest.raises(InputError, match="not UTF-8") as exc:
        read_windio(path)
    assert exc.value.line == 3


@pytest.mark.parametrize("edit, field", [
    # each raised TypeError, ValueError, AttributeError or IndexError
    (lambda t: t.update(airfoils=3), "airfoils"),
    (lambda t: t["airfoils"][0]["polars"][0].update(re="high"), "polars[0].re"),
    (lambda t: t["airfoils"][0].update(relative_thickness=[0.3]), "relative_thickness"),
    (lambda t: t["airfoils"][0].update(polars=[1.0]), "polars[0]"),
    (lambda t: t["components"]["blade"]["outer_shape_bem"]["airfoil_position"]["labels"].pop(), "airfoil_position"),
    (lambda t: t["components"].update(nacelle=[1]), "components.nacelle"),
    (lambda t: t["control"].update(torque="x"), "control.torque"),
    (lambda t: t["assembly"].update(number_of_blades="three"), "assembly.number_of_blades"),
])
def test_windio_wrong_types_name_the_key(tmp_path, edit, field):
    with pytest.raises(InputError) as exc:
        read_windio(_windio(tmp_path, edit))
    assert field in exc.value.field


@pytest.mark.parametrize("edit, field", [
    # each was read silently: n_blades 3.7 -> 3, a NaN or infinite schedule value or Reynolds number
    (lambda t: t["assembly"].update(number_of_blades=3.7), "assembly.number_of_blades"),
    (lambda t: t["control"]["torque"].update(tsr=float("nan")), "control.torque.tsr"),
    (lambda t: t["control"]["supervisory"].update(maxOmega=float("inf")), "control.supervisory.maxOmega"),
    (lambda t: t["airfoils"][1]["polars"][0].update(re=float("inf")), "re"),
])
def test_windio_non_finite_or_non_integer_values_are_refused(tmp_path, edit, field):
    with pytest.raises(InputError) as exc:
        read_windio(_windio(tmp_path, edit))
    assert field in exc.value.field


# ---------------------------------------------------------------- TOML: read_toml, workflows, mappings
def test_toml_syntax_error_sets_the_line(tmp_path):
    # the line was only inside the message text (InputError.line None)
    path = tmp_path / "w.toml"
    path.write_text('name = "x"\n\n[grid\n')
    with pytest.raises(InputError, match="not valid TOML") as exc:
        read_toml(path)
    assert exc.value.line == 3


def test_toml_not_utf8_names_line_and_column(tmp_path):
    path = tmp_path / "w.toml"
    path.write_bytes(b'name = "x"\ndescription = "\xe9t\xe9"\n')
    with pytest.raises(InputError, match="column 16") as exc:
        read_toml(path)
    assert exc.value.line == 2


def test_toml_with_byte_order_mark_is_read(tmp_path):
    # Windows editors write one; tomllib alone refuses it ("Invalid statement")
    path = tmp_path / "w.toml"
    path.write_bytes(b'\xef\xbb\xbfname = "x"\n')
    assert read_toml(path) == {"name": "x"}


def test_workflow_nan_is_refused_with_its_key(tmp_path):
    # TOML's nan/inf literals reached the settings (grid nodes, fluid density ...) unchecked
    text = WORKFLOW_SEEDS[0].read_text()
    for old, new, key in (("eta_nodes = [", "eta_nodes = [nan, ", "grid.eta_nodes[0]"),
                          ("[grid]\n", "[fluid]\ndensity = inf\n[grid]\n", "fluid.density")):
        path = tmp_path / "w.toml"
        path.write_text(text.replace(old, new, 1))
        with pytest.raises(InputError, match="must be a finite number") as exc:
            load_workflow(path)
        assert exc.value.field == key


def test_workflow_table_of_wrong_type_names_it(tmp_path):
    from calib.workflow import check_section
    with pytest.raises(InputError, match="'grid' must be a table") as exc:
        check_section(3.0, "grid", "w.toml")
    assert exc.value.field == "grid"


def _mapping(tmp_path, old: str, new: str) -> Path:
    text = MAPPING_SEEDS[0].read_text()
    assert old in text
    path = tmp_path / "mapping.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_mapping_table_of_wrong_type_names_it(tmp_path):
    # '[outputs]' as a number raised AttributeError ('float' object has no attribute 'items')
    tree = tomllib.loads(MAPPING_SEEDS[0].read_text())
    tree["outputs"] = 1e308
    path = tmp_path / "mapping.toml"
    path.write_bytes(to_toml(tree))
    with pytest.raises(InputError, match="must be a table") as exc:
        load_mapping(path)
    assert exc.value.field == "outputs"


@pytest.mark.parametrize("old, new, field", [
    # each was accepted and left a NaN or inf in the mapping
    ('wind_speed = { variable = "wind_speed", unit = "m/s" }',
     'wind_speed = { variable = "wind_speed", unit = "m/s", offset = nan }', "inputs.wind_speed.offset"),
    ("nominal = 0.0, lower = -5.0", "nominal = inf, lower = -5.0", "parameters.pitch_offset_blade1.nominal"),
    ('unit = "deg", wrap = 360', 'unit = "deg", wrap = inf', "outputs.azimuth.wrap"),
    ("on = 1, off = 0", "on = nan, off = 0", "switches.tip_loss.on"),
])
def test_mapping_non_finite_number_is_refused(tmp_path, old, new, field):
    with pytest.raises(InputError, match="must be a finite number") as exc:
        load_mapping(_mapping(tmp_path, old, new))
    assert exc.value.field == field


def test_mapping_array_contents_are_checked(tmp_path):
    # radius_variables of numbers and alpha_nodes_deg of strings were accepted
    path = _mapping(tmp_path, 'radius_variables = ["station_radius_1", "station_radius_2", "station_radius_3", '
                              '"station_radius_4"]', "radius_variables = [1, 2]")
    with pytest.raises(InputError, match="array of names") as exc:
        load_mapping(path)
    assert exc.value.field == "outputs.normal_force.radius_variables"
    path = _mapping(tmp_path, 'grid = "resources/correction_grid.json"',
                    'alpha_nodes_deg = ["a", 1]\neta_nodes = [0.5, 1.0]')
    with pytest.raises(InputError, match="array of numbers") as exc:
        load_mapping(path)
    assert exc.value.field == "corrections.alpha_nodes_deg"


def test_windio_airfoil_without_name_is_named(tmp_path):
    # an airfoil entry without 'name' raised TypeError while sorting the known names for the message
    def edit(tree):
        del tree["airfoils"][2]["name"]
    with pytest.raises(InputError, match="airfoil name") as exc:
        read_windio(_windio(tmp_path, edit))
    assert exc.value.field == "airfoils[2].name"


def test_measurement_header_with_long_blank_run_reads_at_once(tmp_path):
    # the header-unit regular expression backtracked cubically: 1600 blanks inside a cell took
    # 30 s, 3000 minutes
    path = tmp_path / "m.csv"
    path.write_text("wind_speed,rotor_speed,pitch,power,note" + " " * 3000 + "x\n8,9,0,1,a\n")
    with time_limit(2.0):
        m = read_measurements(path)
    assert m.channels == ("power",)


def test_measurement_column_of_nested_harmonics_is_an_unknown_column(tmp_path):
    # quantity_of recursed once per '_1p': a 3000-fold name raised RecursionError
    path = tmp_path / "m.csv"
    path.write_text("wind_speed,rotor_speed,pitch,power,power" + "_1p" * 3000 + "\n8,9,0,1,2\n")
    m = read_measurements(path)
    assert m.channels == ("power",)
    assert any("ignored unrecognised numeric" in n for n in m.notes)


def test_measurement_table_with_many_columns_reads_in_linear_time(tmp_path):
    # duplicate detection (names.count), the channel and sigma look-ups (list scans) and the
    # notes (a did-you-mean per ignored column) were quadratic in the number of columns: a table
    # exported transposed, 20000 columns, took about a minute
    n = 20000
    path = tmp_path / "m.csv"
    path.write_text("wind_speed,rotor_speed,pitch,power" + "".join(f",c{i}" for i in range(n)) + "\n8,9,0,1"
                    + ",1" * n + "\n")
    with time_limit(10.0):
        m = read_measurements(path)
    assert m.channels == ("power",)
    assert any(f"({n} in all)" in note for note in m.notes)


def test_windio_alias_bomb_is_refused_at_once(tmp_path):
    # nine lines of YAML aliases nest 10^9 numbers under 'chord.grid': numpy tried to build the
    # array and the error message the full repr (never finished)
    bomb = ["bomb0: &b0 [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]"]
    bomb += [f"bomb{k}: &b{k} [" + ", ".join([f"*b{k - 1}"] * 10) + "]" for k in range(1, 9)]
    text = WINDIO_BYTES[0].decode()
    start, stop = text.index("      chord:\n"), text.index("      twist:\n")
    path = tmp_path / "turbine.yaml"
    path.write_text("\n".join(bomb) + "\n" + text[:start] + "      chord:\n        grid: *b8\n        values: *b8\n"
                    + text[stop:])
    with time_limit(5.0), pytest.raises(InputError, match="lists of numbers") as exc:
        read_windio(path)
    assert exc.value.field == "components.blade.outer_shape_bem.chord"


def test_toml_integer_beyond_64_bits_is_refused(tmp_path):
    # tomllib accepts it (TOML 1.0 says it must not); the mapping's step count then raised
    # TypeError in np.isfinite, a float() of it OverflowError
    path = _mapping(tmp_path, "steps_per_revolution = 72", "steps_per_revolution = 99999999999999999999")
    with pytest.raises(InputError, match="64-bit") as exc:
        load_mapping(path)
    assert exc.value.field == "steady.steps_per_revolution"


def test_mapping_step_counts_have_an_upper_bound(tmp_path):
    path = _mapping(tmp_path, "steps_per_revolution = 72", "steps_per_revolution = 9000000000000000000")
    with pytest.raises(InputError, match=r"must be in \[1, 100000\]") as exc:
        load_mapping(path)
    assert exc.value.field == "steady.steps_per_revolution"


def _synthetic_workflow(tmp_path, edit) -> Path:
    seed = next(p for p in WORKFLOW_SEEDS if "truth" in tomllib.loads(p.read_text()))
    tree = tomllib.loads(seed.read_text())
    edit(tree)
    path = tmp_path / "w.toml"
    path.write_bytes(to_toml(tree))
    return path


@pytest.mark.parametrize("edit, field", [
    # each passed load_workflow and failed later: ValueError unpacking eta_range in smooth_field,
    # a division by a zero width (NaN truth field), float('x') of a noise fraction
    (lambda t: t["truth"]["bumps"][0].update(eta_range=[0.5]), "truth.bumps[0].eta_range"),
    (lambda t: t["truth"]["bumps"][0].update(alpha_width=0.0), "truth.bumps[0].alpha_width"),
    (lambda t: t["noise"]["relative"].update(power="x"), "noise.relative.power"),
    (lambda t: t["conditions"].update(tsr=[7.0, "8"]), "conditions.tsr"),
])
def test_workflow_synthetic_tables_are_checked_on_load(tmp_path, edit, field):
    with pytest.raises(InputError) as exc:
        load_workflow(_synthetic_workflow(tmp_path, edit))
    assert exc.value.field == field


def test_line_numbers_count_only_line_breaks(tmp_path):
    # str.splitlines also splits at a form feed (old Fortran-era page breaks), \x85 and U+2028:
    # every line number after one was off by one
    path = tmp_path / "m.csv"
    path.write_text("wind_speed,rotor_speed,pitch,power\n8,9,0,1\x0c\n8,9,0,x\n")
    with pytest.raises(InputError, match="not a number") as exc:
        read_measurements(path)
    assert exc.value.line == 3
    blade = tmp_path / "blade.dat"
    text = BLADE_SEEDS[0].read_text()
    lines = text.split("\n")
    lines[1] += "\x0c"          # a page break in the title line
    lines[8] = lines[8].replace("1.3308000E+01", "oops", 1)
    blade.write_text("\n".join(lines))
    with pytest.raises(InputError, match="expected a number") as exc:
        read_aerodyn_blade(blade)
    assert exc.value.line == 9


def test_mapping_switch_model_values_are_numbers(tmp_path):
    # values = { snel = "x" } was accepted and written to the FMU at run time
    path = _mapping(tmp_path, "values = { snel = 1, du_selig = 2 }", 'values = { snel = "x", du_selig = 2 }')
    with pytest.raises(InputError, match="must be a number or true/false") as exc:
        load_mapping(path)
    assert exc.value.field == "switches.stall_delay.values.snel"


def test_mapping_setting_that_is_not_a_table_is_named(tmp_path):
    # a [settings] entry given as a number raised AttributeError ('float' object has no attribute 'get')
    tree = tomllib.loads(MAPPING_SEEDS[0].read_text())
    name = next(iter(tree["settings"]))
    tree["settings"][name] = 0.2
    path = tmp_path / "mapping.toml"
    path.write_bytes(to_toml(tree))
    with pytest.raises(InputError, match="must be a table") as exc:
        load_mapping(path)
    assert exc.value.field == f"settings.{name}"


def test_diagnosis_table_of_the_wrong_type_is_named(tmp_path):
    from calib.diagnosis.in_workflow import diagnosis_settings
    from calib.diagnosis.settings import DiagnosisSettings

    with pytest.raises(InputError) as exc:
        DiagnosisSettings(significance=[1]).validate("c.toml", "diagnosis.")
    assert exc.value.field == "diagnosis.significance"
    with pytest.raises(InputError) as exc:
        diagnosis_settings({"max_effects": 1.5}, "wf.toml")
    assert exc.value.field == "diagnosis.max_effects"
    with pytest.raises(InputError) as exc:
        diagnosis_settings({"candidates": 3}, "wf.toml")
    assert exc.value.field == "diagnosis.candidates"
