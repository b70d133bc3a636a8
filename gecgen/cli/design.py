"""`gecgen design ROBOT [--errors FILE] --poses N -o POSES.csv [--json]`: choose the poses to measure.

Candidates are uniform samples within the joint limits (`--candidates K`, `--seed`) or the rows
of `--from CSV`; constraints drop those a tracker cannot measure; `gecgen/plan/design.py`
chooses N of the rest (`--criterion`: D- or I-optimal). POSES.csv holds `pose`, `q1..qn` and, when the wrench is part
of the pose, `fx..mz` and `payload_kg`: the commands to send, and the measurement file's joint
columns once `target x y z` are filled in.

With `--fixtures FILE.csv` (sockets and planes, `model/fixture_file.py`) the configurations are chosen
for calibration without a tracker instead (`gecgen/plan/fixture_design.py`): POSES.csv is then a
measurement file's rows, `point` or `plane` named and `x y z` empty, to be recorded with the joints
read once the ball is seated or the probe touches.

With `--cameras FILE` (and `--board`, `--rig`) the poses are chosen for images instead
(`gecgen/plan/camera_design.py`, through the API's `design_images`): every board corner or marker in
view, informative for the pixel fit; POSES.csv is `pose, q1..qn`, the joints to take the images at.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from gecgen.cli.common import (MAX_POSES, MAX_SEED, ROBOT_HELP, number, numbers, progress_status, robot_and_model,
                               say, whole)
from gecgen.model import load_robot
from gecgen.model.measurements import read_measurements, write_csv
from gecgen.model.robot import WRENCH
from gecgen.model.table import read_table
from gecgen.model.validation import ModelError, require
from gecgen.plan import camera_design as CD
from gecgen.plan import design as D
from gecgen.plan import fixture_design as FD

DEFAULT_CANDIDATES = 5000


def add_parser(command):
    """Register `design` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("design", run)
    p.set_defaults(human=human)
    p.add_argument("robot", help=ROBOT_HELP)
    p.add_argument("--errors", help="error-model file (default: robots/NAME.errors.yaml)")
    p.add_argument("--poses", type=int, required=True, help="number of poses to choose")
    p.add_argument("-o", "--output", required=True, help="CSV of the chosen poses (pose, q1..qn[, fx..mz, payload_kg])")
    p.add_argument("--candidates", type=whole(1, MAX_POSES),
                   help=f"uniform samples within the joint limits to choose from (default {DEFAULT_CANDIDATES}); with "
                        f"--fixtures, configurations tried per fixture (default {FD.CANDIDATES}); with --cameras, poses "
                        f"drawn in --home +- --span, of which those in view are kept (default {CD.SAMPLED})")
    p.add_argument("--from", dest="from_csv", help="CSV of the allowed configurations (q1..qn, optional fx..mz and "
                                                    "aux columns) instead of uniform samples")
    p.add_argument("--seed", type=whole(0, MAX_SEED), default=0,
                   help="seed of the samples, the random comparison and the validation poses")
    p.add_argument("--targets", help="comma-separated targets measured at every pose (default: those of --given, "
                                     "else every target of the robot)")
    p.add_argument("--payload-kg", help="comma-separated payloads (kg) at the tool origin, as gecgen simulate: the "
                                        "wrench the sensor reads of their weight is part of each pose")
    p.add_argument("--gravity", help="gravity in the world frame for the payload wrench, m/s^2 (default: the robot "
                                     "file's `gravity`, standard gravity along -z unless it says otherwise)")
    p.add_argument("--min-z", type=number(), help="every measured target at world z >= this (m)")
    p.add_argument("--tracker", help="tracker position x,y,z in the world (m); with --max-incidence-deg")
    p.add_argument("--max-incidence-deg", type=number(0, 180, above=True),
                   help="largest angle between the line of sight to the tracker and the tool z axis (the "
                        "reflector's acceptance, deg)")
    p.add_argument("--given", help="measurement CSV already measured: the design adds poses to its information")
    p.add_argument("--criterion", choices=list(D.CRITERIA), default=D.DEFAULT_CRITERION,
                   help="D: maximise log det of the information (the coefficients' joint confidence region); I: "
                        "minimise the mean predicted variance of the measured positions over the candidates "
                        "(default %(default)s)")
    p.add_argument("--noise-mm", type=float, default=None,
                   help=f"measurement noise per coordinate (mm) for the predicted uncertainty (default "
                        f"{1e3 * D.NOISE_M:g}; with --fixtures, the seating noise, default {1e3 * FD.NOISE_M:g})")
    p.add_argument("--fixtures", help="CSV of sockets and planes (name, x, y, z[, nx, ny, nz], m in the robot's world "
                                      "frame): choose configurations for calibration without a tracker")
    p.add_argument("--target", help="with --fixtures: the target that sits in the sockets or touches the planes "
                                    "(default: the robot's only target)")
    p.add_argument("--patch-mm", type=number(0, 10_000, above=True),
                   help=f"with --fixtures: half-width of the square of each plane the touches are planned in (mm, "
                        f"default {1e3 * FD.PATCH_M:g})")
    g = p.add_argument_group("with a camera (docs/reference.md, \"Designing the images\"): poses at which the "
                             "cameras see the board or the markers, for the pixel fit")
    g.add_argument("--cameras", metavar="FILE", help="camera file: each camera's intrinsics and mount (world or tool)")
    g.add_argument("--board", metavar="FILE", help="a camera on the tool: the board it sees, fixed in the world")
    g.add_argument("--rig", metavar="FILE", help="where the cameras (and the board) are: per camera its rotation and "
                                                 "translation, as simulate --rig-out writes them")
    g.add_argument("--home", type=numbers(), metavar="Q1,..,QN",
                   help="the candidates are drawn in home +- span (rad or m; default the middle of each joint's range)")
    g.add_argument("--span", type=numbers(0), metavar="S",
                   help=f"half-span of the candidates about --home, rad or m (one value or one per joint, default "
                        f"{CD.SPAN:g})")
    g.add_argument("--margin-px", type=number(0, 10_000),
                   help=f"every point at least this far inside the image (px, default {CD.MARGIN_PX:g})")
    g.add_argument("--max-angle-deg", type=number(0, 180, above=True),
                   help=f"largest angle between the line of sight and the board's face (deg, default "
                        f"{CD.MAX_ANGLE_DEG:g}); markers: their tool's z axis, unchecked unless given")
    g.add_argument("--distance-m", type=numbers(0), metavar="NEAR,FAR",
                   help=f"every point's depth along the optical axis within these (m, default "
                        f"{CD.DISTANCE_M[0]:g},{CD.DISTANCE_M[1]:g})")
    g.add_argument("--noise-px", type=number(0, 100, above=True),
                   help=f"the corners' noise per coordinate for the predicted figures (px, default {CD.NOISE_PX:g})")


