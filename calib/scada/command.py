"""``calib scada``: read a SCADA export, filter it, bin it, print the counts and the power curve, and
optionally write the bins or the kept records as a calib measurement table."""

from __future__ import annotations

import argparse

import numpy as np

from calib.errors import InputError
from calib.scada.analysis import power_curve
from calib.scada.density import air_density_sigma
from calib.scada.filters import FILTERS, FilterSettings
from calib.scada.reader import read_scada
from calib.scada.table import write_bins_table, write_records_table

DESCRIPTION = ("Read a SCADA export of 10-minute statistics (Ws_avg, P_avg, Ba_avg, Rs_avg, Ot_avg ... or names "
               "given with --map), compute the air density (IEC 61400-12-1) where temperature and pressure allow, "
               "filter the records (every flag counted), bin them (IEC method of bins, 0.5 m/s) and print the "
               "counts and the power curve per turbine; --bins-out / --records-out write a calib measurement table.")


def add_scada_parser(sub) -> argparse.ArgumentParser:
    """The ``scada`` subcommand on the ``calib`` subparsers ``sub``."""
    p = sub.add_parser("scada", help="SCADA 10-minute export: filters, counts, IEC power curve, measurement table",
                       description=DESCRIPTION)
    p.set_defaults(func=scada_command)
    p.add_argument("export", help="CSV export: a time stamp, optionally a turbine column, signal statistics")
    p.add_argument("--rated-power", type=float, required=True, help="rated power [kW]")
    p.add_argument("--turbine", default=None, help="read this turbine only")
    p.add_argument("--map", action="append", default=[], metavar="COLUMN=SIGNAL,STAT[,UNIT]",
                   help="a further column name, e.g. 'WindSpeed_mean=wind_speed,mean,m/s' (repeatable)")
    p.add_argument("--ignore", action="append", default=[], metavar="COLUMN", help="a column not to read")
    p.add_argument("--pressure", type=float, default=None, help="station pressure [hPa] when the export has none")
    p.add_argument("--no-normalize", action="store_true", help="bin the measured wind speed, not the one "
                   "normalized to 1.225 kg/m^3")
    p.add_argument("--fine-pitch", type=float, default=None, help="fine pitch [deg] (default: estimated)")
    p.add_argument("--skip", action="append", default=[], choices=FILTERS, help="a filter not to run (repeatable)")
    p.add_argument("--align", choices=("iec", "left"), default="iec", help="bins centred on multiples of 0.5 m/s "
                   "(iec, default) or with edges there (left, as OpenOA)")
    p.add_argument("--bins-out", default=None, help="write the bins (N >= 3) as a measurement table CSV")
    p.add_argument("--records-out", default=None, help="write the kept records as a measurement table CSV")
    p.add_argument("--temperature-sigma", type=float, default=None, metavar="K",
                   help="1-sigma of the temperature sensor [K]: with --pressure-sigma, the air density's sigma "
                        "(IEC 61400-12-1 Annex E sensitivities) is written as air_density_sigma in --records-out")
    p.add_argument("--pressure-sigma", type=float, default=None, metavar="HPA",
                   help="1-sigma of the pressure (sensor or the --pressure given) [hPa]")
    p.add_argument("--fill", action="append", default=[], metavar="CONDITION=VALUE",
                   help="a condition the export lacks, held constant in the table, e.g. rotor_speed=17 [rpm]")
    return p


def _pairs(items, what):
    out = {}
    for item in items:
        if "=" not in item:
            raise InputError(f"expected NAME=VALUE, got {item!r}", f"--{what}")
        k, v = item.split("=", 1)
        out[k.strip()] = v
    return out


