"""``calib design WORKFLOW --budget N``: which operating points (and sensor groups) a campaign should measure.

Writes into ``--out`` (default ``design`` beside the workflow): ``test_matrix.csv`` (run order:
conditions, sensors, repeats), ``parameters.csv`` (predicted posterior 1-σ of every parameter for the
design, the full candidate set and a space-filling design of the same size), ``design.json``,
``design.png`` (the points on the λ–pitch plane), ``gain.png`` (the marginal-gain curve) and
``report.md``, whose first paragraph it also prints.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from calib.errors import InputError

__all__ = ["add_design_parser", "run_design"]

DESCRIPTION = ("Choose the operating points of a test campaign before it is run: from the workflow's model, "
               "prior and noise, the points of a candidate set (a stated grid, or a lambda x pitch grid over the "
               "workflow's operating envelope) that maximize the information the data will give (Bayesian "
               "D-optimality by default), by greedy selection and a Fedorov exchange on sensitivities computed "
               "once per candidate. Writes the test matrix in run order, the predicted posterior sigma of every "
               "parameter, the marginal gain of each point, figures and report.md; prints its first paragraph.")


def add_design_parser(sub):
    """The ``design`` subcommand's parser, added to ``sub`` (argparse subparsers)."""
    p = sub.add_parser("design", help="choose a campaign's operating points and sensors", description=DESCRIPTION)
    p.add_argument("workflow", help="workflow TOML file (model, grid, prior, noise; its data span the envelope)")
    p.add_argument("--budget", type=int, required=True, help="operating points in the design (fixed ones included)")
    p.add_argument("--out", default=None, help="output folder (default: design/ beside the workflow)")
    p.add_argument("--criterion", choices=("d", "a", "prediction"), default="d",
                   help="d: Bayesian D-optimality (default); a: A-optimality on --parameters; prediction: the "
                        "prediction variance at --targets (default: the candidates)")
    p.add_argument("--parameters", default=None, help="NAME,NAME,... of --criterion a")
    p.add_argument("--after", default=None, help="a calibrated result's folder: its posterior is the prior")
    p.add_argument("--grid", default=None, help="candidate grid, e.g. 'tsr=2:8:0.25;pitch=-2:8:1' (keys tsr or "
                   "wind_speed, pitch, rotor_speed, yaw; START:STOP:STEP or a,b,c); default: over the envelope")
    p.add_argument("--points", default="25x16", help="the generated grid's λ x pitch counts (default 25x16)")
    p.add_argument("--targets", default=None, help="target grid of --criterion prediction (the --grid syntax)")
    p.add_argument("--fixed", default=None, help="points to keep, 'tsr,pitch[,rotor_speed];...' (each a candidate)")
    p.add_argument("--sensors", default=None, help="sensor groups NAME[:COST],... : hub, torque, root, "
                   "station@ETA, workflow (default), or a channel name")
    p.add_argument("--repeats", type=int, default=1, help="how often one point may be chosen (default 1)")
    p.add_argument("--cover", type=int, default=0, help="start from this many space-filling points over the "
                   "envelope (kept), the rest chosen by the criterion (default 0)")
    p.add_argument("--between-nodes", action="store_true", help="add the variance of the correction field "
                   "between and beyond the nodes (its smooth-field prior) to the candidates' noise")
    p.add_argument("--discrepancy", default="1:0.25", help="a smooth model discrepancy over the operating plane "
                   "in the criterion, SCALE[:LENGTH]: its sigma relative to the noise and its correlation length as a "
                   "fraction of the envelope (default 1:0.25), so that the points spread; none: trust the model's form")
    p.add_argument("--draws", type=int, default=0, help="pseudo-Bayesian: average the criterion over this many "
                   "prior draws of the correction field too (default 0: at the linearization point only)")
    p.add_argument("--seed", type=int, default=0, help="random seed of --draws (default 0)")
    p.add_argument("--choose", type=int, default=None, help="also score every choice of K of the optional sensor "
                   "groups (those of --sensors not in --always) at the design's points, by the held-out prediction "
                   "variance of the --always groups' channels (one wind speed left out at a time); writes "
                   "sensor_choice.csv")
    p.add_argument("--always", default=None, help="with --choose: the sensor groups always measured, NAME,... "
                   "(default: the first of --sensors)")
    p.add_argument("--resume", action="store_true", help="an FMU's design: answer the model calls on record in "
                   "OUT/history (of a killed or finished run with the same inputs) instead of simulating them again")
    return p


