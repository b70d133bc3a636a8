"""Bad input gets one short line on stderr naming the file and the fix, at once: no traceback, no
hang, nothing dropped or guessed. Every case is a shipped file (robots/pps.yaml, robots/tiago.yaml and
its URDF, robots/tiago.import.yaml) or a small valid table with one defect, run through the command line."""
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROBOTS

from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.measurements import read_measurements
from gecgen.fit import calibration
from gecgen.fit.registration import IDENTITY

PPS = (ROBOTS / "pps.yaml").read_text()
TIAGO = (ROBOTS / "tiago.yaml").read_text()
URDF = (ROBOTS / "tiago" / "tiago_48_schunk.urdf").read_text()
MAPPING = (ROBOTS / "tiago.import.yaml").read_text()
HEADER = "pose,q1,q2,q3,q4,q5,q6,target,x,y,z"


def edit(text: str, old: str, new: str) -> str:
    assert old in text, old  # the shipped file still holds what the case breaks
    return text.replace(old, new)


def write(folder, name, content):
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    return path


def table(q1=0.1, q2=0.05, header=HEADER, extra=""):
    """Three poses of pps measuring t1..t3; pose 1 has the given q1 and q2; `extra` appends to every row."""
    rows = [header]
    for pose in range(3):
        q = [q1 if pose == 1 else 0.1, q2 if pose == 1 else 0.05, 0.0, 0.2, 0.01, -0.01]
        rows += [",".join([str(pose), *map(repr, q), t, "0.1", "0.6", "0.8"]) + extra for t in ("t1", "t2", "t3")]
    return "\n".join(rows) + "\n"


