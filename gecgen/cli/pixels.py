"""`gecgen identify ROBOT PIXELS.csv --cameras CAMERAS.yaml [--board BOARD.yaml]`: a calibration from image
points (`fit.camera`), written as identify writes one; `gecgen simulate ROBOT --cameras CAMERAS.yaml ...`:
image points of a truth robot (`simulate.camera`)."""
from __future__ import annotations

from pathlib import Path

from gecgen.cli.common import number, numbers
from gecgen.model.robot import Robot
from gecgen.model.validation import ModelError, require


def add_options(p):
    """identify's, diagnose's and calibrate's options for image points."""
    g = p.add_argument_group("with a camera (docs/reference.md, \"Cameras\"): DATA is a pixel file")
    g.add_argument("--cameras", metavar="FILE", help="camera file: each camera's intrinsics and mount (world or tool)")
    g.add_argument("--board", metavar="FILE", help="board file of the chessboard a camera on the tool sees")
    g.add_argument("--refine-intrinsics", action="store_true",
                   help="refine each camera's fx, fy, cx, cy and distortion in the same fit (in every fit of "
                        "diagnose's and calibrate's loop), from the camera file's values (JSON intrinsics, with "
                        "their std)")
    g.add_argument("--noise-px", type=number(0, 100, above=True), metavar="PX",
                   help="the corners' noise per coordinate, px (1 sigma): the coefficients the images determine too "
                        "weakly against it are held at zero and named (default: the fit's own residual)")


def identified(args) -> dict:
    """The calibration from the pixel file args.data and its JSON result."""
    from gecgen.cli.common import robot_and_model, warned
    from gecgen.cli.human import warning_lines
    from gecgen.model.cameras import read_board, read_cameras
    from gecgen.model.pixels import read_pixels
    from gecgen.fit.calibration import save
    from gecgen.fit.camera import calibration_of, fit_pixels, pose_uncertainty, refuse_untrustworthy

    cameras_given(args)
    for option in ("ridge", "rank_tol", "noise_mm"):
        value = getattr(args, option, None)
        require(value in (None, "0", False), f"--{option.replace('_', '-')} is not supported with --cameras yet; "
                                             f"leave it out")
    require(args.register in ("auto", "never"), "--register always: with --cameras the cameras' poses are fitted "
                                               "with the robot; leave it out")
    cameras = read_cameras(args.cameras)
    board = read_board(args.board) if args.board else None
    robot, model = robot_and_model(args.robot, args.errors)
    data = read_pixels(args.data, robot, cameras, board)
    require(not model.aux or set(model.aux) <= set(data.aux_names),
            f"{args.data}: the error model uses auxiliary signals {', '.join(model.aux)} the pixel file lacks; "
            f"add the columns or use another error model")
    with warned() as caught:
        fit = fit_pixels(robot, model, data, cameras, board, loss=args.loss, noise_px=args.noise_px,
                         intrinsics=args.refine_intrinsics, significance=not args.keep_insignificant)
    refuse_untrustworthy(fit, str(args.data))
    calibration = calibration_of(robot, model, fit, cameras, board)
    calibration.report["camera_uncertainty"] = pose_uncertainty(robot, model, data, cameras, board, fit)
    out = args.output or f"{robot.name}.calib.json"
    save(calibration, out)
    result = {"robot": robot.name, "data": str(args.data), "calibration": str(out), "measurement": "pixels",
            **{k: calibration.report[k] for k in ("n_params", "n_identifiable", "eliminated", "before", "train",
                                                  "sigma_px", "outliers", "converged", "iterations", "cameras",
                                                  "held", "scale", "camera_uncertainty")},
            **({"board": calibration.report["board"]} if board is not None else {}),
            **({"intrinsics": calibration.report["intrinsics"]} if args.refine_intrinsics else {}),
            "warnings": warning_lines(caught),
            "next": f"{compensate_next(robot, out)}, gecgen export {out} --c DIR"}
    from shlex import quote

    from gecgen.fit.significance import overall
    from gecgen.report.content import image_coverage
    from gecgen.report.verdict import pixels_next_step

    noise = None
    if args.noise_px is not None:
        fitted = (len(fit.kept) + 6 * (len(fit.poses) + (fit.board is not None))
                  + sum(len(v) for v in (fit.intrinsics_std or {}).values()))
        # overall() takes metres and reports mm: px scaled by 1e-3 come back as px (chi-square is scale-free)
        noise = overall(1e-3 * fit.sigma_px, 2 * len(data.uv) - fitted, 1e-3 * args.noise_px)
    evaluate = (f"gecgen evaluate {quote(str(out))} HELD_OUT_PIXELS.csv --cameras {quote(str(args.cameras))}"
                + (f" --board {quote(str(args.board))}" if args.board else ""))
    assessment = pixels_next_step(result, noise, image_coverage(data, cameras), evaluate)
    result["next_step"] = assessment.next_step
    if args.report:
        from gecgen import report

        result.update(report.write(report.content.pixels(robot, data, fit, calibration, str(out), cameras,
                                                         result["warnings"], assessment), args.report))
    return result