def _numbers(text: str, option: str, count: int | None, unit: str) -> list[float]:
    """Comma-separated finite numbers of an option (count of them when given)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    ok = values and all(np.isfinite(values)) and (count is None or len(values) == count)
    require(ok, f"--{option} {text}: expected {count or 'one or more'} comma-separated numbers ({unit})")
    return values


def _candidates(args, robot, model):
    gravity = robot.gravity if args.gravity is None else _numbers(args.gravity, "gravity", 3, "m/s^2")
    payloads = _numbers(args.payload_kg, "payload-kg", None, "kg") if args.payload_kg else None
    require(payloads is None or min(payloads) >= 0, f"--payload-kg {args.payload_kg}: payloads are masses, >= 0 kg")
    if args.from_csv:
        require(args.candidates is None, "--candidates: the candidates are the rows of --from; drop one of the two")
        return D.file_candidates(args.from_csv, robot, model.aux, payloads, gravity)
    require(not model.aux, f"the error model uses auxiliary signals ({', '.join(model.aux)}) that uniform samples "
                           f"lack: give the candidates with --from CSV holding those columns")
    n = DEFAULT_CANDIDATES if args.candidates is None else args.candidates
    require(n >= 1, f"--candidates {n}: give at least 1 candidate pose")
    return D.uniform_candidates(robot, n, np.random.default_rng(args.seed), payloads, gravity)


def _targets(args, robot, given) -> np.ndarray:
    names = list(robot.targets)
    if not args.targets:
        return np.unique(given.target) if given is not None else np.arange(len(names))
    chosen = [t.strip() for t in args.targets.split(",")]
    for t in chosen:
        require(t in names, f"--targets: '{t}' is not a target of {robot.name} ({', '.join(names)})")
    return np.array(sorted({names.index(t) for t in chosen}))


def run(args) -> dict:
    with progress_status(not args.json) as status:
        return _designed(args, status)


def _designed(args, status) -> dict:
    """The command's work; says how far it is on `status` (`common.progress_status`)."""
    from gecgen.runtime.compiled import CompiledModel

    require(1 <= args.poses <= MAX_POSES,
            f"--poses {args.poses}: give at least 1 pose to design (at most {MAX_POSES:,})")
    if args.cameras:
        return _run_cameras(args, status)
    for option in CAMERA_OPTIONS:
        require(getattr(args, option) is None, f"--{option.replace('_', '-')} goes with --cameras (image points); "
                                               f"give the camera file or drop it")
    if args.noise_mm is None:
        args.noise_mm = 1e3 * (FD.NOISE_M if args.fixtures else D.NOISE_M)
    require(math.isfinite(args.noise_mm) and args.noise_mm > 0,
            f"--noise-mm {args.noise_mm}: give the measurement noise per coordinate, > 0 mm")
    if args.fixtures:
        return _run_fixtures(args, status)
    for option in ("target", "patch_mm"):
        require(getattr(args, option) is None, f"--{option.replace('_', '-')} goes with --fixtures; give the "
                                               f"fixtures file or drop it")
    require((args.tracker is None) == (args.max_incidence_deg is None),
            "--tracker and --max-incidence-deg go together: give the tracker position x,y,z (m) and the "
            "reflector's largest incidence angle (deg)")
    robot = load_robot(args.robot)
    given = read_measurements(args.given, robot) if args.given else None
    if given is not None and given.orientation is not None:
        warnings.warn(f"{args.given}: design counts the measured positions of --given only, not its orientations "
                      f"(designing for pose measurements is not supported yet): the information of the data "
                      f"measured is underestimated")
    columns = given.aux_names if given is not None else ()
    if args.from_csv:
        header = read_table(args.from_csv, "file of candidate poses", "q1..qn").header
        columns = tuple(h for h in header if h not in WRENCH and not (h[:1] == "q" and h[1:].isdigit()))
    robot, model = robot_and_model(args.robot, args.errors, columns)
    if given is not None and robot.estimated:  # the measured poses place what the robot file leaves open
        from gecgen.fit.placement import place_targets

        robot = place_targets(robot, given)[0]
    cands = _candidates(args, robot, model)
    targets = _targets(args, robot, given)
    tracker = _numbers(args.tracker, "tracker", 3, "m") if args.tracker else None
    ok = D.constraint_mask(robot, cands, targets, args.min_z, tracker, args.max_incidence_deg)
    constraints = {k: v for k, v in (("min_z", args.min_z), ("tracker", tracker),
                                     ("max_incidence_deg", args.max_incidence_deg)) if v is not None}
    if not ok.any():
        given_as = " ".join(f"--{k.replace('_', '-')} {args.tracker if k == 'tracker' else v}"
                            for k, v in constraints.items())
        raise ModelError(f"no candidate pose passes the constraints ({given_as}): relax them, or give other "
                         f"candidates (--candidates, --from)")
    allowed = np.nonzero(ok)[0]
    cands = cands.subset(allowed)
    say(status, f"choosing {args.poses} poses of {len(cands)} candidates ({args.criterion}-optimal)")
    result = D.design_poses(CompiledModel(robot, model), cands, args.poses, targets, given, args.seed,
                            args.noise_mm / 1e3, criterion=args.criterion)
    first = int(given.pose_ids.max()) + 1 if given is not None else 0  # appends to the given file's ids
    chosen = cands.subset(result.chosen)
    header = ["pose", *(f"q{i + 1}" for i in range(robot.n))]
    header += list(WRENCH) if chosen.has_wrench else []
    header += ["payload_kg"] if chosen.payload_kg is not None else []
    header += list(model.aux)
    rows = []
    for p in range(len(chosen)):
        row = [first + p, *map(repr, chosen.q[p].tolist())]
        row += list(map(repr, chosen.w[p].tolist())) if chosen.has_wrench else []
        row += [repr(float(chosen.payload_kg[p]))] if chosen.payload_kg is not None else []
        rows.append(row + list(map(repr, chosen.aux[p].tolist())))
    write_csv(args.output, header, rows)
    return {"robot": robot.name, "error_model": model.source, "output": str(args.output), **result.to_dict(),
            "targets": [robot.target_names[t] for t in targets], "constraints": constraints,
            "n_sampled": len(ok), "seed": args.seed, "given": args.given}


