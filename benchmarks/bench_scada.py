"""La Haute Borne (ENGIE open data, 4 turbines, 2014-2015) through calib.scada against OpenOA, full set.

Reads the whole 10-minute SCADA set with :func:`calib.scada.read_scada`, filters it with the
settings OpenOA's filters are given in ``benchmarks/openoa_reference.py`` and bins it with OpenOA's
bin edges; per turbine, the largest difference of a bin's mean power from OpenOA's
``power_curve.IEC`` (bins with N >= 3 and |P| > 1 % of rated), the records each side kept, and
what calib's own filters (all five, icing included; wind speed normalized to 1.225 kg/m^3 with the
density from the outdoor temperature and the pressure of the site's elevation) remove.

The data: ``examples/data/la_haute_borne.zip`` of the openoa 3.2 wheel (``$CALIB_LHB_ZIP``, else
the wheel is fetched with ``pip download --no-deps openoa==3.2`` into ``.bench-venv-openoa/``).
The reference: recomputed with OpenOA in ``$CALIB_OPENOA_PYTHON`` or ``.bench-venv-openoa`` (built
here with ``python -m venv`` and ``pip install openoa==3.2`` when absent; openoa 3.2 needs
pandas < 3, calib's environment has pandas 3), else the committed
``tests/data/scada/openoa_reference_full.json`` (openoa 3.2).

``python benchmarks/bench_scada.py`` (about 1-3 min, plus building the OpenOA environment once).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

from calib.scada import FilterSettings, power_curve, read_scada  # noqa: E402
from test_scada_openoa import compare  # noqa: E402

SUITE = "validate"
OPENOA = "openoa==3.2"
ENV = os.path.join(ROOT, ".bench-venv-openoa")
MEMBER = "la-haute-borne-data-2014-2015.csv"
COMMITTED = os.path.join(ROOT, "tests", "data", "scada", "openoa_reference_full.json")
ELEVATION_M = 411.0   # la-haute-borne_asset_table.csv
RATED_W = 2050e3


def _wheel() -> str:
    wheels = os.path.join(ENV, "wheel")
    found = [f for f in os.listdir(wheels) if f.endswith(".whl")] if os.path.isdir(wheels) else []
    if not found:
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", OPENOA, "-d", wheels], check=True)
        found = [f for f in os.listdir(wheels) if f.endswith(".whl")]
    return os.path.join(wheels, found[0])


def data_csv(workdir: str) -> str:
    """The full La Haute Borne CSV, extracted into ``workdir``."""
    zpath = os.environ.get("CALIB_LHB_ZIP")
    if not zpath:
        with zipfile.ZipFile(_wheel()) as whl:
            whl.extract("examples/data/la_haute_borne.zip", workdir)
        zpath = os.path.join(workdir, "examples", "data", "la_haute_borne.zip")
    with zipfile.ZipFile(zpath) as z:
        z.extract(MEMBER, workdir)
    return os.path.join(workdir, MEMBER)


def openoa_python() -> str | None:
    py = os.environ.get("CALIB_OPENOA_PYTHON") or os.path.join(ENV, "bin", "python")
    if os.path.exists(py):
        return py
    try:
        subprocess.run([sys.executable, "-m", "venv", ENV], check=True)
        subprocess.run([os.path.join(ENV, "bin", "python"), "-m", "pip", "install", "-q", _wheel()], check=True)
        return os.path.join(ENV, "bin", "python")
    except (subprocess.CalledProcessError, OSError):
        return None


def site_pressure(elevation_m: float) -> float:
    """ISO standard-atmosphere pressure [Pa] at ``elevation_m``."""
    return 101325.0 * (1.0 - 2.25577e-5 * elevation_m) ** 5.25588


def run() -> dict:
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        csv = data_csv(work)
        py = openoa_python()
        source = "committed tests/data/scada/openoa_reference_full.json"
        reference = json.load(open(COMMITTED))
        if py is not None:
            out = os.path.join(work, "reference.json")
            subprocess.run([py, os.path.join(HERE, "openoa_reference.py"), csv, out], check=True)
            fresh = json.load(open(out))
            source = f"recomputed with openoa {fresh['openoa_version']}"
            same = fresh["turbines"] == reference["turbines"]
            reference = fresh
        else:
            same = None
        t_read = time.perf_counter()
        records = read_scada(csv)
        t_read = time.perf_counter() - t_read
    res = {"reference": source, "reference_equals_committed": same, "records": len(records),
           "read_seconds": round(t_read, 1)}
    for name, r in compare(records, reference).items():
        res[f"{name}_max_percent"] = r["max_percent"]
        res[f"{name}_bins_compared"] = r["bins_compared"]
        res[f"{name}_kept"] = r["kept"]
        res[f"{name}_kept_openoa"] = r["kept_openoa"]
        res[f"{name}_n_equal"] = r["n_equal"]
    own = FilterSettings(rated_power=RATED_W)
    for name in records.turbines:
        a = power_curve(records.select(records.turbine == name), own, pressure=site_pressure(ELEVATION_M))
        for flag, count in a.report.counts.items():
            res[f"{name}_own_{flag}"] = count
        res[f"{name}_own_gaps"] = a.report.gaps[name]
        res[f"{name}_own_fine_pitch"] = a.report.fine_pitch
    res["max_percent_all_turbines"] = max(res[f"{n}_max_percent"] for n in records.turbines)
    res["ok"] = res["max_percent_all_turbines"] < 1.0
    res["seconds"] = round(time.perf_counter() - t0, 1)
    return res


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:32s} {v}")
