"""The ``calib`` command (see :data:`DESCRIPTION`)."""

from __future__ import annotations

import argparse
import sys

from calib.errors import CalibError


def _demo(args) -> int:
    from calib.demo import run_demo
    run_demo(args.out, args.rotor)
    return 0


def _run(args) -> int:
    from calib.workflow import main as workflow_main
    return int(workflow_main([args.file, "--out", args.out] + (["--force"] if args.force else [])) or 0)


def _predict(args) -> int:
    from calib.predict import run_predict
    run_predict(args.result_dir, args.data, args.out, args.confidence)
    return 0


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
  calib fmu build          build the bundled turbine FMUs from their C sources
  calib rotors             list the embedded rotors

'calib COMMAND --help' describes each command."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="calib", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    from calib import __version__
    parser.add_argument("--version", action="version", version=f"calib {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="C_P surface and power curve of an embedded rotor",
                       description="The embedded default job: C_P(lambda, beta) surface and power curve of an "
                                   "embedded rotor, written as figures into the output folder.")
    p.add_argument("--out", default="demo_output", help="output folder (default: demo_output)")
    p.add_argument("--rotor", default="nrel5mw", help="embedded rotor name (default: nrel5mw)")
    p.set_defaults(func=_demo)
    p = sub.add_parser("run", help="run a workflow TOML file",
                       description="Run a workflow TOML file (rotor, measurements or a synthetic truth, "
                                   "calibration stages); writes results, figures and report.html. Every key "
                                   "is documented in workflows/README.md.")
    p.add_argument("file", help="workflow TOML file")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--force", action="store_true", help="calibrate even when the unit check suspects a unit "
                   "mistake in the measurements (the report says so)")
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
    p = sub.add_parser("fmu", help="FMU tools (calib fmu build)",
                       description="FMU tools. 'calib fmu build --help' lists the build options.")
    fmu_sub = p.add_subparsers(dest="fmu_command", required=True)
    from calib.fmu.build import BUILD_DESCRIPTION, add_build_arguments
    b = fmu_sub.add_parser("build", help="build the bundled turbine FMUs from their C sources",
                           description=BUILD_DESCRIPTION)
    add_build_arguments(b)
    b.set_defaults(func=_fmu_build)
    p = sub.add_parser("rotors", help="list the embedded rotors",
                       description="List the embedded rotors with radius, blade count, stations, precone, tilt.")
    p.set_defaults(func=_rotors)
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