def _grid_spec(text: str, option: str) -> dict:
    spec = {}
    for part in str(text).split(";"):
        if not part.strip():
            continue
        key, eq, value = part.partition("=")
        if not eq:
            raise InputError(f"{option} {text!r}: expected KEY=RANGE;KEY=RANGE, e.g. 'tsr=2:8:0.25;pitch=-2:8:1'",
                             option, field=option.lstrip("-"))
        spec[key.strip()] = value.strip()
    return spec


def _fixed(text, env):
    from calib.types import OperatingConditions

    rows = []
    for k, part in enumerate(s for s in str(text).split(";") if s.strip()):
        try:
            vals = [float(x) for x in part.split(",")]
            if len(vals) not in (2, 3):
                raise ValueError
        except ValueError:
            raise InputError(f"--fixed point {k + 1} {part!r}: expected tsr,pitch or tsr,pitch,rotor_speed",
                             "--fixed", field="fixed") from None
        rows.append(vals + [env.rotor_speed[0]] * (3 - len(vals)))
    lam, pitch, rpm = np.array(rows, float).T
    return OperatingConditions(rpm * np.pi / 30 * env.radius / lam, rpm, pitch, env.air_density, env.yaw[0])


def _counts(text):
    try:
        a, b = (int(x) for x in str(text).lower().split("x"))
        if a < 1 or b < 1:
            raise ValueError
        return a, b
    except ValueError:
        raise InputError(f"--points {text!r}: expected NTSRxNPITCH, e.g. 25x16", "--points", field="points") from None


def _design(args, problem, n_tsr, n_pitch):
    from calib.design import design
    from calib.design.candidates import check_inside, user_grid
    from calib.design.discrepancy import parse_discrepancy

    env = problem.envelope
    candidates = user_grid(_grid_spec(args.grid, "--grid"), env, "--grid") if args.grid else None
    if candidates is not None:
        check_inside(candidates, env, "--grid")
    targets = user_grid(_grid_spec(args.targets, "--targets"), env, "--targets") if args.targets else None
    fixed = _fixed(args.fixed, env) if args.fixed else None
    params = [s.strip() for s in args.parameters.split(",") if s.strip()] if args.parameters else None
    return design(problem, args.budget, candidates, fixed, args.criterion, params, targets, args.repeats,
                  n_tsr=n_tsr, n_pitch=n_pitch, draws=args.draws, seed=args.seed, cover=args.cover,
                  discrepancy=parse_discrepancy(args.discrepancy))


def _history(args, wf: Path, out: Path, printer):
    """An FMU workflow's run history in OUT/history (:func:`calib.history.open_history`): new, or with
    ``--resume`` reopened, refused when the workflow's inputs changed; None for the native BEM (its
    sensitivities are one cheap call)."""
    from calib.history import open_history
    from calib.workflow.schema import load_workflow
    from calib.workflow.setup import prepare, run_inputs

    workflow = load_workflow(wf)
    if not prepare(workflow).is_fmu:
        if args.resume:
            raise InputError("--resume is for an FMU's design (the native BEM's sensitivities are not recorded)",
                             "--resume", field="resume")
        return None
    out.mkdir(parents=True, exist_ok=True)
    arguments = {k: v for k, v in sorted(vars(args).items()) if k not in ("resume", "out", "func", "command")
                 and isinstance(v, (str, int, float, bool, type(None)))}
    hist = open_history(out, {"command": "design", "workflow": str(wf.resolve()), "arguments": arguments,
                              "inputs": run_inputs(workflow)}, args.resume)
    hist.event("start", resumed=args.resume, records=hist.n_records)
    if args.resume:
        printer(f"[calib design] resuming from {hist.folder}: {hist.n_records} model calls on record")
    return hist