#: options of a tracker design that a fixture design has no use for: refused, never ignored
NOT_WITH_FIXTURES = {"from_csv": "--from", "targets": "--targets", "payload_kg": "--payload-kg", "min_z": "--min-z",
                     "tracker": "--tracker", "max_incidence_deg": "--max-incidence-deg", "given": "--given"}


def _run_fixtures(args, status) -> dict:
    from gecgen.model.fixture_file import read_fixtures
    from gecgen.runtime.compiled import CompiledModel

    for option, flag in NOT_WITH_FIXTURES.items():
        require(getattr(args, option) is None, f"{flag} does not apply to a design for --fixtures (the target sits "
                                               f"in the sockets or on the planes); drop it")
    require(args.criterion == "D", f"--criterion {args.criterion}: a design for --fixtures is D-optimal; drop it")
    robot, model = robot_and_model(args.robot, args.errors)
    require(not model.aux, f"the error model uses auxiliary signals ({', '.join(model.aux)}) that a fixture design "
                           f"cannot plan; use a model without them")
    names = robot.target_names
    if args.target is None:
        require(len(names) == 1, f"{robot.name} has {len(names)} targets ({', '.join(names)}): name the one that sits "
                                 f"in the sockets or touches with --target")
        target = 0
    else:
        require(args.target in names, f"--target {args.target}: not a target of {robot.name} ({', '.join(names)})")
        target = names.index(args.target)
    fixtures = read_fixtures(args.fixtures)
    n = FD.CANDIDATES if args.candidates is None else args.candidates
    patch = FD.PATCH_M if args.patch_mm is None else args.patch_mm / 1e3
    say(status, f"solving the robot's configurations at each fixture ({n} candidates)")
    cands = FD.fixture_candidates(robot, fixtures, target, n, np.random.default_rng(args.seed), patch)
    say(status, f"choosing {args.poses} configurations of the candidates (D-optimal)")
    result = FD.design_fixtures(CompiledModel(robot, model), cands, args.poses, target, args.seed, args.noise_mm / 1e3)
    header = ["pose", *(f"q{i + 1}" for i in range(robot.n)), "target", "x", "y", "z", "point", "plane"]
    rows = []
    for f, q, chosen in zip(fixtures, cands.q, result.chosen):
        for i in chosen:
            where = ["", f.name] if f.is_plane else [f.name, ""]
            rows.append([len(rows), *map(repr, q[i].tolist()), names[target], "", "", "", *where])
    write_csv(args.output, header, rows)
    return {"robot": robot.name, "error_model": model.source, "output": str(args.output),
            **result.to_dict(fixtures), "target": names[target], "seed": args.seed}


