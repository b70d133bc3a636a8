"""A result's verdict and next step, in words a person acts on: against a tolerance when one is
given (meets, does not meet, cannot tell), otherwise against the instrument noise and the held-out
interval; what limits the result (noise, undetermined coefficients, extrapolation, a model that
leaves more than the noise) and the command to run next.

Built from figures the command already computed (its JSON), never by a new fit. Lengths in mm.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

#: verdict words against a tolerance
MEETS, DOES_NOT_MEET, CANNOT_TELL = "meets", "does not meet", "cannot tell"
#: verdict words without a tolerance
AT_NOISE, BEYOND_NOISE, NOISE_UNKNOWN = "at the noise", "beyond the noise", "noise not known"
#: the verdict against a tolerance as the start of a sentence
PHRASE = {MEETS: "It meets", DOES_NOT_MEET: "It does not meet", CANNOT_TELL: "These poses cannot tell whether it meets"}
#: an interval wider than this share of its RMS is too few poses to say much
WIDE_INTERVAL = 0.25
#: a residual below this share of the stated noise says the noise stated is too large: at the degrees of
#: freedom of any calibration, a true 1 sigma leaves a residual this low with vanishing probability
FAR_BELOW = 0.5


@dataclass(frozen=True)
class Commands:
    """The commands a next step names, filled in with the run's own files: `diagnose` (find what the
    model misses), `more_poses` (design poses to add to the training data), `score` (score the
    calibration on held-out poses), `export` (put it into the controller), `noise` (the option that
    states the instrument's noise, on the command that was run)."""

    diagnose: str
    more_poses: str
    score: str
    export: str
    noise: str = "--noise-mm S"


@dataclass(frozen=True)
class Noise:
    """The fit's residual against the instrument noise (mm per coordinate): `beyond` whether the
    model leaves more than the noise; `source` where the noise figure comes from."""

    sigma_mm: float
    noise_mm: float
    beyond: bool
    source: str

    @classmethod
    def of_significance(cls, significance: dict | None) -> "Noise | None":
        """From a fit's `significance` (its `overall`, present when the noise was stated)."""
        o = (significance or {}).get("overall")
        return None if o is None else cls(o["sigma_mm"], o["noise_mm"], bool(o["beyond_noise"]), "stated (--noise-mm)")

    @classmethod
    def of_remaining(cls, remaining: dict) -> "Noise | None":
        """From diagnose's `remaining` (the noise stated or pooled over repeated poses)."""
        if remaining.get("covered") is None:
            return None
        return cls(remaining["sigma_mm"], remaining["noise"]["noise_mm"], not remaining["covered"],
                   remaining["noise"]["source"])


@dataclass(frozen=True)
class Assessment:
    """verdict: one of MEETS, DOES_NOT_MEET, CANNOT_TELL (with a tolerance) or AT_NOISE,
    BEYOND_NOISE, NOISE_UNKNOWN (without); statement: the figures it rests on; limits: what limits
    the result, most important first; next_step: what to do, with the command."""

    verdict: str
    statement: str
    limits: list[str]
    next_step: str
    tolerance_mm: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def _overstated(sigma: float, noise: float, unit: str) -> tuple[str, str]:
    """The limit and the step when a fit's residual (sigma per coordinate) is far below the noise stated."""
    return (f"The fit's residual ({sigma:.3g} {unit} per coordinate) is less than half the noise stated ({noise:.3g} "
            f"{unit}): that figure is larger than this set-up's 1 sigma (a maker's bound over its whole range?), "
            f"and judged against it the model could miss effects nearly that large unseen.",
            "state this set-up's own 1 sigma, or measure a few poses twice so that the noise is pooled from the data, "
            "and run again")


def _interval(score: dict) -> tuple[float, float] | None:
    ci = score.get("rms_mm_ci95")
    return (float(ci[0]), float(ci[1])) if ci else None


def _figure(score: dict, relative: bool) -> str:
    """The score in words fitting the instrument: point errors from a tracker; with sockets and
    planes, each seating's distance from its socket's (or touch from its plane's) fitted place, and
    the known distances' error."""
    ci = _interval(score)
    ci = f" (95 % interval by pose {ci[0]:.3g} to {ci[1]:.3g} mm)" if ci else ""
    if not relative:
        return f"RMS point error {score['rms_mm']:.3g} mm{ci}, largest {score['max_mm']:.3g} mm"
    parts = [f"consistency {score['rms_mm']:.3g} mm RMS{ci}, largest {score['max_mm']:.3g} mm: each seating's "
             f"distance from its socket's fitted place, or a touch's from its plane"]
    if score.get("distance_error_mm") is not None:
        parts.append(f"known distances off by {abs(score['distance_error_mm']):.3g} mm at most")
    return ", ".join(parts)


def assess(*, after: dict, before: dict | None, held_out: bool, n_poses: int | None, tolerance_mm: float | None,
           noise: Noise | None, held: tuple[int, int] | None, n_train_poses: int | None, extrapolation: dict,
           inside: dict | None, relative: bool, commands: Commands, before_name: str = "uncalibrated",
           weak: list[dict] | None = None) -> Assessment:
    """The verdict on a score `after` ({rms_mm, max_mm[, rms_mm_ci95, consistency_mm, distance_error_mm]},
    `identify.summary` as the JSON has it) of n_poses poses (None: not known), `held_out` (data the
    fit never saw) or the training data; `before` that of the model named before_name on the same
    data. noise: the fit's residual against the instrument's; held: (coefficients held at zero as not determined, identifiable ones)
    of a fit on n_train_poses poses; extrapolation: poses outside the training range per input
    ({name: poses}); inside: the score of the poses inside every range; relative: socket or plane
    data (no absolute position measured); weak: the coefficients held as weakly determined (the
    fit's `held`, each with its reason: why the data leave it, and the fix in parentheses)."""
    what = "held-out" if held_out else "training"
    statement = f"On {'the' if n_poses is None else n_poses} {what} poses: {_figure(after, relative)}"
    if before is not None:
        statement += f"; {before_name} {before['rms_mm']:.3g} mm"
    statement += "."
    if relative:
        statement += (" Sockets and planes measure the arm's shape, not where it stands: the base placement is not "
                      "seen, and these figures are not distances from a tracker's points.")
    limits, steps = [], []
    if not held_out:
        limits.append("No held-out data: a training residual is not a prediction of the error at new poses.")
        steps.append(f"score the calibration on poses it was not fitted on: `{commands.score}`")
    if noise is not None and noise.beyond:
        limits.append(f"The model leaves more than the noise: the fit's residual is {noise.sigma_mm:.3g} mm per "
                      f"coordinate against {noise.noise_mm:.3g} mm of instrument noise ({noise.source}).")
        steps.append(f"find what the model misses: `{commands.diagnose}`")
    if held and held[0]:
        train = f" by the {n_train_poses} training poses" if n_train_poses else ""
        limits.append(f"{held[0]} of {held[1]} identifiable coefficients are not determined{train} and are held at "
                      "zero: the poses do not excite them.")
        steps.append(f"measure more poses where they are excited (designed to add to the training data): "
                     f"`{commands.more_poses}`, then calibrate again on both")
    for limit, fix in weak_limits(weak):
        limits.append(limit)
        if fix:  # the data's own cause comes before the general advice to measure more
            steps.insert(min(len(steps), 0 if held_out else 1), fix)
    if extrapolation:
        worst = max(extrapolation.values())
        if len(extrapolation) == 1:  # one input: the count is exact
            name = next(iter(extrapolation))
            out, rest = f"{worst} of the {n_poses} poses lie outside {name}'s training range", n_poses - worst
            rest = f"; the {rest} inside" if rest else ""
        else:
            names = ", ".join(f"{name} {k}" for name, k in extrapolation.items())
            out = f"at least {worst} of the {n_poses} poses lie outside a training range (per input: {names})"
            rest = "; the poses inside every range"
        rest = f"{rest}: {inside['rms_mm']:.3g} mm RMS" if inside else ""
        limits.append(f"Extrapolation: {out}{rest}. The calibration is not validated there.")
        steps.append("measure training poses over the whole range the robot works in (the design command above "
                     "spreads them to the joint limits), or keep the robot inside the training ranges")
    if noise is None:
        limits.append("The instrument noise is not known, so whether the model explains the robot cannot be decided.")
        steps.append(f"state the instrument's noise per coordinate ({commands.noise}) and run again")
    elif noise.sigma_mm < FAR_BELOW * noise.noise_mm:
        limit, step = _overstated(noise.sigma_mm, noise.noise_mm, "mm")
        limits.append(limit)
        steps.append(step)
    elif not noise.beyond:
        limits.append(f"The fit's residual ({noise.sigma_mm:.3g} mm per coordinate) is the instrument's noise "
                      f"({noise.noise_mm:.3g} mm, {noise.source}): a larger model will not lower it; a better "
                      "instrument, or averaging repeated measurements, would.")
    ci = _interval(after)
    if held_out and ci and ci[1] - ci[0] > WIDE_INTERVAL * after["rms_mm"]:
        limits.append(f"{n_poses or 'Too few'} held-out poses give a wide interval ({ci[0]:.3g} to {ci[1]:.3g} "
                      "mm): more held-out poses narrow it.")

    if tolerance_mm is None:
        verdict = NOISE_UNKNOWN if noise is None else BEYOND_NOISE if noise.beyond else AT_NOISE
    elif not held_out:
        verdict = CANNOT_TELL
        statement += f" Against the tolerance of {tolerance_mm:.3g} mm this cannot tell: it is training data."
    else:
        lo, hi = ci or (after["rms_mm"], after["rms_mm"])
        if lo > tolerance_mm:
            verdict = DOES_NOT_MEET
            why = f"even the low end of the RMS interval, {lo:.3g} mm, is above the tolerance of {tolerance_mm:.3g} mm"
        elif hi <= tolerance_mm and after["max_mm"] <= tolerance_mm:
            verdict = MEETS
            why = (f"every held-out point is within the tolerance of {tolerance_mm:.3g} mm, and so is the high end of "
                   f"the RMS interval, {hi:.3g} mm")
        else:
            verdict = CANNOT_TELL
            why = (f"the RMS's 95 % interval, {lo:.3g} to {hi:.3g} mm, spans the tolerance of {tolerance_mm:.3g} mm"
                   if hi > tolerance_mm else
                   f"the RMS's 95 % interval, {lo:.3g} to {hi:.3g} mm, is within the tolerance of {tolerance_mm:.3g} "
                   f"mm, but the largest held-out point error, {after['max_mm']:.3g} mm, is beyond it (the robot or "
                   f"the measurement: check that pose, or measure it again)")
            steps.insert(0, "measure more held-out poses inside the working volume and score them: "
                            f"`{commands.score}`")
        statement += f" {PHRASE[verdict]} the tolerance: {why}."
        if verdict == DOES_NOT_MEET and noise is not None and not noise.beyond and not steps:
            steps.append("the model is at the instrument's noise: no calibration of this data can meet the tolerance; "
                         "measure with a better instrument")
    export = (f"put it into the controller, `{commands.export}`, and verify on poses it never saw "
              "(docs/guide.md, \"Verify on the robot\")")
    if verdict == MEETS:
        steps.insert(0, export)
    elif not steps:
        steps.append(export)
    text = "; then ".join(steps[:2])
    return Assessment(verdict, statement, limits, text[0].upper() + text[1:] + ".", tolerance_mm)


def accuracy_next_step(result: dict, calibration: str, volume: str, data: str, options: str = "") -> Assessment:
    """The accuracy statement's verdict (`gecgen accuracy`'s result, as it is: meets, does not
    meet, cannot tell or no tolerance given), what limits it (its reasons) and the next step, with
    this run's files and the options it was given that the statement rests on (`options`, e.g.
    " --noise-mm 0.04"), which the command it names keeps."""
    from gecgen.verify.volume import COMPENSATED_OUTSIDE, OUTSIDE_TRAINING  # the other reports load none of it

    verdict, tol = result["verdict"], result["tolerance_mm"]
    statement = (f"The worst compensated error over the volume is at most {result['bound_mm']:.3g} mm with "
                 f"{result['confidence']:.0%} confidence, largest at the worst sample "
                 f"({result['worst_at']['bound_mm']:.3g} mm); " + ("no tolerance was given." if tol is None else f"the tolerance is {tol:.3g} mm."))
    again = f"gecgen accuracy {calibration} {volume} {data}{options}"
    outside = any(r.startswith((OUTSIDE_TRAINING, COMPENSATED_OUTSIDE)) for r in result["reasons"])
    if result["noise_mm"] is None and result.get("measurement") != "pixels":  # triangulated points' noise is kept
        step = (f"state the tracker's noise and the robot's repeatability, without which the noise counts as model "
                f"error: `{again} --noise-mm S --repeatability-mm R`")
    elif outside and verdict != DOES_NOT_MEET:
        step = ("measure training poses that move the inputs named under \"Why, and what it assumes\" over the "
                "spans given there, calibrate again with them, and state it again on the new calibration: "
                f"`gecgen accuracy NEW_CALIB.json {volume} NEW_DATA.csv{options}"
                f"{'' if tol is None else f' --tolerance-mm {tol:g}'}`")
    elif verdict == MEETS and not result["held_out"]:
        step = (f"sign it with held-out poses measured inside the volume, at its extremes: `{again} --val VAL.csv "
                f"--tolerance-mm {tol:g}`")
    elif verdict == MEETS:
        step = f"put the calibration into the controller: `gecgen export {calibration} --c CONTROLLER_DIR`"
    elif tol is None:
        step = f"state the accuracy the robot must reach: `{again} --tolerance-mm T`"
    elif verdict == DOES_NOT_MEET:
        step = ("measure poses where the bound is largest (the joints named under \"Where it is worst\") and "
                "calibrate again with them, or run `gecgen diagnose` on the training data to find what the model "
                "misses")
    else:
        step = (f"narrow the bound: measure held-out poses inside the volume, at its extremes, and give them: "
                f"`{again} --val VAL.csv --tolerance-mm {tol:g}`")
    return Assessment(verdict, statement, list(result["reasons"]), step[0].upper() + step[1:] + ".", tol)


def iso9283_next_step(result: dict, tolerance_mm: float | None, robot: str) -> Assessment:
    """The ISO 9283 pose test's verdict from `gecgen iso9283 --measured`'s result (the compensated
    run's, when there is one): against a tolerance on the position a pose is brought to, MEETS when
    at every point the pose accuracy plus the repeatability, AP_p + RP_l (the farthest a cycle's
    position lies from the commanded one, by the standard's 3 S), is within it; DOES_NOT_MEET when
    the pose accuracy AP_p alone (the mean position's distance) is beyond it at some point; else
    CANNOT_TELL. Without a tolerance, "no tolerance given"."""
    run, stage = (result["after"], "compensated") if "after" in result else (result, "as commanded")
    points = [v for t in run["points"].values() for v in t.values()]
    reach = max(v["AP_p"] + v["RP_l"] for v in points)
    worst = run["worst"]
    statement = (f"{stage.capitalize()}: pose accuracy AP_p {worst['AP_p']:.3g} mm and repeatability RP_l "
                 f"{worst['RP_l']:.3g} mm at worst over the points; a cycle's position lies at most {reach:.3g} mm "
                 f"from the commanded one (AP_p + RP_l).")
    if "after" in result:
        statement += f" Before compensation AP_p was {result['worst']['AP_p']:.3g} mm."
    limits = [] if "after" in result else ["Only the run as commanded was measured: what compensation gives is not "
                                           "known."]
    if worst["RP_l"] >= worst["AP_p"]:
        limits.append("The repeatability is as large as the accuracy: no calibration can bring the robot closer than "
                      "it repeats.")
    if tolerance_mm is None:
        verdict = "no tolerance given"
    elif max(v["AP_p"] for v in points) > tolerance_mm:
        verdict = DOES_NOT_MEET
    elif reach <= tolerance_mm:
        verdict = MEETS
    else:
        verdict = CANNOT_TELL
        limits.append(f"The tolerance {tolerance_mm:.3g} mm lies between the mean positions' distance and the "
                      "farthest cycle's: the repeatability decides it.")
    if "after" not in result:
        step = (f"compensate the plan (`gecgen compensate CALIB {result['plan']} -o compensated.csv`), run and measure "
                f"it, and give it: `gecgen iso9283 {robot} --plan {result['plan']} --measured {result['measured']} "
                f"--after RUN2.csv`")
    elif verdict == DOES_NOT_MEET:
        step = ("calibrate again with poses around the test's cube (`gecgen design` with `--given` the training data), "
                "then repeat the test")
    elif tolerance_mm is None:
        step = "state the tolerance the robot must reach: `--tolerance-mm T`"
    else:
        step = "sign the test's figures; repeat it after any change to the robot (`gecgen check` for a short one)"
    return Assessment(verdict, statement, limits, step[0].upper() + step[1:] + ".", tolerance_mm)


def weak_limits(weak: list[dict] | None) -> list[tuple[str, str]]:
    """What the coefficients held as weakly determined (a fit's `held`, each with its reason: why the data
    leave it, and the fix in parentheses) say of a calibration: per fix, the limit in words and the fix
    ("" when none is said). A direction known only to some times a plausible size says its own times, so
    those coefficients are said together, with the range of them."""
    by_fix: dict[str, list[dict]] = {}
    for h in weak or ():
        by_fix.setdefault(h["reason"].partition("; held at zero")[2].strip(" ()"), []).append(h)
    out = []
    for fix, hs in by_fix.items():
        causes = {h["reason"].partition("; held at zero")[0] for h in hs}
        beyond = [h["beyond_plausible"] for h in hs if h.get("beyond_plausible") is not None]
        cause = causes.pop() if len(causes) == 1 else (
            f"their directions are known only to {min(beyond):.3g} to {max(beyond):.3g} times a plausible size"
            if beyond else "; ".join(sorted(causes)))
        n = len(hs)
        out.append((f"{n} coefficient{'s are' if n > 1 else ' is'} held at zero as the data determine "
                    f"{'them' if n > 1 else 'it'} too weakly: {cause}.", fix))
    return out


def pixels_next_step(result: dict, noise: dict | None, coverage: dict[str, tuple[int, int]],
                     evaluate: str) -> Assessment:
    """The verdict on a calibration from image points (`gecgen identify --cameras`'s result): its
    training reprojection residual against the corners' noise when it was stated (`noise`:
    `fit.significance.overall` of the residual per coordinate against `--noise-px`, in px), what
    limits it (no held-out images, coefficients the images leave undetermined, the model beyond the
    noise, images the points cover in part: coverage, per camera (cells holding a point, cells)) and
    the next step; evaluate: the command that scores held-out images."""
    train, before = result["train"], result["before"]
    statement = (f"On the training images: reprojection residual {train['rms_px']:.3g} px RMS, largest "
                 f"{train['max_px']:.3g} px ({train['rms_mm_at_target']:.3g} mm RMS across the rays at "
                 f"{train['distance_m']:.3g} m); the nominal model {before['rms_px']:.3g} px.")
    limits = ["No held-out images: a training residual is not a prediction of the error at new poses."]
    steps = [f"score the calibration on images it was not fitted on: `{evaluate}`"]
    if noise is None:
        verdict = NOISE_UNKNOWN
        limits.append("The corners' noise was not stated (`--noise-px`), so whether the model explains the images "
                      "cannot be decided.")
    elif noise["beyond_noise"]:
        verdict = BEYOND_NOISE
        limits.append(f"The model leaves more than the noise: the residual is {noise['sigma_mm']:.3g} px per "
                      f"coordinate against the stated {noise['noise_mm']:.3g} px.")
        steps.append("fit a larger error model (`--errors`)" if result.get("intrinsics") else
                     "refine the cameras' intrinsics with the robot (`--refine-intrinsics`) or fit a larger error "
                     "model (`--errors`)")
    else:
        verdict = AT_NOISE
        if noise["sigma_mm"] < FAR_BELOW * noise["noise_mm"]:
            limit, step = _overstated(noise["sigma_mm"], noise["noise_mm"], "px")
            limits.append(limit)
            steps.append(step)
    weak = [e["param"] for e in result["eliminated"] if e["reason"] in ("insignificant", "held")]
    if weak:
        kept = result["n_identifiable"]
        limits.append(f"The images determine {kept} of the {kept + len(weak)} coefficients the model can have; "
                      f"{len(weak)} {'is' if len(weak) == 1 else 'are'} held at zero, too weakly determined "
                      f"(\"Eliminated parameters\" says why).")
        # those held as weakly determined, by cause, as for a tracker; the fixes are the images' own
        limits += [limit for limit, _ in weak_limits(result.get("held"))]
        steps.append("record more images at poses that turn the joints those coefficients name, and identify again")
    for name, (cells, total) in coverage.items():
        if cells < total:
            limits.append(f"Camera `{name}`: points fall in {cells} of {total} cells of its image: the lens is "
                          f"checked only there.")
            steps.append(f"record images with the points near the corners of camera `{name}`'s image")
    text = "; then ".join(steps[:2])
    return Assessment(verdict, statement, limits, text[0].upper() + text[1:] + ".")


def pixel_check_next_step(result: dict, rig: str) -> str:
    """What to do after `gecgen check --cameras` (its result: looks_like, rms_px, reference_sigma_px,
    poses_refitted, judged_against), in one sentence; rig: its --cameras (and --board) options."""
    looks = result["looks_like"]
    kind = looks["kind"]
    if kind == "as calibrated":
        return (f"the images are within the calibration's noise ({result['rms_px']:.3g} px rms against its "
                f"{result['reference_sigma_px']:.3g} px per coordinate): nothing to do")
    if kind in ("camera moved", "board moved"):
        what = ", ".join(looks["moved"])
        return (f"{what} moved ({'; '.join(_moves(result, looks['moved']))}) and the robot is as calibrated at these "
                f"poses: put it back, or identify again with images taken where it is now "
                f"(gecgen identify ROBOT TRAIN.csv {rig})")
    if kind == "moved or joint":
        j = looks["joint"]
        return (f"{looks['why']}: check that {', '.join(looks['moved'])} stayed where it was (a mark, a second "
                f"camera) before recalibrating; if it did, {j['joint']} ({j['name']}) is off by {j['offset']:.3g} "
                f"{j['unit']}: recalibrate (gecgen identify ROBOT TRAIN.csv {rig})")
    if kind == "joint":
        return (f"the robot changed: a reading offset of {looks['joint']} ({looks['name']}) of {looks['offset']:.3g} "
                f"{looks['unit']} explains {looks['explained']:.0%} of it; recalibrate (gecgen identify ROBOT "
                f"TRAIN.csv {rig}) or look at that joint's zero")
    if result["judged_against"].startswith("the calibration's training residual"):
        return ("the images differ from the calibration beyond its training residual, and no moved camera nor a "
                "single joint's offset explains it: new poses exceed that residual by the model's own misfit too; "
                f"check again against images held out from the calibration (--val HELD_OUT.csv) before recalibrating")
    return ("the images differ from the calibration beyond its noise, and no moved camera nor a single joint's "
            f"offset explains it: recalibrate (gecgen identify ROBOT TRAIN.csv {rig}) and look at what changed")


def _moves(result: dict, names: list[str]) -> list[str]:
    return [f"{p['name']} {p['rotation_deg']:.3g} deg, {p['translation_mm']:.3g} mm" for p in result["poses_refitted"]
            if p["name"] in names]