def bomb(key: str) -> str:
    """YAML whose `key` holds ten nested levels of ten aliases each: 10**10 values when expanded."""
    levels = ['&l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    levels += [f"&l{k} [{', '.join([f'*l{k - 1}'] * 10)}]" for k in range(1, 10)]
    return f"{key}: [{', '.join(levels)}]\n"


def tiago(tmp, urdf=URDF):
    write(tmp, "tiago/tiago_48_schunk.urdf", urdf)
    return write(tmp, "tiago.yaml", TIAGO)


def telescope(tmp):
    """The mimic-joint robot and its URDF, copied into tmp: the robot file's path."""
    for name in ("telescope.yaml", "telescope.urdf"):
        write(tmp, name, (ROBOTS.parent / "tests" / "data" / "mimic" / name).read_text())
    return tmp / "telescope.yaml"


def ur10_estimate(tmp):
    """The UR10 of tests/data/ur10 with its probe left to estimate, copied into tmp: the robot file's path."""
    write(tmp, "ur10_robot.urdf", (ROBOTS.parent / "tests" / "data" / "ur10" / "ur10_robot.urdf").read_text())
    return write(tmp, "ur10.yaml", "name: ur10\nangle_unit: rad\nurdf: ur10_robot.urdf\nbase_link: base_link\n"
                                   "tip_link: wrist_3_link\ntargets:\n  probe: estimate\n")


def pps(tmp, text=PPS):
    return write(tmp, "robot.yaml", text)


def with_model(tmp, command: str, terms: str, data: str):
    model = write(tmp, "model.errors.yaml", f"frames:\n  1: {terms}\n")
    return [command, pps(tmp), write(tmp, "data.csv", data), "--errors", model]


def calibrated(tmp, terms: str):
    """A calibration of pps with the given frame-1 terms (zero coefficients), written as identify would."""
    robot = load_robot(pps(tmp))
    model = load_error_model(write(tmp, "model.errors.yaml", f"frames:\n  1: {terms}\n"), robot)
    nc = len(model.coefficients)
    calib = calibration.Calibration(robot, model, np.zeros(nc), np.zeros(nc), tuple(range(nc)), np.eye(nc), IDENTITY, {})
    calibration.save(calib, tmp / "calib.json")
    return tmp / "calib.json"


LOOP = '<joint name="loop" type="fixed"><parent link="arm_7_link"/><child link="base_footprint"/></joint></robot>'
#: arm_1_joint's origin and axis (the axis alone is written alike on many joints)
ARM_1_AXIS = '<origin rpy="0 0 -1.57079632679" xyz="0.15505 0.014 -0.151"/>\n    <axis xyz="0 0 1"/>'
SECOND_PARENT = '<joint name="extra" type="fixed"><parent link="base_footprint"/><child link="arm_3_link"/></joint></robot>'

# case: (arguments given the test's folder, the file the message must name, a phrase it must hold)
CASES = {
    "angle_unit missing": (lambda t: ["redundancy", pps(t, edit(PPS, "angle_unit: deg\n", ""))],
                           "robot.yaml", "add 'angle_unit: deg' or 'angle_unit: rad'"),
    "joint named like another joint's variable": (
        lambda t: ["redundancy", pps(t, edit(PPS, "name: vertical,", "name: q3,"))],
        "robot.yaml", "joints[1].name: 'q3' is spelled like a joint variable"),
    "joint named like a wrench component": (lambda t: ["redundancy", pps(t, edit(PPS, "name: roll,", "name: fx,"))],
                                            "robot.yaml", "'fx' is a wrench component"),
    "joint named like a term function": (lambda t: ["redundancy", pps(t, edit(PPS, "name: pitch,", "name: sin,"))],
                                         "robot.yaml", "'sin' is reserved"),
    "two joints of one name": (lambda t: ["redundancy", pps(t, edit(PPS, "name: pitch,", "name: roll,"))],
                               "robot.yaml", "joints[5].name: 'roll' is also the name of joint 5"),
    "URDF joint named like another joint's variable": (
        lambda t: ["redundancy", tiago(t, edit(URDF, '"arm_1_joint"', '"q1"'))],
        "tiago_48_schunk.urdf", "joint 'q1' is spelled like a joint variable but names joint 2"),
    "robot name of 100,000 characters": (lambda t: ["redundancy", pps(t, edit(PPS, "name: pps\n", f"name: {'x-' * 50_000}\n"))],
                                         "robot.yaml", "name: 'x-x-x-"),
    "term of 100,000 characters": (lambda t: ["redundancy", ROBOTS / "pps.yaml", "--errors",
                                              write(t, "m.errors.yaml", f"default: ['{'q1+' * 33_333}q1']\n")],
                                   "m.errors.yaml", "longer than 200 characters"),
    "NaN in a robot file": (lambda t: ["redundancy", pps(t, edit(PPS, "d: 0.45", "d: .nan"))],
                            "robot.yaml", "joints[3].d: nan is not a finite number"),
    "inf in a robot file": (lambda t: ["redundancy", pps(t, edit(PPS, "t1: [-0.20,", "t1: [-.inf,"))],
                            "robot.yaml", "targets.t1[0]: -inf is not a finite number"),
    "alias bomb in a robot file": (lambda t: ["redundancy", pps(t, edit(PPS, "name: pps\n", bomb("name")))],
                                   "robot.yaml", "YAML aliases (*name) stand for more than"),
    "alias bomb in an error model": (lambda t: ["redundancy", ROBOTS / "pps.yaml", "--errors",
                                                write(t, "bomb.errors.yaml", bomb("default"))],
                                     "bomb.errors.yaml", "YAML aliases (*name) stand for more than"),
    "robot file of 1.1 MB": (lambda t: ["redundancy", pps(t, PPS + "#" + "x" * 1_100_000 + "\n")],
                             "robot.yaml", "a robot file may have at most 1000000"),
    "URDF with a loop (gravity)": (lambda t: ["gravity", tiago(t, edit(URDF, "</robot>", LOOP)),
                                              write(t, "q.csv", "q1,q2,q3,q4,q5,q6,q7,q8\n" + "0.1," * 7 + "0.1\n"),
                                              "-o", t / "out.csv"],
                                   "tiago_48_schunk.urdf", "is its own ancestor (the joints form a loop)"),
    "URDF axis of 1.7e308 (its length overflows)": (lambda t: ["redundancy", tiago(t, edit(URDF, ARM_1_AXIS, ARM_1_AXIS.replace('"0 0 1"',
                                                                                                  '"1.7e308 1.7e308 0"')))],
                           "tiago_48_schunk.urdf", "'arm_1_joint' axis xyz: length inf; a joint axis is a unit vector"),
    "URDF link with two parents": (lambda t: ["redundancy", tiago(t, edit(URDF, "</robot>", SECOND_PARENT))],
                                   "tiago_48_schunk.urdf", "link 'arm_3_link' is already the child of joint"),
    "robot file not UTF-8": (lambda t: ["redundancy", pps(t, edit(PPS, "description: Patient",
                                                                   "description: caf\xe9 Patient").encode("latin-1"))],
                             "robot.yaml", "line 4: byte 0xe9 is not UTF-8; save the robot file as UTF-8"),
    "error model not UTF-8": (lambda t: ["redundancy", ROBOTS / "pps.yaml", "--errors",
                                         write(t, "m.errors.yaml", b"# caf\xe9\ndefault: ['1']\n")],
                              "m.errors.yaml", "byte 0xe9 is not UTF-8"),
    "CSV not UTF-8": (lambda t: ["identify", ROBOTS / "pps.yaml", write(t, "data.csv", table().encode() + b"5\xff\n")],
                      "data.csv", "line 11: byte 0xff is not UTF-8"),
    "mapping not UTF-8": (lambda t: ["import", ROBOTS / "tiago.yaml", t / "wide.csv", "--mapping",
                                     write(t, "map.yaml", MAPPING.encode() + b"# \xe9\n"), "-o", t / "out.csv"],
                          "map.yaml", "is not UTF-8"),
    "CSV separated by semicolons": (lambda t: ["identify", ROBOTS / "pps.yaml", write(t, "data.csv", table().replace(",", ";"))],
                                    "data.csv", "row 1: the columns are separated by ';'; gecgen reads comma-separated "
                                                "files: convert the file to commas (a wide export converts with "
                                                "gecgen import --sep ';' --decimal ',')"),
    "CSV separated by tabs": (lambda t: ["identify", ROBOTS / "pps.yaml", write(t, "data.csv", table().replace(",", "\t"))],
                              "data.csv", "separated by tabs; gecgen reads comma-separated files: convert the file to "
                                          "commas (a wide export converts with gecgen import --sep tab)"),
    "CSV cell of 200,000 characters": (
        lambda t: ["identify", ROBOTS / "pps.yaml", write(t, "data.csv", table().replace(",t2,", "," + "x" * 200_000 + ",", 1))],
        "data.csv", "row 3, column 'target': 200000 characters"),
    "CSV blank line between rows": (lambda t: ["identify", ROBOTS / "pps.yaml", write(t, "data.csv", table().replace("\n2,", "\n\n2,", 1))],
                                    "data.csv", "row 8: a blank line between the rows; remove it"),
    "wrench of 1e308": (lambda t: ["identify", ROBOTS / "pps.yaml",
                                   write(t, "data.csv", table(header=HEADER + ",fx", extra=",1e308"))],
                        "data.csv", "row 2, column 'fx': '1e308' is beyond +-1e+07"),
    "aux signal of 1e308": (lambda t: ["identify", ROBOTS / "pps.yaml",
                                       write(t, "data.csv", table(header=HEADER + ",temp_c", extra=",1e308"))],
                            "data.csv", "row 2, column 'temp_c': '1e308' is beyond +-1e+12"),
    "pose id 1e308": (lambda t: ["identify", ROBOTS / "pps.yaml", write(t, "data.csv", table().replace("\n2,", "\n1e308,"))],
                      "data.csv", "column 'pose': not an integer pose id within +-2**53"),
    "pose id 2**53 + 1": (lambda t: ["identify", ROBOTS / "pps.yaml",
                                     write(t, "data.csv", table().replace("\n2,", "\n9007199254740993,"))],
                          "data.csv", "column 'pose': not an integer pose id within +-2**53"),
    "a term's factor of 1e300": (lambda t: ["redundancy", ROBOTS / "pps.yaml", "--errors",
                                            write(t, "m.errors.yaml", 'frames:\n  1: ["1", "1e300*q1"]\n')],
                                 "m.errors.yaml", "term '1e300*q1': holds the number 1e+300, outside 1e-12..1e+12"),
    "nested powers": (lambda t: ["redundancy", ROBOTS / "pps.yaml", "--errors",
                                 write(t, "m.errors.yaml", 'frames:\n  1: ["((q1**16)**16)**16"]\n')],
                      "m.errors.yaml", "a variable appears to the power 256"),
    "sqrt of a negative reading (identify)": (lambda t: with_model(t, "identify", '["1", "sqrt(q1)"]', table(q1=-0.5)),
                                              "data.csv", "pose 1: the term 'sqrt(q1)' of model.errors.yaml is NaN"),
    "1/q2 at q2 = 0 (redundancy)": (lambda t: with_model(t, "redundancy", '["1", "1/q2"]', table(q2=0.0)),
                                    "data.csv", "pose 1: the term '1/q2' of model.errors.yaml is infinite at q2 = 0"),
    "q1**-1 at q1 = 0 (diagnose)": (lambda t: with_model(t, "diagnose", '["1", "q1**-1"]', table(q1=0.0)),
                                    "data.csv", "the term 'q1**-1' of model.errors.yaml is infinite"),
    "sqrt of a negative command (compensate)": (
        lambda t: ["compensate", calibrated(t, '["1", "sqrt(q1)"]'),
                   write(t, "cmds.csv", "q1,q2,q3,q4,q5,q6\n0.1,0,0,0,0,0\n-0.1,0,0,0,0,0\n"), "-o", t / "out.csv"],
        "cmds.csv", "row 3: the term 'sqrt(q1)' of calib.json: error_model is NaN at q1 = -0.1"),
}


def edited(tmp, change):
    """A calibration of pps (constant model) with one edit to its JSON."""
    import json

    path = calibrated(tmp, '["1"]')
    d = json.loads(path.read_text())
    change(d)
    path.write_text(json.dumps(d))
    return path


# issue 20: nothing destroyed, nothing silently read another way, no traceback from an option; run in
# this process (the command line's own entry point, main), as the cases above run in a subprocess
IN_PROCESS = {
    "an output naming the robot file": (lambda t: ["identify", pps(t), write(t, "data.csv", table()), "-o", t / "robot.yaml"],
                                        "robot.yaml", "is the robot, which this command reads; writing the calibration"),
    "an output naming the data": (lambda t: ["identify", pps(t), write(t, "data.csv", table()), "-o", t / "data.csv"],
                                  "data.csv", "is the data, which this command reads; writing the calibration there"),
    "an output naming the URDF a robot file names": (
        lambda t: ["identify", telescope(t), write(t, "data.csv", "pose,q1,q2,q3,q4,target,x,y,z\n"), "-o",
                   t / "telescope.urdf"],
        "telescope.urdf", "telescope.yaml names, which this command reads; writing the calibration there"),
    # issue 21: a near miss is named, YAML errors say where, paths say what they are relative to
    "a mistyped command": (lambda t: ["simulat"], "simulat", "did you mean 'simulate'?"),
    # issue 22: an option of sockets and planes, or of a design, is never silently ignored
    "a socket option without sockets": (lambda t: ["simulate", pps(t), "--per-socket", "30", "-o", t / "s.csv"],
                                        "--per-socket", "goes with --plates or --planes"),
    "a calibration for an ISO 9283 plan": (lambda t: ["iso9283", str(ROBOTS / "puma560.yaml"), "-o", t / "plan.csv",
                                                   "--calibration", t / "c.json"],
                                         "--calibration", "goes with --plan and --measured"),
    "poses with sockets": (lambda t: ["simulate", str(ROBOTS / "panda_ball.yaml"), "--plates", "1", "--poses",
                                      "10", "-o", t / "s.csv"], "--poses", "--plates and --planes simulate sockets"),
    "YAML that does not parse": (lambda t: ["redundancy", write(t, "bad.yaml", "name: x\nangle_unit: rad\n  b: [1\n")],
                                 "bad.yaml", "line 3, column 4: not valid YAML"),
    "a tip_link the URDF lacks": (
        lambda t: ["redundancy", write(t, "tel.yaml", telescope(t).read_text().replace("tip_link: tool_link",
                                                                                     "tip_link: tool_lnk"))],
        "telescope.urdf", "tip_link 'tool_lnk' is not a link of this URDF; did you mean 'tool_link'?"),
    "a urdf path that does not exist": (
        lambda t: ["redundancy", write(t, "tel.yaml", telescope(t).read_text().replace("urdf: telescope.urdf",
                                                                                     "urdf: urdf/telescope.urdf"))],
        "tel.yaml", "(the path is relative to the robot file's folder"),
    "commands in degrees (compensate)": (
        lambda t: ["compensate", calibrated(t, '["1"]'), write(t, "cmds.csv", "q1,q2,q3,q4,q5,q6\n0,0,0,90,0,0\n"),
                   "-o", t / "out.csv"],
        "cmds.csv", "row 2, column 'q4': 90 is outside the joint limits"),
    "commands of a robot with more joints (compensate)": (
        lambda t: ["compensate", calibrated(t, '["1"]'), write(t, "cmds.csv", "q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,0,0,0\n"),
                   "-o", t / "out.csv"],
        "cmds.csv", "row 1: column 'q7' but robot pps has 6 joints; remove it or use the calibration or robot file"),
    "commands naming their joints (compensate)": (
        lambda t: ["compensate", calibrated(t, '["1"]'), write(t, "cmds.csv", "lateral,vertical,longitudinal,theta,roll,"
                                                                               "pitch\n0,0,0,0,0,0\n"), "-o", t / "out.csv"],
        "cmds.csv", "missing column 'q1'; the file names joints (lateral, ...): gecgen reads q1..q6 in the robot file's "
                    "order (q1 = lateral); rename the columns"),
    "measurements naming their joints": (
        lambda t: ["identify", pps(t), write(t, "data.csv", table(header=HEADER.replace("q1,q2", "lateral,vertical")))],
        "data.csv", "missing column 'q1' (needed: pose, q1, q2, q3, q4, q5, q6, target, x, y, z); the file names joints "
                    "(lateral, ...): gecgen reads q1..q6 in the robot file's order (q1 = lateral); rename the columns, "
                    "or convert the file with gecgen import --mapping"),
    "two outputs naming one file": (lambda t: ["simulate", pps(t), "--poses", "3", "-o", t / "s.csv", "--val-out",
                                               t / "s.csv"], "s.csv", "--val-out names the same file as --output"),
    "an output onto a device": (lambda t: ["simulate", pps(t), "--poses", "3", "-o", "/dev/null"],
                                "/dev/null", "is not a regular file (a device, pipe or socket)"),
    "an output name over 255 bytes": (lambda t: ["simulate", pps(t), "--poses", "3", "-o", t / ("x" * 252 + ".csv")],
                                      "xxxx.csv", "the file name is longer than 255 bytes"),
    "design for a target left to estimate": (
        lambda t: ["design", ur10_estimate(t), "--poses", "10", "-o", t / "d.csv"], "ur10.yaml",
        "target 'probe' is left to estimate, so this needs measured data (identify, diagnose and calibrate place it "
        "from theirs); to plan before measuring, write a rough guess instead, targets: {probe: [x, y, z]}"),
    "a key twice in a robot file": (lambda t: ["redundancy", pps(t, PPS + "angle_unit: rad\n")],
                                    "robot.yaml", "key 'angle_unit' appears twice in one mapping; keep one"),
    "a full-width joint name": (lambda t: ["redundancy", pps(t, edit(PPS, "name: pitch,", "name: \uff51\uff15,"))],
                                "robot.yaml", "is not an ASCII identifier"),
    "--seed -1": (lambda t: ["simulate", pps(t), "--seed", "-1", "-o", t / "s.csv"], "--seed", "is outside 0.."),
    "--poses 0": (lambda t: ["design", pps(t), "--poses", "0", "-o", t / "d.csv"], "--poses 0", "give at least 1 pose to design"),
    "--payload-kg abc": (lambda t: ["simulate", pps(t), "--payload-kg", "abc", "-o", t / "s.csv"], "--payload-kg",
                         "'abc' is not a number"),
    "--payload-kg nan": (lambda t: ["simulate", pps(t), "--payload-kg", "0,nan", "-o", t / "s.csv"], "--payload-kg",
                         "'nan': give a finite number at least 0"),
    "--step 1e-9": (lambda t: ["simulate", pps(t), "--design", "one-at-a-time", "--step", "1e-9", "-o", t / "s.csv"],
                    "--step", "poses (at most 10,000,000); give a larger step"),
    "--max-rounds 0": (lambda t: ["diagnose", pps(t), write(t, "data.csv", table()), "--max-rounds", "0"],
                       "--max-rounds", "0 is outside 1.."),
    "--holdout 1.5": (lambda t: ["calibrate", pps(t), write(t, "data.csv", table()), "--holdout", "1.5", "-o", t / "c"],
                      "--holdout 1.5", "give the share of poses to hold out"),
    "an unknown option value": (lambda t: ["identify", pps(t), write(t, "data.csv", table()), "--loss", "L2"],
                                "--loss", "invalid choice 'L2'; did you mean 'l2'?"),
    "a station id beyond 2**53": (lambda t: ["identify", pps(t), write(t, "data.csv", table(header=HEADER + ",station",
                                                                                         extra=",1e20"))],
                                  "data.csv", "column 'station': not an integer station id within +-2**53"),
    "positions in centimetres": (lambda t: ["identify", pps(t), write(t, "data.csv", table().replace(",0.1,0.6,0.8",
                                                                                                    ",10,60,80"))],
                                 "data.csv", "positions are in metres; divide millimetres by 1000, centimetres by 100"),
    "a header of 100,000 columns, one twice": (
        lambda t: ["identify", pps(t), write(t, "data.csv", ",".join([*HEADER.split(","), *(f"a{k}" for k in range(99_988)),
                                                                      "a7"]) + "\n")],
        "data.csv", "column 'a7' appears twice in the header"),
    "calibration: a coefficient of 1e300": (
        lambda t: ["evaluate", edited(t, lambda d: d["coefficients"][0].update(value=1e300)), write(t, "data.csv", table())],
        "reaches 1e+300 m", "the file was edited or belongs to another robot"),
    "calibration: error_model a string": (lambda t: ["evaluate", edited(t, lambda d: d.update(error_model="x")),
                                                     write(t, "data.csv", table())],
                                          "calib.json", "error_model: expected an object with default and frames"),
    "calibration: a negative std": (lambda t: ["evaluate", edited(t, lambda d: d["coefficients"][0].update(std=-1.0)),
                                               write(t, "data.csv", table())],
                                    "calib.json", "std -1.0 is negative"),
    "calibration: applied \"false\"": (
        lambda t: ["evaluate", edited(t, lambda d: d["registration"].update(applied="false")), write(t, "data.csv", table())],
        "calib.json", 'registration.applied: "false" is not true or false'),
    "calibration: a training range of one number": (
        lambda t: ["evaluate", edited(t, lambda d: d.update(training_ranges={"q1": [1]})), write(t, "data.csv", table())],
        "calib.json", "training_ranges: expected each input's [lowest, highest] value as two finite numbers"),
}


@pytest.mark.parametrize("case", IN_PROCESS)
def test_bad_input_is_refused_in_one_line_in_process(tmp_path, case, monkeypatch):
    import contextlib
    import io

    from gecgen.cli import main

    make_args, filename, phrase = IN_PROCESS[case]
    monkeypatch.chdir(tmp_path)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = main([str(a) for a in make_args(tmp_path)] + ["--json"])
        except SystemExit as exc:  # argparse's refusal of an option's value
            code = exc.code
    lines = err.getvalue().splitlines()
    assert code != 0 and out.getvalue() == "" and len(lines) == 1, err.getvalue()[-2000:]
    # the length is the message's own: the temporary folder's path is as long as the test runner makes it
    assert filename in lines[0] and phrase in lines[0] and len(lines[0].replace(str(tmp_path), "T")) < 300, lines[0]


@pytest.mark.parametrize("case", CASES)
def test_bad_input_is_refused_in_one_short_line(tmp_path, case):
    make_args, filename, phrase = CASES[case]
    args = [str(a) for a in make_args(tmp_path)]
    # a hang (an alias bomb expanding, a quadratic check) ends in the timeout; speed lives in benchmarks/
    run = subprocess.run([sys.executable, "-m", "gecgen.cli", *args, "--json"], capture_output=True, text=True,
                         cwd=tmp_path, timeout=60)
    lines = run.stderr.splitlines()
    assert run.returncode != 0 and run.stdout == "" and len(lines) == 1, run.stderr[-2000:]
    # the length is the message's own: the temporary folder's path is as long as the test runner makes it
    assert filename in lines[0] and phrase in lines[0] and len(lines[0].replace(str(tmp_path), "T")) < 300, lines[0]


def test_a_byte_order_mark_and_modest_aliases_are_accepted(tmp_path):
    """Spreadsheets write a BOM before the header; anchors that share a term list are ordinary YAML."""
    robot = load_robot(ROBOTS / "pps.yaml")
    plain = read_measurements(write(tmp_path, "plain.csv", table()), robot)
    marked = read_measurements(write(tmp_path, "bom.csv", "\ufeff" + table()), robot)
    for key in ("q", "pose_ids", "target", "xyz"):
        assert getattr(marked, key).tolist() == getattr(plain, key).tolist(), key
    model = load_error_model(write(tmp_path, "m.errors.yaml", "frames:\n  1: &terms ['1', q1]\n  2: *terms\n"), robot)
    assert [t.text for t in model.terms[6 * 2]] == ["1", "q1"]


def test_quoted_cells_and_windows_line_ends_read_as_the_plain_file(tmp_path):
    """The csv module reads what the fast reader declines (quotes); CRLF the fast reader takes; blank
    lines after the last row end the file."""
    robot = load_robot(ROBOTS / "pps.yaml")
    plain = read_measurements(write(tmp_path, "plain.csv", table()), robot)
    quoted = table().replace(",t1,", ',"t1",').replace(",0.6,", ',"0.6",')
    blank_end = table() + "\n \n\t\n"  # a spreadsheet's empty lines after the last row
    for name, text in (("quoted.csv", quoted), ("crlf.csv", table().replace("\n", "\r\n")),
                       ("blank_end.csv", blank_end), ("blank_end_crlf.csv", blank_end.replace("\n", "\r\n"))):
        data = read_measurements(write(tmp_path, name, text.encode()), robot)
        for key in ("q", "pose_ids", "target", "xyz"):
            assert getattr(data, key).tolist() == getattr(plain, key).tolist(), (name, key)


def test_what_the_first_audit_broke_now_works(tmp_path):
    """A legal 255-byte output name is written (the temporary file is named apart from it); revolute
    limits wholly past half a turn (190..300 deg) sample poses within them; 5e-2 in YAML is a number."""
    from gecgen.cli import main

    name = tmp_path / ("x" * 251 + ".csv")
    assert main(["simulate", str(ROBOTS / "puma560.yaml"), "--poses", "3", "-o", str(name)]) == 0 and name.is_file()
    assert not list(tmp_path.glob(".*.part"))
    robot = pps(tmp_path, edit(edit(PPS, "limits: [-90, 90]", "limits: [190, 300]"), "[-0.20, 0.01, -0.20]",
                                "[-2e-1, 1e-2, -2E-1]"))
    assert load_robot(robot).targets["t1"] == (-0.2, 0.01, -0.2)
    out = tmp_path / "s.csv"
    assert main(["simulate", str(robot), "--poses", "20", "-o", str(out), "--json"]) == 0
    q4 = read_measurements(out, load_robot(robot)).q[:, 3]
    assert np.radians(190) <= q4.min() and q4.max() <= np.radians(300)
    assert main(["redundancy", str(robot), "--json"]) == 0


def test_a_tracker_frame_is_not_fitted_to_points_that_cannot_fix_it(tmp_path, capsys):
    """One pose measured 60 times (30 um of noise) turned the fitted frame by 131 degrees, and points on
    a line by 156: such data leaves the frame alone, says so, and --register always refuses it."""
    import json

    import pandas as pd

    from gecgen.cli import main

    robot = str(ROBOTS / "industrial6r.yaml")
    assert main(["simulate", robot, "--poses", "5", "--seed", "1", "-o", str(tmp_path / "t.csv")]) == 0
    first = pd.read_csv(tmp_path / "t.csv").iloc[[0] * 60].assign(pose=range(60))
    first[["x", "y", "z"]] += np.random.default_rng(0).normal(0, 3e-5, (60, 3))
    line = first.copy()  # the same point slid along a line by up to 0.3 m, as a rail would put it
    line["x"] += np.linspace(0, 0.3, 60)
    for name, table in (("one.csv", first), ("line.csv", line)):
        table.to_csv(tmp_path / name, index=False)
        capsys.readouterr()
        assert main(["identify", robot, str(tmp_path / name), "-o", str(tmp_path / "c.json"), "--json"]) == 0
        out, err = capsys.readouterr()
        assert json.loads(out)["registration"]["angle_deg"] == 0.0
        assert "too little to fix a tracker frame" in err, err
        assert main(["identify", robot, str(tmp_path / name), "--register", "always", "-o", str(tmp_path / "d.json")]) == 2
        assert "registration needs measured points spread at least 10 mm" in capsys.readouterr().err


def test_orientations_in_the_wrong_unit_fail_the_fit(tmp_path, capsys):
    """figaroh's UR10 poses imported with their angles called degrees (they are radians): the fit
    left 8.42 mm where the nominal model left 3.50 mm, and exited 0; now it is not a calibration."""
    from gecgen.cli import main

    data = ROBOTS.parent / "tests" / "data" / "ur10"
    write(tmp_path, "ur10_robot.urdf", (data / "ur10_robot.urdf").read_text())
    robot = write(tmp_path, "ur10.yaml", "name: ur10\nangle_unit: rad\nurdf: ur10_robot.urdf\nbase_link: base_link\n"
                                         "tip_link: wrist_3_link\ntool: {origin: [0.0, -0.12, 0.0], rpy: [-0.5, 0, 0]}\n"
                                         "targets:\n  probe: estimate\n")
    mapping = write(tmp_path, "map.yaml", edit((data / "calibration.mapping.yaml").read_text(), "unit: rad", "unit: deg"))
    assert main(["import", str(robot), str(data / "calibration.csv"), "--mapping", str(mapping),
                 "-o", str(tmp_path / "poses.csv")]) == 0
    capsys.readouterr()
    assert main(["identify", str(robot), str(tmp_path / "poses.csv"), "-o", str(tmp_path / "c.json")]) == 1
    err = capsys.readouterr().err
    assert "the fit leaves more position error than the nominal model" in err and not (tmp_path / "c.json").exists()


def test_a_file_written_into_an_output_folder_never_replaces_an_input(tmp_path):
    """Files an output folder receives are known only as they are written: one that would land on
    a file the command reads is refused there, and the input is left as it was."""
    from gecgen.model.files import reading, write_atomically
    from gecgen.model import ModelError

    source = write(tmp_path, "errors.yaml", "frames: {}\n")
    with reading([str(source)]):
        with pytest.raises(ModelError, match="errors.yaml: is .*errors.yaml, which this command reads"):
            write_atomically(tmp_path / "." / "errors.yaml", "overwritten")
        write_atomically(tmp_path / "other.yaml", "fine")
    assert source.read_text() == "frames: {}\n" and not list(tmp_path.glob(".gecgen-*"))
    write_atomically(source, "after the command")  # outside the command, the file is just a file


def test_simulate_says_when_it_has_no_truth_to_simulate(tmp_path, capsys):
    """Without a truth file the simulated robot is the nominal one: said, not silent."""
    from gecgen.cli import main

    assert main(["simulate", str(ROBOTS / "puma560.yaml"), "--poses", "3", "-o", str(tmp_path / "p.csv")]) == 0
    err = capsys.readouterr().err
    assert "warning: no truth file" in err and "the simulated robot is the nominal one" in err