def _by_branch(summaries: dict) -> dict:
    """{stage: a summary with `branches`} as {branch: {stage: its figures}} (px, and mm at the target)."""
    out: dict = {}
    for stage, summary in summaries.items():
        for branch, figures in summary["branches"].items():
            out.setdefault(branch, {})[stage] = figures
    return out


def recorded_rig(args):
    """For a command that reads a pixel calibration with new images (evaluate, check, accuracy --cameras):
    the calibration (CALIB) and its cameras and board files, read, after refusing in one line files other
    than those the calibration recorded (the command refuses --board alone first: `cameras_given`):
    (Calibration, cameras, board or None)."""
    from gecgen.fit.calibration import load
    from gecgen.fit.camera import refuse_another_rig
    from gecgen.model.cameras import read_board, read_cameras

    calibration = load(args.calibration)
    cameras = read_cameras(args.cameras)
    board = read_board(args.board) if args.board else None
    refuse_another_rig(calibration, args.calibration, cameras, args.cameras, board)
    return calibration, cameras, board


def cameras_given(args):
    """Refuse --board or --refine-intrinsics without --cameras, in one line, before any other refusal (the
    options those would name mean nothing without cameras)."""
    what = ("--board names the board a carried camera sees" if args.board else
            "--refine-intrinsics refines the intrinsics of the cameras of image points")
    require(args.cameras, f"{what}: give --cameras too")


def _loop_cameras(args):
    """diagnose's and calibrate's --cameras and --board, read, after refusing (one line) the tracker
    options that mean nothing for image points: (cameras, board or None)."""
    from gecgen.model.cameras import read_board, read_cameras

    cameras_given(args)
    given = [o for o, v in (("--register", args.register not in ("auto", "never")), ("--noise-mm", args.noise_mm),
                            ("--orientation-length", args.orientation_length)) if v]
    require(not given, f"{given[0] if given else ''} is not supported with --cameras (the cameras' poses are fitted "
                       f"with the robot; the corners' noise is --noise-px); leave it out")
    return read_cameras(args.cameras), read_board(args.board) if args.board else None