#: options of a design for images, refused without --cameras
CAMERA_OPTIONS = ("board", "rig", "home", "span", "margin_px", "max_angle_deg", "distance_m", "noise_px")
#: options of a tracker or fixture design that a design for images has no use for: refused, never ignored
NOT_WITH_CAMERAS = {"targets": "--targets", "payload_kg": "--payload-kg", "gravity": "--gravity", "min_z": "--min-z",
                    "tracker": "--tracker", "max_incidence_deg": "--max-incidence-deg", "given": "--given",
                    "fixtures": "--fixtures", "target": "--target", "patch_mm": "--patch-mm", "noise_mm": "--noise-mm"}


def _run_cameras(args, status) -> dict:
    from gecgen.api import design_images

    for option, flag in NOT_WITH_CAMERAS.items():
        require(getattr(args, option) is None, f"{flag} does not apply to a design for images (--cameras); drop it"
                                               + ("; the corners' noise is --noise-px" if option == "noise_mm" else ""))
    require(args.rig, "--cameras: give --rig FILE, where the cameras (and the board) are: a design keeps what they "
                      "see in view")
    require(args.distance_m is None or len(args.distance_m) == 2,
            f"--distance-m: give NEAR,FAR (m), not {len(args.distance_m or [])} values")
    robot, model = robot_and_model(args.robot, args.errors)
    if args.from_csv:
        require(args.candidates is None, "--candidates: the candidates are the rows of --from; drop one of the two")
        require(args.home is None and args.span is None, "--home and --span draw the candidates; with --from the "
                                                         "candidates are its rows: drop one of them")
        candidates = D.file_candidates(args.from_csv, robot, model.aux).q
    else:
        candidates = args.candidates
    require(not model.aux, f"the error model uses auxiliary signals ({', '.join(model.aux)}) that a design for images "
                           f"cannot plan; use a model without them")
    say(status, f"choosing {args.poses} poses the cameras see the {'board' if args.board else 'markers'} from")
    out = design_images(robot, args.cameras, args.rig, args.poses, board=args.board, errors=model,
                        candidates=candidates, home=args.home, span=args.span, seed=args.seed,
                        criterion=args.criterion, noise_px=args.noise_px, margin_px=args.margin_px,
                        max_angle_deg=args.max_angle_deg, distance_m=args.distance_m)
    header = ["pose", *(f"q{i + 1}" for i in range(robot.n))]
    write_csv(args.output, header, [[p, *map(repr, q.tolist())] for p, q in enumerate(out.q)])
    rig = out.rig
    return {"robot": robot.name, "error_model": model.source, "output": str(args.output), **out.design.to_dict(),
            "mount": "tool" if rig.tool else "world", "cameras": list(rig.cameras),
            "view": {"margin_px": rig.margin_px, "max_angle_deg": rig.max_angle_deg,
                     "distance_m": list(rig.distance_m)},
            "n_sampled": out.n_sampled, "n_in_view": out.n_in_view, "seed": args.seed}


