"""Import of wide tables (one row per pose, four points per row) through a column mapping."""
import csv
import json
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
import yaml
from conftest import ROBOTS

from gecgen.cli import main
from gecgen.model import ModelError, load_robot
from gecgen.model.measurements import LIMIT_TOLERANCE, read_measurements
from gecgen.model.wide import import_wide, load_mapping

DATA = Path(__file__).resolve().parent / "data" / "tiago-mocap"
FILES = {"train_2021-11-30.csv": 37, "validation_2021-11-26.csv": 62}
MAPPING = ROBOTS / "tiago.import.yaml"
POINTS = [[f"{a}{k}" for a in "xyz"] for k in range(1, 5)]  # the x, y, z columns of m1..m4


@pytest.fixture(scope="module")
def tiago():
    return load_robot(ROBOTS / "tiago.yaml")


def read_table(path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# -- the real TIAGo files --------------------------------------------------------------------------
def test_train_file_converts_to_37_poses_of_4_targets_exactly(tiago, tmp_path, capsys):
    rows = read_table(DATA / "train_2021-11-30.csv")
    data = import_wide(DATA / "train_2021-11-30.csv", tiago, MAPPING)
    assert (data.n_poses, len(data.xyz)) == (37, 148)
    assert data.pose_ids.tolist() == list(range(37))  # pose: row
    expected_q = [[float(r[name]) for name in tiago.joint_names] for r in rows]
    expected_xyz = [[float(r[c]) for c in cols] for r in rows for cols in POINTS]
    assert data.q.tolist() == expected_q and data.xyz.tolist() == expected_xyz  # bit for bit
    assert [tiago.target_names[t] for t in data.target[:8]] == ["m1", "m2", "m3", "m4"] * 2
    assert data.aux_names == ("marker_std_mm",)
    # the command writes the contract's file, and reading it back gives the same numbers
    out = tmp_path / "train.csv"
    assert main(["import", str(ROBOTS / "tiago.yaml"), str(DATA / "train_2021-11-30.csv"), "--mapping",
                 str(MAPPING), "-o", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert (result["poses"], result["rows"], result["targets"]) == (37, 148, ["m1", "m2", "m3", "m4"])
    back = read_measurements(out, tiago)
    for key in ("q", "xyz", "aux", "pose_ids", "target"):
        assert getattr(back, key).tolist() == getattr(data, key).tolist(), key


@pytest.mark.parametrize("name", FILES)
def test_readings_outside_the_urdf_limits_are_reported_not_clipped(tiago, tmp_path, capsys, name):
    rows = read_table(DATA / name)
    q = np.array([[float(r[j]) for j in tiago.joint_names] for r in rows])
    lo, hi = np.array([[j.lower for j in tiago.joints], [j.upper for j in tiago.joints]])
    out = tmp_path / "m1.csv"
    assert main(["import", str(ROBOTS / "tiago.yaml"), str(DATA / name), "--mapping", str(MAPPING),
                 "--targets", "m1", "-o", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert (result["poses"], result["rows"]) == (FILES[name], FILES[name])
    expected = [(int(r) + 2, tiago.joint_names[j]) for r, j in np.argwhere((q < lo) | (q > hi))]
    assert [(o["row"], o["joint"]) for o in result["outside_limits"]] == expected
    # on these files: the torso at full lift reads a fraction of a millimetre above its 0.35 m limit
    assert expected and {j for _, j in expected} == {"torso_lift_joint"}
    assert all(0 < o["excess"] < LIMIT_TOLERANCE for o in result["outside_limits"])
    assert "outside the limits" in captured.err
    written = read_measurements(out, tiago)
    assert written.q.tolist() == q.tolist()  # kept as read


# -- bad tables and mappings (synthetic, no data needed) -------------------------------------------
def wide_table(tiago, extra: dict | None = None, rows: int = 3) -> dict[str, list]:
    """A small valid wide table: columns -> cells (text), in the layout of the mocap files."""
    rng = np.random.default_rng(7)
    table = {c: [repr(v) for v in rng.uniform(-0.5, 0.5, rows).tolist()] for cols in POINTS for c in cols}
    for j in tiago.joints:
        table[j.name] = [repr(v) for v in rng.uniform(max(j.lower, -1), min(j.upper, 1), rows).tolist()]
    table |= {"shipped_row": [str(r) for r in range(rows)], "t_start_robot": ["1.5"] * rows,
              "t_end_robot": ["2.5"] * rows, "marker_std_mm": ["0.2"] * rows}
    return table | (extra or {})


def write_table(path, table: dict[str, list]):
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(table)
        out.writerows(zip(*table.values()))
    return path


def write_mapping(path, spec: dict):
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def shipped_mapping() -> dict:
    return yaml.safe_load(MAPPING.read_text())


def test_mapping_by_joint_index_pose_column_and_wrench(tiago, tmp_path):
    table = wide_table(tiago, {"fz_sensor": ["1.0", "2.0", "3.0"]})
    spec = shipped_mapping()
    spec["joints"] = {f"q{k + 1}": name for k, name in enumerate(tiago.joint_names)}
    spec |= {"pose": "shipped_row", "ignore": ["t_start_robot", "t_end_robot"], "wrench": {"fz": "fz_sensor"},
             "targets": {"m3": ["x3", "y3", "z3"], "m1": ["x1", "y1", "z1"]}}
    spec["ignore"] += ["x2", "y2", "z2", "x4", "y4", "z4"]
    data = import_wide(write_table(tmp_path / "t.csv", table), tiago, write_mapping(tmp_path / "m.yaml", spec))
    assert data.pose_ids.tolist() == [0, 1, 2]
    assert data.w[:, 2].tolist() == [1.0, 2.0, 3.0] and not data.w[:, [0, 1, 3, 4, 5]].any()
    assert [tiago.target_names[t] for t in data.target[:2]] == ["m3", "m1"]  # mapping order
    assert data.xyz[0].tolist() == [float(table[c][0]) for c in ("x3", "y3", "z3")]


def test_a_table_in_degrees_and_millimetres_converts_to_rad_and_m(tiago, tmp_path):
    """The same poses written as a controller exports them (revolute readings in deg; the prismatic
    torso lift and the points in mm) import to the same numbers as the table in rad and m."""
    table = wide_table(tiago)
    plain = import_wide(write_table(tmp_path / "t.csv", table), tiago,
                        write_mapping(tmp_path / "m.yaml", shipped_mapping()))
    prismatic = [j.kind == "P" for j in tiago.joints]
    assert any(prismatic) and not all(prismatic)
    for col, p in zip(shipped_mapping()["joints"].values(), prismatic):
        table[col] = [repr(float(v) * (1e3 if p else 180 / np.pi)) for v in table[col]]
    for col in (c for c in table if c[0] in "xyz" and c[1:].isdigit()):
        table[col] = [repr(float(v) * 1e3) for v in table[col]]
    converted = import_wide(write_table(tmp_path / "u.csv", table), tiago,
                            write_mapping(tmp_path / "u.yaml", shipped_mapping() | {"units": {"angles": "deg",
                                                                                              "lengths": "mm"}}))
    np.testing.assert_allclose(converted.q, plain.q, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(converted.xyz, plain.xyz, rtol=1e-12, atol=1e-15)


def cell(column: str, text: str):
    """Table edit: the second data row (file row 3) of `column` becomes `text`."""
    return lambda table: table[column].__setitem__(1, text)


def add_column(name: str):
    return lambda table: table.update({name: ["1"] * len(table["x1"])})


def pose_column(spec: dict):
    """Mapping edit: pose ids from shipped_row instead of the row number."""
    spec["pose"] = "shipped_row"
    spec["ignore"].remove("shipped_row")


BAD = {
    # name: (table edit, mapping edit, expected message part)
    "missing column": (lambda t: t.pop("z4"), None, "row 1: no column 'z4'"),
    "NaN": (cell("y2", "nan"), None, "row 3, column 'y2': 'nan' is not finite"),
    "empty cell": (cell("arm_3_joint", ""), None, "row 3, column 'arm_3_joint': '' is not a number"),
    "unused column": (add_column("temp_c"), None, "column 'temp_c' is neither mapped nor ignored"),
    "unknown target": (None, lambda s: s["targets"].update(m9=["x1", "y1", "z1"]), "'m9' is not a target of tiago"),
    "target with two columns": (None, lambda s: s["targets"].update(m1=["x1", "y1"]), "targets.m1: expected three"),
    "unknown joint": (None, lambda s: s["joints"].update(arm_9_joint="arm_7_joint"), "'arm_9_joint' is not a joint"),
    "unmapped joint": (None, lambda s: s["joints"].pop("arm_7_joint"), "no column for q8 (arm_7_joint)"),
    "joint mapped twice": (None, lambda s: s["joints"].update(q1="torso_lift_joint"), "'q1' is mapped twice"),
    "column used twice": (None, lambda s: s["targets"].update(m2=["x1", "y2", "z2"]), "column 'x1' is used twice"),
    "mapped and ignored": (None, lambda s: s["ignore"].append("x1"), "column 'x1' is used twice"),
    "aux with a contract name": (add_column("x"), lambda s: s["aux"].append("x"), "aux: 'x' cannot be an auxiliary"),
    "unknown key": (None, lambda s: s.update(columns={}), "unknown key 'columns'"),
    "unknown unit": (None, lambda s: s.update(units={"angles": "grad"}), "units.angles: 'grad'; use rad or deg"),
    "unknown unit key": (None, lambda s: s.update(units={"forces": "kN"}), "unknown key 'forces'"),
    "repeated pose id": (cell("shipped_row", "0"), pose_column, "row 3, column 'shipped_row': pose id repeats"),
    "fractional pose id": (cell("shipped_row", "1.5"), pose_column, "row 3, column 'shipped_row': not an integer"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_tables_and_mappings_are_refused_with_one_line(tiago, tmp_path, case):
    edit_table, edit_mapping, expect = BAD[case]
    table, spec = wide_table(tiago), shipped_mapping()
    if edit_table:
        edit_table(table)
    if edit_mapping:
        edit_mapping(spec)
    with pytest.raises(ModelError) as err:
        import_wide(write_table(tmp_path / "t.csv", table), tiago, write_mapping(tmp_path / "m.yaml", spec))
    message = str(err.value)
    assert expect in message and "\n" not in message, message


def test_shipped_mapping_reads_a_valid_table_and_the_command_fails_in_one_line(tiago, tmp_path, capsys):
    table = write_table(tmp_path / "t.csv", wide_table(tiago))
    assert import_wide(table, tiago, load_mapping(MAPPING, tiago)).n_poses == 3
    bad = wide_table(tiago, {"temp_c": ["20"] * 3})  # a column the mapping does not know
    code = main(["import", str(ROBOTS / "tiago.yaml"), str(write_table(tmp_path / "b.csv", bad)), "--mapping",
                 str(MAPPING), "-o", str(tmp_path / "out.csv"), "--json"])
    captured = capsys.readouterr()
    assert code == 2 and captured.out == "" and len(captured.err.strip().splitlines()) == 1
    assert "temp_c" in captured.err and not (tmp_path / "out.csv").exists()


# -- exports with other separators and decimal commas ----------------------------------------------
def delimited(table: dict[str, list], sep: str, decimal: str = ",") -> str:
    """The table as a spreadsheet may write it: `sep` between columns, `decimal` the decimal mark
    (a European one by default)."""
    return "".join(sep.join(row) + "\n" for row in [list(table), *zip(*table.values())]).replace(".", decimal)


def with_point(table: dict[str, list]) -> str:
    """A decimal-comma export whose first x1 cell has a decimal point instead."""
    return delimited(table, ";").replace(table["x1"][0].replace(".", ","), "0.5", 1)


@pytest.mark.parametrize("sep, option", [(";", ";"), ("\t", "tab"), ("|", "|")])
def test_an_export_with_decimal_commas_imports_as_the_plain_table(tiago, tmp_path, capsys, sep, option):
    table = wide_table(tiago, rows=5)
    table["x2"][1], table["y3"][2], table["z4"][0] = "-1.5e-05", "-0.25", "2"  # exponent, sign, integer
    plain = import_wide(write_table(tmp_path / "plain.csv", table), tiago, MAPPING)
    path = tmp_path / "export.csv"
    path.write_text(delimited(table, sep))
    data = import_wide(path, tiago, MAPPING, sep=sep, decimal=",")
    with mock.patch("gecgen.model.table._plain_columns", return_value=None):  # the csv module's reading
        careful = import_wide(path, tiago, MAPPING, sep=sep, decimal=",")
    for key in ("q", "w", "aux", "pose_ids", "pose", "target", "xyz"):
        assert getattr(data, key).tolist() == getattr(plain, key).tolist() == getattr(careful, key).tolist(), key
    # the command writes the contract's file (commas, decimal points), the same as from the plain table
    for name, source, options in (("a.csv", tmp_path / "plain.csv", []), ("b.csv", path, ["--sep", option, "--decimal", ","])):
        assert main(["import", str(ROBOTS / "tiago.yaml"), str(source), "--mapping", str(MAPPING), *options,
                     "-o", str(tmp_path / name), "--json"]) == 0
    capsys.readouterr()
    assert (tmp_path / "b.csv").read_bytes() == (tmp_path / "a.csv").read_bytes()
    assert read_measurements(tmp_path / "b.csv", tiago).xyz.tolist() == plain.xyz.tolist()


EXPORTS = {
    # name: (file text from the wide table, import options, expected message part)
    "point beside decimal commas": (with_point, ["--sep", ";", "--decimal", ","],
                                    "row 2, column 'x1': '0.5' is not a number with the decimal mark ','; fix the value"),
    "semicolons without --sep": (lambda t: delimited(t, ";"), [],
                                 "row 1: the columns are separated by ';'; gecgen reads comma-separated files: convert "
                                 "the file to commas (a wide export converts with gecgen import --sep ';' --decimal ',')"),
    "commas with --sep ';'": (lambda t: delimited(t, ",", "."), ["--sep", ";"],
                              "row 1: the columns are separated by ',', not ';'; give the file's separator (--sep ',')"),
    "tabs with --sep ';'": (lambda t: delimited(t, "\t"), ["--sep", ";", "--decimal", ","],
                            "the columns are separated by tabs, not ';'; give the file's separator (--sep tab)"),
    "decimal comma and comma separator": (lambda t: delimited(t, ";"), ["--decimal", ","],
                                          "--sep ',' --decimal ',': a comma cannot both separate the columns"),
    "unknown separator": (lambda t: delimited(t, ";"), ["--sep", ":"], "--sep ':': give ',', ';', tab or '|'"),
}


@pytest.mark.parametrize("case", EXPORTS)
def test_exports_read_with_the_wrong_options_are_refused_in_one_line(tiago, tmp_path, capsys, case):
    make, options, expect = EXPORTS[case]
    path = tmp_path / "export.csv"
    path.write_text(make(wide_table(tiago)))
    code = main(["import", str(ROBOTS / "tiago.yaml"), str(path), "--mapping", str(MAPPING), *options,
                 "-o", str(tmp_path / "out.csv"), "--json"])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2 and captured.out == "" and len(lines) == 1 and expect in lines[0], captured.err
    assert not (tmp_path / "out.csv").exists()