def diagnosed(args) -> dict:
    """`gecgen diagnose ROBOT PIXELS.csv --cameras FILE`: the closed loop on image points
    (`loop.pixels.ImagePoints`), its new error model and code, and its JSON result (mm at the target and
    px)."""
    from gecgen.cli.common import robot_and_model
    from gecgen.emit import generate
    from gecgen.loop.diagnose import diagnose, verdict, write_error_model
    from gecgen.loop.pixels import ImagePoints
    from gecgen.model.measurements import hold_out
    from gecgen.model.pixels import read_pixels
    from gecgen.runtime.compiled import printed_code

    cameras, board = _loop_cameras(args)
    robot, model = robot_and_model(args.robot, args.errors)
    data = read_pixels(args.data, robot, cameras, board)
    val = read_pixels(args.val, robot, cameras, board) if args.val else None
    if args.holdout is not None:
        data, val = hold_out(data, args.holdout, args.seed)
    require(not model.aux or set(model.aux) <= set(data.aux_names),
            f"{args.data}: the error model uses auxiliary signals {', '.join(model.aux)} the pixel file lacks; "
            f"add the columns or use another error model")
    measure = ImagePoints(robot, cameras, board, args.noise_px, intrinsics=args.refine_intrinsics)
    try:
        diag = diagnose(robot, model, data, val, seed=args.seed, noise_mm=args.noise_px, max_rounds=args.max_rounds,
                        measure=measure)
    except RuntimeError as exc:  # the declared model's own fit cannot be trusted
        raise ModelError(f"{args.data}: {exc}") from None
    out = args.output or f"{robot.name}.diagnosed.errors.yaml"
    write_error_model(robot, diag.final.model, diag.effects, out)
    generated = args.generated or out.removesuffix(".yaml").removesuffix(".errors") + "_generated"
    generate(robot, diag.final.model, generated, printed_code(robot, diag.final.model))
    # the stated noise too: identify holds against it what the images determine too weakly, as diagnose's fits did
    rig = (f"--cameras {args.cameras}" + (f" --board {args.board}" if args.board else "")
           + (" --refine-intrinsics" if args.refine_intrinsics else "")
           + (f" --noise-px {args.noise_px:g}" if args.noise_px is not None else ""))
    result = {"robot": robot.name, "measurement": "pixels", "error_model": diag.initial.model.source,
            "before": diag.before, "after": diag.after, "effects": [e.to_dict() for e in diag.effects],
            "errors_out": str(out), "generated": str(generated), "rounds": diag.history,
            "candidates_tested": diag.candidates_tested, "remaining": diag.remaining, "verdict": verdict(diag.remaining),
            "validation": str(args.val) if args.val else f"--holdout {args.holdout:g} of DATA (seed {args.seed})"
            if args.holdout is not None else "internal hold-out of 1/5 of the poses",
            "next": f"gecgen identify {args.robot} {args.data} --errors {out} {rig} -o {robot.name}.calib.json"}
    if robot.branches:  # a tree: each hand's figures, as diagnose gives them from tracker points
        for key, test in (("train_branches", None), ("val_branches", val)):
            if key == "train_branches" or test is not None:  # diagnose's internal hold-out is its own
                result[key] = _by_branch({stage: rnd.fit.train if test is None else measure.held_out(rnd, test)
                                          for stage, rnd in (("before", diag.initial), ("after", diag.final))})
    if args.report:  # the diagnosed model's fit on the training images, what it added first
        from gecgen import report
        from gecgen.fit.camera import calibration_of

        final = diag.final
        content = report.content.pixels(robot, data, final.fit, calibration_of(robot, final.model, final.fit, cameras, board),
                                        str(out), cameras, command="diagnose",
                                        lead=report.content.pixel_diagnosis(result), held_out=True)
        result.update(report.write(content, args.report))
    return result