#: the tracker design's comparison table: (JSON key, its figure for the random poses, label, what it means)
COMPARED = (("log_det", "random_log_det", "log det of the information (D)", "higher is better"),
            ("mean_variance", "random_mean_variance", "mean prediction variance (I)",
             "per unit noise variance; lower is better"),
            ("rms_mm", "random_rms_mm", "predicted position std, RMS (mm)", "at {noise} noise per coordinate, over "
                                                                             "{n}"),
            ("max_mm", "random_max_mm", "predicted position std, max (mm)", ""),
            ("O1", "random_O1", "O1: geometric mean singular value", "divided by sqrt(rows); higher is better"),
            ("O2", "random_O2", "O2: condition number", "lower is better"),
            ("O3", "random_O3", "O3: smallest singular value", "higher is better"))


def human(result: dict):
    """design's summary for a person: what each figure is and which way is better, the designed
    poses beside as many random ones of the same candidates (a fixture design's: `_fixtures_human`);
    --json has every figure."""
    from gecgen.cli.human import scalar

    if "predicted_std" not in result:
        _fixtures_human(result)
        return
    if "mount" in result:
        _cameras_human(result)
        return
    figures = _figures(result)
    constraints = ", ".join(f"{k} {v}" for k, v in result["constraints"].items()) or "none"
    print(f"robot: {result['robot']} (error model {result['error_model']})")
    print(f"output: {result['output']}")
    print(f"poses: {result['n_poses']}, chosen among {result['n_candidates']} candidate poses ({result['n_sampled']} "
          f"sampled with seed {result['seed']}; constraints: {constraints})")
    print(f"targets measured: {', '.join(result['targets'])}")
    if result["given"]:
        print(f"added to the poses of {result['given']}, whose information is counted")
    chosen = {"D": "D-optimal (the largest log det of the information", "I": "I-optimal (the smallest mean "
              "variance of the predicted positions"}[result["criterion"]]
    print(f"criterion: {chosen} on the {result['n_identifiable']} identifiable coefficients)")
    _compared(figures, f"{scalar(figures['noise_mm'])} mm")
    _volume(result)
    print(f"not excited by any candidate: {', '.join(result['unexcitable']) or 'none'}")
    history = result["history"]
    refreshed = f"; the pool of candidates refreshed {result['rounds']} times" if result["rounds"] else ""
    print(f"search: a greedy start, then {result['swaps']} exchanges in {result['passes']} passes (criterion "
          f"{scalar(history[0])} -> {scalar(history[-1])}){refreshed}")


def _figures(result: dict) -> dict:
    return {**{k: result[k] for k in ("log_det", "random_log_det", "mean_variance", "random_mean_variance")},
            **result["observability"], **result["predicted_std"]}