def _choose(args, problem, res) -> dict:
    """Every choice of ``--choose`` K optional sensor groups scored at the design's points
    (:func:`calib.design.groups.subset_scores`), ranked by the held-out prediction variance of the
    ``--always`` groups' channels."""
    from calib.design.discrepancy import parse_discrepancy
    from calib.design.groups import subset_scores

    names = [g.name for g in problem.groups]
    always = [s.strip() for s in args.always.split(",") if s.strip()] if args.always else names[:1]
    bad = [g for g in always if g not in names]
    if bad:
        raise InputError(f"--always {bad[0]!r} is not one of the --sensors groups ({', '.join(names)})", "--always",
                         field="always")
    optional = [g for g in problem.groups if g.name not in always]
    if not optional or not 1 <= args.choose <= len(optional):
        raise InputError(f"--choose {args.choose}: expected 1..{len(optional)}, the optional sensor groups (those of "
                         f"--sensors not in --always: {', '.join(g.name for g in optional) or 'none'})", "--choose",
                         field="choose")
    targets = [c for g in problem.groups if g.name in always for c in g.channels]
    cond = res.candidates.subset(res.design)
    scores = subset_scores(problem, cond, args.choose, always=always, targets=targets,
                           discrepancy=parse_discrepancy(args.discrepancy))
    cost = {g.name: g.cost for g in problem.groups}
    rows = [{"rank": 0, "groups": " + ".join(s["groups"]), "cost_per_point": float(sum(cost[g] for g in s["groups"])),
             "heldout_variance": s["heldout_variance"], "ds_logdet": s["logdet"]} for s in scores]
    rows.sort(key=lambda r: r["heldout_variance"])
    for k, r in enumerate(rows):
        r["rank"] = k + 1
    return {"k": args.choose, "always": always, "targets": targets, "points": len(cond), "rows": rows}


def choice_sentence(choice: dict) -> str:
    """The sensor choice in words."""
    best, rows = choice["rows"][0], choice["rows"]
    return (f"Of {len(rows)} choices of {choice['k']} sensor group(s) to add to {' + '.join(choice['always'])}, "
            f"{best['groups']} predicts {', '.join(choice['targets'])} best at a held-out wind speed (variance "
            f"{best['heldout_variance']:.3g} noise variances, the worst choice {rows[-1]['heldout_variance']:.3g}); "
            "sensor_choice.csv ranks them all.")


def run_design(args, printer=print) -> int:
    from calib.design import problem_from_workflow
    from calib.design.report import paragraph, write_outputs
    from calib.logs import progress_line

    if args.budget <= 0:
        raise InputError(f"--budget must be a whole number of points > 0, got {args.budget}", "--budget",
                         field="budget")
    n_tsr, n_pitch = _counts(args.points)
    wf = Path(args.workflow)
    if not wf.is_file():
        raise InputError(f"no such workflow file: {wf}", "WORKFLOW", field="workflow")
    t0 = time.process_time()
    sensors = [s for s in args.sensors.split(",") if s.strip()] if args.sensors else None
    out = Path(args.out) if args.out else wf.parent / "design"
    hist = _history(args, wf, out, printer)
    problem = problem_from_workflow(wf, sensors=sensors, after=args.after, between_nodes=args.between_nodes,
                                    history=hist, progress=progress_line if hist is not None else None)
    try:
        res = _design(args, problem, n_tsr, n_pitch)
        choice = _choose(args, problem, res) if args.choose is not None else None
    finally:
        problem.close()
    if hist is not None:
        hist.event("finished", computed=hist.computed, replayed=hist.replayed)
        printer(f"[calib design] model calls: {hist.calls_sentence()}")
    paths = write_outputs(res, out)
    printer(paragraph(res))
    if choice is not None:
        from calib.design.report import write_choice
        paths.append(write_choice(choice, out))
        printer(choice_sentence(choice))
    printer(f"[calib design] {len(res.ok)} candidates, sensitivities {res.seconds['sensitivities']:.1f} s CPU, "
            f"selection {res.seconds['selection']:.1f} s CPU ({res.selection.exchanges} exchanges), total "
            f"{time.process_time() - t0:.1f} s CPU; wrote {', '.join(p.name for p in paths)} to {out}")
    return 0