def calibrated(args, out, build, status) -> dict:
    """`gecgen calibrate ROBOT PIXELS.csv --cameras FILE -o DIR`: the model chosen among the candidates by
    cross-validation over the training images (`loop.calibrate.choose` on `loop.pixels.ImagePoints`),
    written into `build` (which becomes `out`) as calibrate writes a tracker calibration; its JSON result,
    the validation images scored with the cameras (and board) as the fit placed them."""
    import warnings

    import numpy as np

    from gecgen import report
    from gecgen.api import model_names
    from gecgen.cli.common import say
    from gecgen.cli.human import warning_lines
    from gecgen.deliver import export
    from gecgen.fit.calibration import save
    from gecgen.fit.camera import calibration_of, frame_robot, pose_uncertainty, refuse_untrustworthy, summary_at
    from gecgen.fit.inputs import error_model
    from gecgen.loop.calibrate import choose
    from gecgen.loop.diagnose import write_error_model
    from gecgen.loop.pixels import ImagePoints
    from gecgen.model import load_robot
    from gecgen.model.files import write_atomically
    from gecgen.model.measurements import hold_out
    from gecgen.model.pixels import read_pixels
    from gecgen.runtime.compiled import CompiledModel, build_in_background

    cameras, board = _loop_cameras(args)
    robot = load_robot(args.robot)
    data = read_pixels(args.train, robot, cameras, board)
    val = read_pixels(args.val, robot, cameras, board) if args.val else None
    if args.holdout is not None:
        data, val = hold_out(data, args.holdout, args.seed)
    default = error_model(args.errors, robot, data.aux_names, constant=False)
    names = model_names(tuple(n.strip() for n in args.models.split(",")), "--models")
    measure = ImagePoints(robot, cameras, board, args.noise_px, significance=not args.keep_insignificant,
                          intrinsics=args.refine_intrinsics)
    say(status, "choosing the model by cross-validation over the training images")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            choice = choose(robot, data, default, args.seed, names=names, measure=measure,
                            progress=lambda name: say(status, f"cross-validating the {name} model on the training "
                                                              f"images"), stage=lambda text: say(status, text))
        except RuntimeError as exc:
            raise ModelError(f"{args.train}: {str(exc).splitlines()[0]}") from None
    refuse_untrustworthy(choice.fit, str(args.train))
    say(status, f"writing the calibration, its code and the report into {out}")
    calib = calibration_of(robot, choice.model, choice.fit, cameras, board)
    calib.report.update({"model": choice.chosen.name, "candidates": choice.table,
                         "camera_uncertainty": pose_uncertainty(robot, choice.model, data, cameras, board,
                                                                choice.fit)})
    scored = {}
    if val is not None:
        cm = CompiledModel(frame_robot(robot), choice.model)
        scored["validation"] = str(args.val) if args.val else f"--holdout {args.holdout:g} of {args.train} (seed " \
                                                              f"{args.seed})"
        scored["val_before"], scored["val"] = (summary_at(cm, robot, val, cameras, board, choice.fit.g, c,
                                                          args.refine_intrinsics)
                                               for c in (np.zeros(len(choice.fit.c)), choice.fit.c))
        # what `check --cameras` judges new images against: the residual where the fit did not look
        calib.report["validation_px"] = {"images": scored["validation"], "rms_px": scored["val"]["rms_px"],
                                         "sigma_px": scored["val"]["rms_px"] / np.sqrt(2), "dof": 2 * len(val.uv)}
    save(calib, build / "calibration.json")
    effects = choice.diagnosis.effects if choice.diagnosis else []
    write_error_model(robot, choice.model, effects, build / "errors.yaml")
    # as calibrate from tracker data: the C printed here first, its compile left to the background
    delivered = CompiledModel(calib.robot, calib.model, build=False)
    code, _ = export.c_files(calib, delivered, str(out / "calibration.json"))
    for name, text in code.items():
        write_atomically(build / "generated" / name, text)
    fit = choice.fit
    result = {"robot": robot.name, "train_data": str(args.train), "output": str(out), "measurement": "pixels",
              "model": choice.chosen.name, "error_model": str(out / "errors.yaml"), "candidates": choice.table,
              "n_params": len(choice.model.coefficients), "n_identifiable": len(fit.kept), "before": fit.before,
              "train": fit.train, "outliers": [o.to_dict() for o in fit.outliers], "held": calib.report["held"],
              "effects": [e.to_dict() for e in effects], "cameras": calib.report["cameras"],
              "camera_uncertainty": calib.report["camera_uncertainty"],
              **({"board": calib.report["board"]} if board is not None else {}),
              **({"intrinsics": calib.report["intrinsics"]} if args.refine_intrinsics else {}), **scored}
    files = {"calibration": out / "calibration.json", "errors": out / "errors.yaml", "generated": out / "generated",
             "coefficient_header": out / "generated" / f"{robot.name}_calibration.h"}
    result["files"] = {k: str(v) for k, v in files.items()}
    result["warnings"] = warning_lines(caught)
    rig = f"--cameras {args.cameras}" + (f" --board {args.board}" if args.board else "")
    result["next"] = (f"gecgen evaluate {out / 'calibration.json'} HELD_OUT.csv {rig}, "
                      f"{compensate_next(robot, out / 'calibration.json')}")
    content = report.content.pixels(robot, data, fit, calib, str(out / "calibration.json"), cameras,
                                    result["warnings"], command="calibrate", lead=report.content.pixel_choice(result),
                                    held_out=val is not None)
    result["files"].update({k: str(out / Path(v).relative_to(build)) for k, v in report.write(content, build).items()})
    if delivered.c_pending:
        build_in_background(delivered.robot, delivered.model, delivered.key, alongside=True)
    return result