def _number(text: str, where: str) -> float:
    """``text`` as a finite number, or an InputError naming ``where`` (one NAME=number per ``--fill``)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise InputError(f"expected a number (one CONDITION=VALUE per --fill, e.g. --fill rotor_speed=15 "
                         f"--fill pitch=0), got {text!r}", where)
    return value


def scada_command(args) -> int:
    mapping = {k: tuple(x.strip() for x in v.split(",")) for k, v in _pairs(args.map, "map").items()}
    fill = {k: _number(v, f"--fill {k}") for k, v in _pairs(args.fill, "fill").items()}
    records = read_scada(args.export, mapping=mapping, ignore=args.ignore, turbine=args.turbine)
    settings = FilterSettings(rated_power=1e3 * args.rated_power, fine_pitch=args.fine_pitch,
                              enabled=tuple(f for f in FILTERS if f not in args.skip))
    print(f"{records.source}: {len(records)} records of {len(records.turbines)} turbine(s)")
    for note in records.notes:
        print(f"  note: {note}")
    pressure = None if args.pressure is None else 100.0 * args.pressure
    for name in records.turbines:
        mine = records.select(records.turbine == name)
        a = power_curve(mine, settings, normalize=not args.no_normalize, pressure=pressure, align=args.align)
        print(f"\nturbine {name or '(one)'}: {'; '.join(a.notes)}")
        print(a.report.summary())
        b = a.bins
        pitch_std = b.conditions.get("pitch", {}).get("std", np.full(b.n.size, np.nan))
        print(f"  {'bin [m/s]':>9} {'N':>6} {'wind [m/s]':>10} {'power [kW]':>11} {'sigma/sqrt(N)':>13} "
              f"{'wind std':>8} {'pitch std':>9}")
        for i in range(b.n.size):
            print(f"  {b.centre[i]:9.2f} {b.n[i]:6d} {b.wind_speed[i]:10.3f} {b.power[i] / 1e3:11.1f} "
                  f"{b.power_sigma[i] / 1e3:13.2f} {b.conditions['wind_speed']['std'][i]:8.3f} {pitch_std[i]:9.3f}")
        suffix = f"_{name}" if len(records.turbines) > 1 else ""
        if args.bins_out:
            said = []
            out = write_bins_table(b, _with_suffix(args.bins_out, suffix), fill=fill, source=records.source,
                                   comments=[f"calib scada {records.source} turbine {name}"], said=said)
            print(f"  bins written to {out}" + "".join(f"; {s}" for s in said))
        if args.records_out:
            kept = a.report.kept
            means = {"wind_speed": a.wind_speed[kept]}
            means.update({s: mine.get(s)[kept] for s in ("pitch", "rotor_speed") if mine.has(s)})
            if a.density is not None:
                means["air_density"] = np.broadcast_to(a.density, kept.shape)[kept]
            rho_sigma = _density_sigma(args, mine, pressure, kept) if a.density is not None else None
            said = []
            out = write_records_table(means, mine.get("power")[kept], b, _with_suffix(args.records_out, suffix),
                                      fill=fill, source=records.source, density_sigma=rho_sigma,
                                      comments=[f"calib scada {records.source} turbine {name}"], said=said)
            print(f"  records written to {out}" + "".join(f"; {s}" for s in said))
    return 0


def _density_sigma(args, records, pressure, kept):
    """The kept records' air-density σ from ``--temperature-sigma`` and ``--pressure-sigma``
    (:func:`calib.scada.density.air_density_sigma`), None unless both are given and the density came
    from temperature and pressure."""
    if args.temperature_sigma is None and args.pressure_sigma is None:
        return None
    for flag, value in (("--temperature-sigma", args.temperature_sigma), ("--pressure-sigma", args.pressure_sigma)):
        if value is None or not value >= 0 or not np.isfinite(value):
            raise InputError(f"{flag} must be a number >= 0 with the other sensor's sigma, got {value!r}", flag)
    if records.has("air_density") or not records.has("temperature"):
        raise InputError("--temperature-sigma/--pressure-sigma need the density computed from temperature and "
                         "pressure; this export " + ("measures the density itself" if records.has("air_density")
                                                     else "has no temperature"), "--temperature-sigma")
    b = records.get("pressure") if records.has("pressure") else np.full(len(records), float(pressure))
    phi = records.get("humidity") if records.has("humidity") else 0.0
    sigma = air_density_sigma(records.get("temperature"), b, args.temperature_sigma, 100.0 * args.pressure_sigma, phi)
    return np.broadcast_to(sigma, kept.shape)[kept]


def _with_suffix(path: str, suffix: str) -> str:
    if not suffix:
        return path
    stem, dot, ext = path.rpartition(".")
    return f"{stem}{suffix}.{ext}" if dot else path + suffix
