"""The ``calib`` command (see :data:`DESCRIPTION`)."""

from __future__ import annotations

import argparse
import sys

from calib import __version__
from calib.errors import CalibError


def _demo(args) -> int:
    import logging
    from pathlib import Path

    from calib.demo import run_demo
    from calib.logs import command_logging

    log = logging.getLogger("calib.demo")
    with command_logging(args.out, args.verbose, args.quiet):
        summary = run_demo(args.out, args.rotor)
        diag = None
        if args.rotor == "nrel5mw" and not args.no_diagnosis:
            from calib.diagnosis.command import run_diagnose
            campaign = Path(__file__).resolve().parent / "data" / "demo_campaign" / "nrel5mw_campaign.csv"
            log.info(f"[calib demo] diagnosis on the embedded NREL 5-MW campaign ({campaign.name}, a hidden "
                     f"effect in the data)")
            diag = run_diagnose("nrel5mw", str(campaign), str(Path(args.out) / "diagnosis"),
                                printer=log.info, prefix="[calib demo]")
        from calib.demo import write_demo_report
        log.info(f"[calib demo] report: {write_demo_report(args.out, summary, diag)}")
    return 0


def _run(args) -> int:
    from calib.workflow import run_from_args
    return run_from_args(args)


def _predict(args) -> int:
    from calib.calibration.predict_command import run_predict
    run_predict(args.result_dir, args.data, args.out, args.confidence)
    return 0


def _powercurve(args) -> int:
    from calib.powercurve.command import run_powercurve
    return run_powercurve(args)


def _design(args) -> int:
    from calib.design.command import run_design
    return run_design(args)


def _diagnose(args) -> int:
    from calib.diagnosis.command import diagnose_from_args
    return diagnose_from_args(args)


def _fmu_build(args) -> int:
    from calib.fmu.build import run_build
    return run_build(args)


def _rotors(args) -> int:
    from calib.rotor.library import ROTORS, load_rotor
    for name in ROTORS:
        r = load_rotor(name)
        print(f"{name:10s} R = {r.tip_radius:7.3f} m  B = {r.n_blades}  stations = {r.n_stations:3d}  "
              f"precone = {r.precone_deg:g} deg  tilt = {r.tilt_deg:g} deg")
    return 0


DESCRIPTION = """calibrate wind-turbine lifting-line (BEM) models from measured rotor loads

  calib demo               the embedded default job
  calib run FILE --out D   run a workflow TOML file (keys: workflows/README.md)
  calib predict DIR ...    a calibrated model at new conditions, with 95 % intervals
  calib powercurve DIR     the calibrated power curve and AEP, with their uncertainty
  calib design FILE ...    choose a campaign's operating points and sensors
  calib diagnose ...       find, name and add the effect the model misses
  calib scada FILE ...     SCADA 10-minute statistics: filters, IEC power curve, tables
  calib fmu build          build the bundled turbine FMUs from their C sources
  calib rotors             list the embedded rotors

'calib COMMAND --help' describes each command."""


# The commands' modules are imported in build_parser and in the commands, not with this module: a worker of the
# process pool or of Dask imports the main module of `calib` (the console script, which imports this one) before
# its first task, and the calibration stack (scipy.stats) cost each worker about 1 CPU s there (issue 38).
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="calib", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"calib {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="C_P surface, power curve and a diagnosis of an embedded campaign",
                       description="The embedded default job: C_P(lambda, beta) surface and power curve of an "
                                   "embedded rotor, then (NREL 5-MW) the diagnosis on an embedded test "
                                   "campaign with a hidden effect; figures and report.html in the output folder.")
    p.add_argument("--out", default="demo_output", help="output folder (default: demo_output)")
    p.add_argument("--rotor", default="nrel5mw", help="embedded rotor name (default: nrel5mw)")
    p.add_argument("--no-diagnosis", action="store_true", help="skip the diagnosis on the embedded "
                   "NREL 5-MW campaign (run by default with the nrel5mw rotor)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("-v", "--verbose", action="store_true", help="also print debug lines (the log file "
                       "OUT/calib.log always has them)")
    group.add_argument("-q", "--quiet", action="store_true", help="print warnings and errors only")
    p.set_defaults(func=_demo)
    p = sub.add_parser("run", help="run a workflow TOML file",
                       description="Run a workflow TOML file (rotor, measurements or a synthetic truth, "
                                   "calibration stages); writes results, figures and report.html. Every key "
                                   "is documented in workflows/README.md.")
    from calib.workflow import add_run_arguments
    add_run_arguments(p)
    p.set_defaults(func=_run)
    p = sub.add_parser("predict", help="a calibrated model at new conditions, with intervals",
                       description="Evaluate the model a calibration produced (rebuilt from its result folder) at "
                                   "the conditions of a CSV file; write each channel with its lower and upper "
                                   "interval bound (SI units). If the file also holds measured channels, print "
                                   "chi2/dof of measured against predicted.")
    p.add_argument("result_dir", help="folder holding result.json and result.npz (a stage folder of 'calib run')")
    p.add_argument("--data", required=True, help="CSV with wind_speed, rotor_speed, pitch (and optionally "
                   "measured channels and <channel>_sigma columns); layout as for measurements")
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument("--confidence", type=float, default=0.95, help="two-sided interval level (default 0.95)")
    p.set_defaults(func=_predict)
    p = sub.add_parser("diagnose", help="find, name and add the effect the model misses",
                       description="The diagnosis: find where the nominal model and the measurements "
                                   "disagree, name the missing physical effect (rotational augmentation, erosion, "
                                   "pitch offset, Reynolds number, tip loss, tunnel blockage, wind-speed scale) by "
                                   "likelihood ratio and BIC, add it, recalibrate the polars on top and show the gap "
                                   "shrink. Writes DIR/diagnosis.json and DIR/report.html; exits 0 whatever it finds.")
    p.add_argument("--rotor", default=None, help="embedded rotor name (see 'calib rotors') or a rotor file: .fst "
                   "(OpenFAST deck), .yaml (windIO), .dat (AeroDyn15 main file); or give [rotor] in --config")
    from calib.diagnosis.command import add_diagnose_arguments
    add_diagnose_arguments(p)
    p.set_defaults(func=_diagnose)
    p = sub.add_parser("fmu", help="FMU tools (calib fmu build)",
                       description="FMU tools. 'calib fmu build --help' lists the build options.")
    fmu_sub = p.add_subparsers(dest="fmu_command", required=True)
    from calib.fmu.build import BUILD_DESCRIPTION, add_build_arguments
    b = fmu_sub.add_parser("build", help="build the bundled turbine FMUs from their C sources",
                           description=BUILD_DESCRIPTION)
    add_build_arguments(b)
    b.set_defaults(func=_fmu_build)
    _add_scada(sub)
    p = sub.add_parser("rotors", help="list the embedded rotors",
                       description="List the embedded rotors with radius, blade count, stations, precone, tilt.")
    p.set_defaults(func=_rotors)
    return _add_powercurve(parser, sub)


def _add_scada(sub):
    from calib.scada.command import add_scada_parser
    add_scada_parser(sub)


def _add_powercurve(parser, sub):
    """``parser`` with the ``powercurve`` subcommand added to its subparsers ``sub``."""
    from calib.powercurve.command import add_powercurve_parser
    add_powercurve_parser(sub).set_defaults(func=_powercurve)
    from calib.design.command import add_design_parser
    add_design_parser(sub).set_defaults(func=_design)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except CalibError as exc:
        print(f"calib: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("calib: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