#: poses of simulated image points when --poses is not given
PIXEL_POSES = 40
#: rad (m for a prismatic joint): the default half-span of the simulated poses about --home
SPAN = 0.2
#: the rendered images' blur (px), noise (grey levels) and change of light when --images is given without them
IMAGE_DEFAULTS = {"blur_px": 0.7, "image_noise": 2.0, "lighting": 0.2}


def add_simulate_options(p):
    """simulate's options for image points."""
    g = p.add_argument_group("with a camera (docs/reference.md, \"Cameras\"): image points instead of tracker "
                             "points, into a pixel file")
    g.add_argument("--cameras", metavar="FILE", help="camera file: the simulated cameras' intrinsics and mount")
    g.add_argument("--board", metavar="FILE", help="a camera on the tool: the board it sees, fixed in the world")
    g.add_argument("--noise-px", type=number(0, 100), default=None, metavar="PX",
                   help="corner noise per coordinate, px (default 0.2)")
    g.add_argument("--eye", action="append", default=[], metavar="NAME=X,Y,Z",
                   help="fixed cameras: where camera NAME is in the world (m); one per camera (default none: each "
                        "must be given)")
    g.add_argument("--look-at", type=numbers(), metavar="X,Y,Z",
                   help="fixed cameras: the world point (m) they look at (default: the tool origin at --home)")
    g.add_argument("--distance", type=number(0, 100, above=True), default=None,
                   help="a camera on the tool: the board's distance in front of it at --home, m (default 0.7)")
    g.add_argument("--rig-out", metavar="FILE", help="write the true cameras' (and board's) poses, YAML")
    g.add_argument("--images", metavar="FOLDER",
                   help="a camera on the tool: render an image of the board at every pose into FOLDER (PNG; "
                        "--val-out's into FOLDER/held-out) and write -o as the readings file `gecgen import "
                        "--images` takes, instead of a pixel file")
    g.add_argument("--blur-px", type=number(0, 20), default=None, metavar="PX",
                   help=f"--images: the Gaussian blur of the rendered images, px (default "
                        f"{IMAGE_DEFAULTS['blur_px']:g})")
    g.add_argument("--image-noise", type=number(0, 100), default=None, metavar="GREY",
                   help=f"--images: the images' Gaussian noise, grey levels of 255 (default "
                        f"{IMAGE_DEFAULTS['image_noise']:g})")
    g.add_argument("--lighting", type=number(0, 1), default=None,
                   help=f"--images: how much the light changes from image to image, 0 to 1: the brightness scaled by "
                        f"up to this and ramped across the image by up to +-half of it (default "
                        f"{IMAGE_DEFAULTS['lighting']:g})")