def _compared(figures: dict, noise: str, kind: str = "candidate"):
    """The designed poses' figures beside the random ones' (COMPARED), the noise as `noise` says it, the
    candidates named `kind` ("candidate", "in-view")."""
    from gecgen.cli.human import scalar

    same = "candidates" if kind == "candidate" else f"{kind} poses"
    print(f"  {'':<38}{'designed':>10}{'random':>10}  (random: as many poses drawn from the same {same})")
    for key, random, label, means in COMPARED:
        means = means.format(noise=noise, n=f"{figures['n_validation_poses']} {kind} poses")
        print(f"  {label:<38}{scalar(figures[key]):>10}{scalar(figures[random]):>10}  {means}".rstrip())


def _cameras_human(result: dict):
    """A design for images (`human`): the view it keeps, the comparison, what the images leave out."""
    from gecgen.cli.human import scalar

    view = result["view"]
    angle = f"{view['max_angle_deg']:g} deg" if view["max_angle_deg"] is not None else "unchecked"
    what = "board corner" if result["mount"] == "tool" else "marker"
    print(f"robot: {result['robot']} (error model {result['error_model']})")
    print(f"output: {result['output']}")
    print(f"poses: {result['n_poses']}, chosen among {result['n_candidates']} of the {result['n_in_view']} candidate "
          f"poses in view ({result['n_sampled']} sampled with seed {result['seed']})")
    print(f"in view: every {what} for camera {', '.join(result['cameras'])}: {scalar(view['margin_px'])} px inside the "
          f"image, {view['distance_m'][0]:g}-{view['distance_m'][1]:g} m deep, angle to its face {angle}")
    chosen = {"D": "D-optimal (the largest log det of the information", "I": "I-optimal (the smallest mean "
              "variance of the predicted image points"}[result["criterion"]]
    print(f"criterion: {chosen})")
    poses = "the camera's and the board's" if result["mount"] == "tool" else "the cameras'"
    print(f"  over the {result['n_pose_unknowns']} unknowns of {poses} poses and the {result['n_identifiable']} "
          f"coefficients the images determine")
    print("  (the predicted std is the image points', across the ray at each point)")
    _compared(_figures(result), f"{scalar(result['predicted_std']['noise_px'])} px", "in-view")
    _volume(result, "the joint")
    left = [e["param"] for e in result["eliminated"] if e["detail"].startswith(("camera pose", "scale"))]
    print(f"left to the cameras' poses or the scale (pixels cannot give them): {', '.join(left) or 'none'}")
    history = result["history"]
    print(f"search: a greedy start, then {result['swaps']} exchanges in {result['passes']} passes (criterion "
          f"{scalar(history[0])} -> {scalar(history[-1])})")


def _volume(result: dict, unknowns: str = "the coefficients'"):
    """The designed poses' log det against the random ones', as what a person can picture."""
    if result["log_det"] is not None and result["random_log_det"] is not None:
        gain = result["log_det"] - result["random_log_det"]
        print(f"  with the designed poses {unknowns} confidence region is {math.exp(abs(gain) / 2):.3g} times "
              f"{'smaller' if gain >= 0 else 'larger'} in volume (e^(gain in log det / 2))")


def _fixtures_human(result: dict):
    """A fixture design's summary (`human`): the same comparison, then each fixture's share."""
    from gecgen.cli.human import print_human, scalar

    predicted = result["predicted"]
    print(f"robot: {result['robot']} (error model {result['error_model']})")
    print(f"output: {result['output']}")
    print(f"configurations: {result['n_poses']} for target {result['target']} (seed {result['seed']})")
    print(f"criterion: D-optimal (the largest log det of the information on the {result['n_identifiable']} "
          f"identifiable coefficients)")
    print(f"  {'':<38}{'designed':>10}{'random':>10}  (random: as many configurations drawn from the same candidates)")
    print(f"  {'log det of the information (D)':<38}{scalar(result['log_det']):>10}"
          f"{scalar(result['random_log_det']):>10}  higher is better")
    print(f"  {'predicted RMS error added (mm)':<38}{scalar(predicted['rms_mm']):>10}"
          f"{scalar(predicted['random_rms_mm']):>10}  by the coefficients' uncertainty at {scalar(predicted['noise_mm'])}"
          f" mm noise")
    _volume(result)
    print_human({k: result[k] for k in ("fixtures", "by_fixtures")})
    print(f"directions of the coefficients no configuration shows: {result['unseen']}")
    print(f"search: a greedy start, then {result['swaps']} exchanges in {result['passes']} passes")
