"""Reports people read: each command's report.html is one self-contained page with the sections a
person needs, axes named after the robot's joints; rendered in a real browser when chromium is there."""
import base64
import contextlib
import io
import json
import re
import shutil
import subprocess

import numpy as np
import pytest
from conftest import ROBOTS

from gecgen.cli import main

ROBOT = ROBOTS / "industrial6r.yaml"
ERRORS = ROBOTS / "constant.errors.yaml"
#: sections every report has, and those of one command only
COMMON = ("Verdict and next step", "Warnings", "Summary", "What was measured", "Distribution of point errors",
          "Residuals against each joint", "Coefficients", "Glossary", "Extrapolation")
ONLY = {"identify": (), "evaluate": (), "diagnose": ("What diagnose found", "Rounds"),
        "calibrate": ("Model choice", "Files")}
BROWSER = shutil.which("chromium")


def gecgen(*args) -> dict:
    """A command's JSON result, with the warning lines it printed on the terminal under TERMINAL."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main([*map(str, args), "--json"]) == 0
    said = f"gecgen {args[0]}: warning: "
    return {**json.loads(out.getvalue()),
            TERMINAL: [line[len(said):] for line in err.getvalue().splitlines() if line.startswith(said)]}


#: where `gecgen` keeps the warnings a command printed
TERMINAL = "terminal warnings"


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """{command: its JSON result}, each with --report, on 40 simulated industrial6r poses (30 to train)."""
    d = tmp_path_factory.mktemp("report")
    gecgen("simulate", ROBOT, "--poses", 40, "--seed", 3, "-o", d / "all.csv")
    rows = np.loadtxt(d / "all.csv", delimiter=",", skiprows=1, usecols=0)
    text = (d / "all.csv").read_text().splitlines()
    for name, keep in (("train", rows < 30), ("val", rows >= 30)):
        (d / f"{name}.csv").write_text("\n".join([text[0], *(t for t, k in zip(text[1:], keep) if k)]) + "\n")
    out = {"identify": gecgen("identify", ROBOT, d / "train.csv", "--errors", ERRORS, "-o", d / "cal.json",
                              "--report", d / "identify")}
    out["evaluate"] = gecgen("evaluate", d / "cal.json", d / "val.csv", "--report", d / "evaluate")
    out["diagnose"] = gecgen("diagnose", ROBOT, d / "train.csv", "--val", d / "val.csv", "--errors", ERRORS,
                             "--max-rounds", 1, "-o", d / "diag.errors.yaml", "--report", d / "diagnose")
    out["calibrate"] = gecgen("calibrate", ROBOT, d / "train.csv", "--val", d / "val.csv", "--errors", ERRORS,
                              "--models", "geometric", "-o", d / "calibrate")
    return out


def html_of(result: dict) -> str:
    return open(result.get("report_html") or result["files"]["report_html"]).read()


@pytest.mark.parametrize("command", list(ONLY))
def test_report_is_self_contained_with_its_sections(reports, command):
    html = html_of(reports[command])
    sources = re.findall(r'(?:src|href)="([^"#][^"]*)"', html)
    assert sources and all(s.startswith("data:image/png;base64,") for s in sources), sources[:3]
    assert "http" not in html.replace("http-equiv", "")
    for title in (*COMMON, *ONLY[command]):
        assert f"<h2>{title}</h2>" in html, title
    # every embedded figure is a PNG, and the Markdown report beside it names the same sections
    assert all(base64.b64decode(s.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n" for s in sources)
    md = open((reports[command].get("report") or reports[command]["files"]["report"])).read()
    assert all(f"## {title}" in md for title in (*COMMON, *ONLY[command]))


@pytest.mark.parametrize("command, before, after", [("identify", "before", "train"), ("evaluate", "before", "after"),
                                                     ("calibrate", "before", "train")])
def test_report_numbers_are_the_commands(reports, command, before, after):
    """The headline table holds the numbers the command printed (computed there by the fit or
    `row_errors`; the report recomputes them from signed residuals)."""
    res = reports[command]
    for stage, key in (("uncalibrated", before), ("calibrated", after)):
        cells = re.search(rf"<td>{stage}</td>(.*?)</tr>", html_of(res)).group(1)
        assert f"{res[key]['rms_mm']:.3g}" in cells and f"{res[key]['max_mm']:.3g}" in cells, (stage, cells)
        if command == "evaluate":  # held-out data: the RMS with its interval by pose, as the command gives it
            lo, hi = res[key]["rms_mm_ci95"]
            assert f"{lo:.3g} to {hi:.3g}" in cells, (stage, cells)


@pytest.mark.parametrize("command", list(ONLY))
def test_residual_axes_name_the_joints_with_units(reports, command):
    """Every residual figure labels its axes with each joint's name and unit and the residual's
    axis and unit (the page's alt text lists the labels matplotlib drew)."""
    alts = re.findall(r'<img alt="Signed residuals[^"]*"', html_of(reports[command]))
    assert len(alts) >= 2  # before and after, on each data set
    for alt in alts:
        assert all(f"q{k} a{k} (deg)" in alt for k in range(1, 7)), alt
        assert all(f"{a} residual (mm)" in alt for a in "xyz"), alt


def test_glossary_and_coefficients_name_frames_and_units(reports):
    md = open(reports["identify"]["report"]).read()
    assert "`ex`, `ey`, `ez`: translations along the frame's x, y, z (reported in mm)" in md
    assert "frame 0: the base" in md and "frame 2: after joint 2, `a2` (revolute)" in md
    # constant errors: translations in mm, rotations in mrad, each with its std and t
    number = r"-?[0-9.]+(e[+-][0-9]+)?"
    assert re.search(rf"\| 2 after a2 \| ex \| `1` \| {number} \| {number} \| [0-9.]+ \| mm \|", md)
    assert re.search(rf"\| [0-9] [^|]+ \| e[spr] \| `1` \| {number} \| {number} \| [0-9.]+ \| mrad \|", md)
    assert re.search(r"\| `[0-9]\.e[xyzspr]:1` \| insignificant \| t = [0-9.]+ < 2: the data do not determine it", md)
    assert "## Eliminated parameters" in md and "structural" in md


@pytest.mark.skipif(BROWSER is None, reason="chromium is not installed (apt-get install chromium)")
@pytest.mark.parametrize("command", list(ONLY))
def test_report_renders_in_a_browser(reports, command, tmp_path):
    from PIL import Image

    html = reports[command].get("report_html") or reports[command]["files"]["report_html"]
    png = tmp_path / f"{command}.png"
    subprocess.run([BROWSER, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={png}", "--window-size=1200,3000",
                    f"file://{html}"], capture_output=True, timeout=120, check=True)
    pixels = np.asarray(Image.open(png).convert("L"), float)
    assert pixels.shape == (3000, 1200)
    # not blank: text and plots make dark pixels in every third of the page's height
    assert all((band < 128).mean() > 0.005 for band in np.array_split(pixels, 3))


def test_an_effect_shows_its_coefficients_as_finally_fitted(reports):
    """The effect table holds the final fit's values (as the coefficient table does), with std and t."""
    md = open(reports["diagnose"]["report"]).read()
    effect = md[md.index("## Effect 1"):]
    effect = effect[:effect.index("\n## ")]
    assert "value as finally fitted" in effect and "| t |" in effect
    name, value = re.search(r"\| `([^`]+)` \| (-?[0-9.e+-]+) \|", effect).groups()
    frame, rest = name.split(".", 1)
    error, term = rest.split(":", 1)
    row = re.search(rf"\| {frame} [^|]* \| {error} \| `{re.escape(term)}` \| (-?[0-9.e+-]+) \|", md)
    assert row and row.group(1) == value, (name, value)


def test_what_was_measured_counts_the_data_and_scores_each_target(reports):
    """The measurement context: 30 training poses of the one SMR, one stationing, no load, each
    joint's measured span against its limits; the per-target errors are the summary's (one target)."""
    md = open(reports["identify"]["report"]).read()
    section = md[md.index("## What was measured"):md.index("## Distribution")]
    assert "30 poses, 30 measured rows: target `smr` 30" in section and "1 tracker stationing" in section
    # no force column: no load cases in force steps, which would claim a force was measured
    assert "no force measured" in section and "load case" not in section and "positions only" in section
    assert len(re.findall(r"\| q[1-6] [^|]+ \| -?[0-9.]+ to -?[0-9.]+ deg \| .* \| [0-9]+ % \|", section)) == 6
    train = reports["identify"]["train"]
    assert f"| target `smr` | {reports['identify']['before']['rms_mm']:.3g} / " in section
    assert f" / {train['max_mm']:.3g} |" in section
    assert "poses_training.png" in section


def test_the_residual_grid_names_each_joint_under_its_panel_at_its_scale(monkeypatch):
    """A row of the residual grid is one Axes holding a panel per joint: each panel's ticks are its
    joint's values where they fall on it, and its joint's name stands under it, also when the panel's
    centre is one of its ticks (a span symmetric about 0, which matplotlib would drop as a minor tick)."""
    import gecgen.report.plots as plots
    from gecgen.model import load_robot
    from gecgen.model.measurements import Measurements
    from gecgen.report.blocks import DataSet, Residuals, joint_label

    robot = load_robot(ROBOTS / "puma560.yaml")
    P = 20
    q = np.tile(np.linspace(-1.0, 1.0, P)[:, None], (1, robot.n)) * np.arange(1, robot.n + 1) / robot.n
    data = Measurements(q, np.zeros((P, 6)), np.zeros((P, 0)), (), np.arange(P), np.arange(P), np.zeros(P, int),
                        np.zeros((P, 3)))
    stage = Residuals("calibrated", np.arange(P), np.random.default_rng(0).normal(size=(P, 3)), None)
    drawn = {}

    def keep(fig, *args):
        fig.canvas.draw()
        bottom = fig.axes[-1]
        drawn["joints"] = [t.get_text() for t in bottom.xaxis.get_ticklabels(minor=True) if t.get_text()]
        drawn["ticks"] = [(tick.get_loc(), tick.label1.get_text()) for tick in bottom.xaxis.get_major_ticks()
                          if tick.label1.get_text()]
        return real(fig, *args)

    real = plots._figure
    monkeypatch.setattr(plots, "_figure", keep)
    figure = plots.residuals_per_joint(robot, DataSet("training", data, [stage]), stage)
    assert drawn["joints"] == [joint_label(robot, k) for k in range(robot.n)]
    assert all(name in figure.axes for name in drawn["joints"]) and "x residual (mm)" in figure.axes
    # panel j spans [j (1 + GAP), j (1 + GAP) + 1]: a tick's place there gives back its joint value
    for loc, text in drawn["ticks"]:
        j = int(loc // (1 + plots.GAP))
        degrees = np.degrees(q[:, j])
        lo, hi = degrees.min() - 0.05 * np.ptp(degrees), degrees.max() + 0.05 * np.ptp(degrees)
        assert float(text.replace("\u2212", "-")) == pytest.approx(lo + (loc - j * (1 + plots.GAP)) * (hi - lo))


def report_md(result: dict) -> str:
    return open(result.get("report") or result["files"]["report"]).read()


def section(md: str, title: str) -> str:
    text = md[md.index(f"## {title}\n"):]
    return text[:text.find("\n## ", 3) if "\n## " in text[3:] else None]


@pytest.mark.parametrize("command", list(ONLY))
def test_report_warnings_are_the_terminal_warnings(reports, command):
    """The report lists, word for word and in order, the warnings the command printed on the
    terminal, carried in its result (JSON `warnings`)."""
    res = reports[command]
    listed = re.findall(r"^- (.*)$", section(report_md(res), "Warnings"), re.M)
    assert listed == res["warnings"] == res[TERMINAL]


def test_some_report_of_the_fixture_has_warnings(reports):
    """The comparison above is not of empty lists only."""
    assert any(reports[command][TERMINAL] for command in ONLY)


def test_calibrate_report_counts_the_held_out_poses_outside_the_training_ranges(reports):
    """The extrapolation table's counts are those the terminal warned of (JSON val_extrapolation)."""
    res = reports["calibrate"]
    rows = re.findall(r"^\| (q[1-6]) [^|]* \| [^|]+ \| [^|]+ \| ([^|]+) \|$", section(report_md(res), "Extrapolation"),
                      re.M)
    assert len(rows) == 6 and all(count.strip() != "-" for _, count in rows)
    assert {q: int(count) for q, count in rows if int(count)} == res["val_extrapolation"]


def _expected_verdict(result: dict, tolerance: float | None) -> str:
    """The verdict from the figures of calibrate's JSON, by the rule the reference states."""
    if tolerance is None:
        overall = result["significance"].get("overall")
        return "noise not known" if overall is None else "beyond the noise" if overall["beyond_noise"] else \
            "at the noise"
    lo, hi = result["val"]["rms_mm_ci95"]
    if lo > tolerance:
        return "does not meet"
    return "meets" if hi <= tolerance and result["val"]["max_mm"] <= tolerance else "cannot tell"


@pytest.mark.parametrize("name, meets", [("pps", False), ("industrial6r", True), ("puma560", False)])
def test_each_shipped_example_report_states_a_verdict_and_a_next_step(name, meets, tmp_path):
    """calibrate on each shipped robot (a geometric model, the fastest path): the report opens with
    the verdict the JSON's figures give, what limits it and a next step naming a gecgen command;
    then with the instrument's noise and a tolerance above the held-out figures (meets) or below
    them (does not meet)."""
    robot = ROBOTS / f"{name}.yaml"
    gecgen("simulate", robot, "--poses", 30, "--seed", 2, "-o", tmp_path / "train.csv", "--val-out",
           tmp_path / "val.csv", "--val-poses", 10)
    base = ["calibrate", robot, tmp_path / "train.csv", "--val", tmp_path / "val.csv", "--errors", ERRORS,
            "--models", "geometric"]
    first = gecgen(*base, "-o", tmp_path / "plain")
    lo, hi = first["val"]["rms_mm_ci95"]
    tolerance = 2 * max(hi, first["val"]["max_mm"]) if meets else lo / 2
    for options in ([], ["--noise-mm", 0.03, "--tolerance-mm", tolerance]):
        res = first if not options else gecgen(*base, *options, "-o", tmp_path / "with")
        tolerance = options[3] if options else None
        verdict = _expected_verdict(res, tolerance)
        if tolerance is not None:
            assert verdict == ("meets" if tolerance > hi else "does not meet")
        md = section(report_md(res), "Verdict and next step")
        assert res["assessment"]["verdict"] == verdict and f"**Verdict: {verdict}.**" in md
        assert f"RMS point error {res['val']['rms_mm']:.3g} mm" in md and "What limits it:" in md
        assert re.search(r"\*\*Next step:\*\* .*`gecgen [a-z]+ [^`]+`", md), md


def test_log_axis_ticks_are_numbered_within_any_span():
    """Every span gets at least two tick values inside it, each short, never more than 12."""
    from gecgen.report.plots import log_ticks

    for lo, hi in ((2.4, 3.4), (0.011, 0.5), (1e-3, 40.0), (0.7, 0.71), (5e-5, 2e-4)):
        ticks = log_ticks(lo, hi)
        assert 2 <= len(ticks) <= 12 and ticks.min() >= lo and ticks.max() <= hi, (lo, hi, ticks)
        assert all(len(f"{v:g}") <= 6 for v in ticks), ticks


def test_legends_stand_above_the_data_and_pose_labels_clear_of_each_other(monkeypatch):
    """Each figure's legend is a row of its own above its axes and their titles (inside an axes it
    covered the largest bars and the histogram's peak), no axes keeps one; the labelled poses'
    labels do not overlap (five large errors on neighbouring poses of 200); a force is in N."""
    import gecgen.report.plots as plots
    from gecgen.model import load_robot
    from gecgen.model.measurements import Measurements
    from gecgen.report.blocks import DataSet, Residuals

    robot = load_robot(ROBOTS / "puma560.yaml")
    P = 200
    rng = np.random.default_rng(0)
    w = np.zeros((P, 6))
    w[:, 1] = rng.uniform(-700, 0, P)
    data = Measurements(rng.uniform(-1, 1, (P, robot.n)), w, np.zeros((P, 0)), (), np.arange(P), np.arange(P),
                        np.zeros(P, int), np.zeros((P, 3)))
    big = np.where((np.arange(P) >= 100) & (np.arange(P) < 105), 5.0, 1.0)[:, None]
    stages = [Residuals(name, np.arange(P), scale * big * rng.normal(size=(P, 3)), None)
              for name, scale in (("uncalibrated", 3.0), ("calibrated", 0.3), ("diagnosed", 0.1))]
    ds = DataSet("training", data, stages)
    drawn = []
    real = plots._figure

    def keep(fig, *args):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        [legend] = fig.legends
        box = legend.get_window_extent(renderer)
        axes = [ax for ax in fig.axes if ax.get_visible()]
        assert all(ax.get_legend() is None for ax in axes)
        assert not any(box.overlaps(b) for ax in axes
                       for b in (ax.get_window_extent(renderer), ax.title.get_window_extent(renderer)))
        labels = [t.get_window_extent(renderer) for ax in axes for t in ax.texts]
        assert not any(a.overlaps(b) for i, a in enumerate(labels) for b in labels[i + 1:])
        drawn.append((fig.axes[0].get_xlabel(), len(labels)))
        return real(fig, *args)

    monkeypatch.setattr(plots, "_figure", keep)
    plots.per_pose(robot, ds)
    plots.error_distribution(robot, ds)
    effect = type("Effect", (), {"error": "2.ep", "terms": ("fy*q3",)})()
    plots.effect(robot, effect, rng.normal(size=P), "fy", stages[1], stages[2], data)
    # the five largest poses lie side by side: one label stands for them, and the others go to poses apart
    assert drawn[0] == ("pose id, in the order of the file", 5)
    assert drawn[2][0] == "fy (N)"


@pytest.mark.parametrize("cell, right", [("0 %", True), ("-0.28 to 0.28 m", True), ("7", True), ("-", True),
                                         (".5", True), ("q1 lateral (m)", False), ("-x", False), ("", False)])
def test_a_cell_that_reads_as_a_number_is_right_aligned(cell, right):
    from gecgen.report.html import numeric

    assert numeric(cell) is right


def test_a_pixel_calibration_is_judged_against_the_stated_corner_noise():
    """identify --cameras's verdict: the training residual against --noise-px (chi-square at p = 0.01),
    the coefficients held as too weakly determined and an image the points cover in part are limits,
    and the first step scores held-out images."""
    from gecgen.fit.significance import overall
    from gecgen.report.verdict import AT_NOISE, BEYOND_NOISE, pixels_next_step

    score = {"rms_px": 0.3, "max_px": 0.9, "rms_mm_at_target": 0.16, "distance_m": 0.75}
    result = {"train": score, "before": {**score, "rms_px": 1.3}, "n_identifiable": 10,
              "eliminated": [{"param": "2.ep:1", "reason": "insignificant"},
                             {"param": "0.ez:1", "reason": "structural"}]}
    command = "gecgen evaluate cal.json HELD_OUT_PIXELS.csv --cameras cams.yaml"
    px = 1e-3  # overall() takes m and reports mm: px in, px out
    at = pixels_next_step(result, overall(0.2 * px, 4000, 0.2 * px), {"cam": (16, 16)}, command)
    beyond = pixels_next_step(result, overall(0.25 * px, 4000, 0.2 * px), {"cam": (9, 16)}, command)
    assert at.verdict == AT_NOISE and beyond.verdict == BEYOND_NOISE
    assert at.next_step.startswith(f"Score the calibration on images it was not fitted on: `{command}`; then record")
    assert "The images determine 10 of the 11 coefficients the model can have; 1 is held" in " ".join(at.limits)
    assert "--refine-intrinsics" in beyond.next_step and any("9 of 16 cells" in line for line in beyond.limits)
    assert any("the residual is 0.25 px per coordinate against the stated 0.2 px" in line for line in beyond.limits)
    assert not any("cells" in line for line in at.limits)
    assert not any("less than half the noise stated" in line for line in at.limits + beyond.limits)
    overstated = pixels_next_step(result, overall(0.2 * px, 4000, 0.5 * px), {"cam": (16, 16)}, command)
    assert overstated.verdict == AT_NOISE
    assert any("0.2 px per coordinate) is less than half the noise stated (0.5 px)" in line for line in overstated.limits)
    assert "measure a few poses twice" in overstated.next_step


def test_a_noise_stated_far_above_the_residual_is_named_as_such():
    """identify --noise-mm 10 on data the model fits to 0.099 mm per coordinate said the residual was the
    instrument's noise: a figure that large hides effects nearly that size, and the verdict says so."""
    from gecgen.report.verdict import AT_NOISE, Commands, Noise, assess

    commands = Commands("gecgen diagnose R D", "gecgen design R --given D", "gecgen evaluate C V", "gecgen export C")
    kw = dict(after={"rms_mm": 0.17, "max_mm": 0.4}, before=None, held_out=False, n_poses=40, tolerance_mm=None,
              held=None, n_train_poses=40, extrapolation={}, inside=None, relative=False, commands=commands)
    far = assess(noise=Noise(0.099, 10.0, False, "stated (--noise-mm)"), **kw)
    near = assess(noise=Noise(0.099, 0.1, False, "stated (--noise-mm)"), **kw)
    assert far.verdict == near.verdict == AT_NOISE
    assert any("less than half the noise stated (10 mm)" in line for line in far.limits)
    assert not any("is the instrument's noise" in line for line in far.limits)
    assert any("is the instrument's noise (0.1 mm" in line for line in near.limits)
    assert not any("less than half" in line for line in near.limits)


def _reads_only_what_exists_or_is_written(step: str, folder) -> None:
    """Each command in a next step that reads a calibration (export, evaluate, compensate) reads one
    on disk (relative to folder), or one that a command before it in the same code span writes."""
    for span in re.findall(r"`([^`]+)`", step):
        written = set()
        for part in span.split("&&"):
            words = part.split()
            if words[1:2] and words[1] in ("export", "evaluate", "compensate"):
                assert words[2] in written or (folder / words[2]).exists(), step
            written |= {b for a, b in zip(words, words[1:]) if a == "-o"}


def test_a_next_step_names_only_calibrations_that_exist_or_that_it_writes_first(reports, tmp_path, monkeypatch):
    """diagnose writes an error model, not a calibration: at the noise its next step fits the new model
    on all the data before exporting it (the README's report said to export a file nothing had
    written). The other reports' steps read the calibration their command wrote."""
    for result in reports.values():
        _reads_only_what_exists_or_is_written(re.search(r"\*\*Next step:\*\* (.*)", report_md(result)).group(1),
                                              tmp_path)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "truth.yaml").write_text("seed: 3\nconstant: {translation_std: 5.0e-4, rotation_std: 3.0e-4}\n"
                                         "noise: {repeatability: 1.0e-5, tracker: 3.0e-5}\n")
    gecgen("simulate", ROBOT, "--truth", "truth.yaml", "--poses", 30, "--val-out", "val.csv", "--val-poses", 10,
           "--seed", 3, "-o", "train.csv")
    out = gecgen("diagnose", ROBOT, "train.csv", "--val", "val.csv", "--errors", ERRORS, "--max-rounds", 1,
                 "--noise-mm", 0.0316, "-o", "new.errors.yaml")
    step = out["assessment"]["next_step"]
    assert out["assessment"]["verdict"] == "at the noise" and "gecgen export" in step
    _reads_only_what_exists_or_is_written(step, tmp_path)