def simulated(args, robot, truth, rng) -> dict:
    """The pixel files of `gecgen simulate --cameras` and its JSON result."""
    # numpy here, not at the top: identify's, diagnose's and calibrate's --help build their options
    # from this module and need no numerical library (start-up time)
    import numpy as np
    import yaml

    from gecgen.model.cameras import read_board, read_cameras
    from gecgen.model.files import write_atomically
    from gecgen.model.pixels import write_pixels
    from gecgen.simulate.camera import eye_in_hand, eye_to_hand, simulate_pixels, true_tools

    others = [f"--{k.replace('_', '-')}" for k, v in (("design", args.design != "random"), ("commands", args.commands),
                                                      ("payload_kg", args.payload_kg), ("orientation", args.orientation))
              if v]
    require(not others, f"{others[0] if others else ''} goes with tracker points; with --cameras the poses are "
                        f"drawn about --home (--poses, --span), without a payload")
    cameras = read_cameras(args.cameras)
    tool = next(iter(cameras.values())).mount == "tool"
    require(not tool or args.board, f"{args.cameras}: the camera is on the tool: give the board it sees (--board)")
    require(tool or not args.board, "--board goes with a camera on the tool (mount: tool); these cameras are fixed")
    require(tool or args.distance is None, "--distance goes with a camera on the tool; give --eye for fixed cameras")
    require(tool or not args.images, "--images renders the board a camera on the tool sees; these cameras are fixed "
                                     "(mount: world): leave it out for their pixel file")
    given = [f"--{k.replace('_', '-')}" for k in IMAGE_DEFAULTS if getattr(args, k) is not None]
    require(args.images or not given, f"{given[0] if given else ''} goes with --images (rendered images); drop it, "
                                      f"or add --images FOLDER")
    require(not (args.images and args.noise_px is not None),
            "--noise-px is the noise of simulated corners; with --images the corners are found in the rendered "
            "images (their noise follows --blur-px, --image-noise, --lighting): leave it out")
    require(not tool or (not args.eye and args.look_at is None),
            "--eye and --look-at place fixed cameras; a camera on the tool is placed near the tool (--distance)")
    lo, hi = robot.sampling_box()
    home = np.array(args.home if args.home is not None else [(a + b) / 2 for a, b in zip(lo, hi)], float)
    require(len(home) == robot.n, f"--home: {len(home)} values for {robot.n} joints; give one per joint (rad or m)")
    span = np.array(args.span or [SPAN], float)
    require(len(span) in (1, robot.n), f"--span: {len(span)} values for {robot.n} joints; give one, or one per joint")
    n = args.poses or PIXEL_POSES
    n_val = (args.val_poses or n) if args.val_out else 0
    require(args.val_poses is None or args.val_out, "--val-poses sets the poses of --val-out; give both, or neither")
    if tool:
        board = read_board(args.board)
    else:
        eyes = {}
        for text in args.eye:
            name, _, xyz = text.partition("=")
            require(name in cameras, f"--eye {text}: no camera {name!r} in {args.cameras} (cameras: "
                                     f"{', '.join(cameras)})")
            eyes[name] = numbers()(xyz) if xyz else []
            require(len(eyes[name]) == 3, f"--eye {text}: give NAME=X,Y,Z (m)")
        missing = [c for c in cameras if c not in eyes]
        require(not missing, f"--eye: camera {missing[0] if missing else ''} has no place; give "
                             f"--eye {missing[0] if missing else ''}=X,Y,Z (m) for every camera of {args.cameras}")
        cameras_at = np.array([eyes[c] for c in cameras])
        at = (np.array(args.look_at, float) if args.look_at is not None
              else true_tools(robot, truth, home[None])[0, :3, 3])
        require(len(at) == 3, "--look-at: give X,Y,Z (m)")
    try:
        if tool:
            rig, q = eye_in_hand(robot, truth, next(iter(cameras.values())), board, home, span, n + n_val, rng,
                                 0.7 if args.distance is None else args.distance)
        else:
            rig, q = eye_to_hand(robot, truth, list(cameras.values()), cameras_at, at, home, span, n + n_val, rng)
    except ModelError:
        raise
    except ValueError as exc:  # the simulator's: too few poses keep every point in view
        raise ModelError(f"{args.cameras}: {exc} (--span, --home, --eye, --look-at or --distance)") from None
    if args.images:
        files = {"readings": args.output, "images": args.images}
        rendered = _rendered(args, robot, truth, rig, q[:n], args.output, Path(args.images), rng)
        if args.val_out:
            files |= {"val": args.val_out, "val_images": str(Path(args.images) / "held-out")}
            _rendered(args, robot, truth, rig, q[n:], args.val_out, Path(args.images) / "held-out", rng)
    else:
        noise = 0.2 if args.noise_px is None else args.noise_px
        data = simulate_pixels(robot, truth, rig, q[:n], noise, rng)
        write_pixels(args.output, robot, data)
        files = {"data": args.output}
        if args.val_out:
            write_pixels(args.val_out, robot, simulate_pixels(robot, truth, rig, q[n:], noise, rng))
            files["val"] = args.val_out
    if args.truth_out:
        write_atomically(args.truth_out, yaml.safe_dump(truth.spec, sort_keys=False))
        files["truth"] = args.truth_out
    rig_spec = {"cameras": {c: {"rotation": R.tolist(), "translation": t.tolist()} for c, (R, t) in rig.poses.items()},
                **({"board": {"rotation": rig.board_pose[0].tolist(), "translation": rig.board_pose[1].tolist()}}
                   if tool else {})}
    if args.rig_out:
        write_atomically(args.rig_out, yaml.safe_dump(rig_spec, sort_keys=False))
        files["rig"] = args.rig_out
    made = ({"images": rendered, **{k: getattr(args, k) if getattr(args, k) is not None else v
                                    for k, v in IMAGE_DEFAULTS.items()}} if args.images else
            {"rows": len(data.uv), "noise_px": noise})
    return {"robot": robot.name, "design": "cameras", "mount": "tool" if tool else "world",
            "poses": rendered if args.images else data.n_poses, **made, **rig_spec, "files": files}


def _rendered(args, robot: Robot, truth, rig, q: np.ndarray, readings: str, folder: Path, rng) -> int:
    """Render the board at the joint readings q (N, n) into `folder` (img000.png, ...) and write their
    readings file (image, q1..qn); the number of images. The images are written as they are rendered,
    the readings file last: a readings file names only images that exist."""
    from gecgen.cli.common import progress_status, say
    from gecgen.model.files import write_atomically
    from gecgen.model.images import _cv2
    from gecgen.simulate.camera import render_images

    cv2 = _cv2()  # one line, not a traceback, without OpenCV
    options = {k: getattr(args, k) if getattr(args, k) is not None else v for k, v in IMAGE_DEFAULTS.items()}
    folder.mkdir(parents=True, exist_ok=True)
    names = [f"img{k:03d}.png" for k in range(len(q))]
    images = render_images(robot, truth, rig, q, rng, options["blur_px"], options["image_noise"], options["lighting"])
    with progress_status(not args.json) as status:
        for k, (name, image) in enumerate(zip(names, images)):
            say(status, f"rendering image {k + 1} of {len(q)} into {folder}")
            write_atomically(folder / name, cv2.imencode(".png", image)[1].tobytes())
    header = ",".join(["image", *(f"q{i + 1}" for i in range(robot.n))])
    write_atomically(readings, "\n".join([header, *(",".join([name, *map(repr, row.tolist())])
                                                    for name, row in zip(names, q))]) + "\n")
    return len(q)


def compensate_next(robot: Robot, calibration) -> str:
    """The compensate command(s) a next step names: on a tree one per branch, which compensate needs."""
    return ", ".join(f"gecgen compensate {calibration} POSES.csv -o OUT.csv" + (f" --branch {b.name}" if b else "")
                     for b in robot.branches or [None])
