"""Property tests of the two parsers of user text: error terms and measurement CSVs. Whatever they
are given, they either accept it as finite numbers and bounded powers or refuse it with a ModelError
of one line; nothing else escapes."""
import math
from unittest import mock

import numpy as np
import pytest
import sympy as sp
from conftest import ROBOTS
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gecgen.model import ModelError, load_robot
from gecgen.model.errors import MAX_EXPONENT
from gecgen.symbolic.parse import term_expressions
from gecgen.symbolic.terms import error_model_from_dict
from gecgen.model.measurements import read_measurements

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
PPS = load_robot(ROBOTS / "pps.yaml")

# -- terms ------------------------------------------------------------------------------------------
NUMBERS = st.one_of(st.integers(-20, 20).map(str), st.floats(allow_nan=False, allow_infinity=False).map(repr),
                    st.sampled_from(["0", "0.5", "1e308", "1e999", "1e-320", "9" * 60]))
ATOMS = st.one_of(st.sampled_from(["q1", "q2", "q6", "fx", "mz", "temp_c", "pi", "lateral", "q7", "x", "__class__"]),
                  NUMBERS)


def compound(children):
    return st.one_of(
        st.tuples(children, st.sampled_from(["+", "-", "*", "/", "%", "**"]), children).map(lambda t: f"({t[0]}{t[1]}{t[2]})"),
        st.tuples(children, NUMBERS).map(lambda t: f"({t[0]})**{t[1]}"),
        st.tuples(children, st.sampled_from(["-0.5", "1/2", "-1", "16", "17"])).map(lambda t: f"({t[0]})**{t[1]}"),
        st.tuples(st.sampled_from(["sin", "cos", "sqrt", "exp", "poly"]), children).map(lambda t: f"{t[0]}({t[1]})"),
        children.map(lambda c: f"-{c}"),
    )


EXPRESSIONS = st.recursive(ATOMS, compound, max_leaves=10)
TERMS = st.one_of(
    EXPRESSIONS,
    st.tuples(EXPRESSIONS, NUMBERS).map(lambda t: f"poly({t[0]}, {t[1]})"),
    st.tuples(EXPRESSIONS, NUMBERS, NUMBERS).map(lambda t: f"fourier({t[0]}, {t[1]}, {t[2]})"),
    st.text(max_size=40),
    st.text(alphabet="q12 fx+-*/().e09,sincoqrtplyu", max_size=40),
)
YAML_VALUES = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=10)),
                           lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=5), c, max_size=3),
                           max_leaves=8)


def accepted_or_refused(spec):
    """The model error_model_from_dict makes of `spec`, or None when it refuses in one line."""
    try:
        return error_model_from_dict(spec, PPS, "<h>")
    except ModelError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("<h>") and len(str(exc)) < 400, str(exc)
        return None


@SETTINGS
@given(st.lists(TERMS, min_size=1, max_size=3))
def test_terms_are_finite_with_bounded_powers_or_refused(texts):
    model = accepted_or_refused({"aux": ["temp_c"], "frames": {1: texts}})
    exprs = term_expressions(PPS, model) if model else {}
    for term in model.terms[6] if model else ():
        expr = exprs[term.text]
        assert not expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan), term.text
        assert all(math.isfinite(float(n)) for n in expr.atoms(sp.Number)), term.text
        assert all(abs(p.exp) <= MAX_EXPONENT for p in expr.atoms(sp.Pow)), term.text
        for x in expr.free_symbols:
            if expr.is_polynomial(x):
                assert sp.degree(expr, x) <= MAX_EXPONENT, term.text


@SETTINGS
@given(YAML_VALUES)
def test_any_yaml_value_as_a_model_is_accepted_or_refused(value):
    for spec in (value, {"default": value}, {"frames": {1: value}}, {"frames": value}, {"aux": value}):
        accepted_or_refused(spec)


def test_the_term_strategies_reach_both_outcomes():
    """The properties above are not vacuous: the strategies produce accepted and refused terms."""
    outcomes = set()

    @settings(max_examples=100, deadline=None, database=None)
    @given(TERMS)
    def collect(text):
        outcomes.add(accepted_or_refused({"aux": ["temp_c"], "frames": {1: [text]}}) is None)

    collect()
    assert outcomes == {True, False}


# -- measurement CSVs -------------------------------------------------------------------------------
HEADER = ["pose", "q1", "q2", "q3", "q4", "q5", "q6", "fx", "temp_c", "target", "x", "y", "z"]
GOOD_CELLS = {"target": st.sampled_from(["t1", "t2", "t3", "ntp"]),
              **{c: st.floats(-0.05, 0.05).map(repr) for c in HEADER if c not in ("pose", "target")}}
ODD_CELLS = st.one_of(st.sampled_from(["", "nan", "-inf", "1e308", "9007199254740993", "1.5", "t9", " 0.1 ", '"0,1"',
                                       "x" * 200, "\ufeff0"]), st.text(max_size=12))
SEPARATORS = st.sampled_from([",", ",", ",", ";", "\t"])


@st.composite
def tables(draw) -> bytes:
    # a third of the tables are well formed, so that both outcomes are common; the rest break them
    clean = draw(st.integers(0, 2)) == 0
    header = draw(st.permutations(HEADER))
    if not clean and draw(st.booleans()):
        header = draw(st.lists(st.sampled_from(HEADER + ["q7", "mz", "pose"]), min_size=1, max_size=14))
    # pose r on row r keeps most tables consistent; odd cells break them
    rows = [[draw(ODD_CELLS) if not clean and draw(st.integers(0, 19)) == 0
             else str(r) if c == "pose" else draw(GOOD_CELLS.get(c, ODD_CELLS))
             for c in header] for r in range(draw(st.integers(1 if clean else 0, 6)))]
    sep = "," if clean else draw(SEPARATORS)
    text = "\n".join(sep.join(row) for row in [header, *rows]) + "\n"
    data = ("\ufeff" if draw(st.booleans()) else "").encode() + text.encode()
    if not clean and draw(st.integers(0, 4)) == 0:  # a stray byte anywhere
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.binary(min_size=1, max_size=3)) + data[at:]
    return data


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("csv")


def read_or_refuse(path):
    """read_measurements(path) with finite arrays, or None after a one-line refusal naming the file."""
    try:
        data = read_measurements(path, PPS)
    except ModelError as exc:
        message = str(exc)
        assert "\n" not in message and message.startswith(str(path)) and len(message) < 400, message
        return None
    for array in (data.q, data.w, data.aux, data.xyz):
        assert np.isfinite(array).all()
    return data


@SETTINGS
@given(st.one_of(tables(), st.binary(max_size=300)))
def test_csv_reads_as_finite_arrays_or_is_refused_in_one_line(folder, content):
    path = folder / "data.csv"
    path.write_bytes(content)
    read_or_refuse(path)


def test_the_csv_strategy_reaches_both_outcomes(folder):
    outcomes = set()

    @settings(max_examples=150, deadline=None, database=None)
    @given(tables())
    def collect(content):
        path = folder / "reach.csv"
        path.write_bytes(content)
        outcomes.add(read_or_refuse(path) is None)

    collect()
    assert outcomes == {True, False}


# -- the fast reader against the csv module --------------------------------------------------------
# cells and lines that pandas and the csv module might read differently, and a plain file otherwise
EDGE_CELLS = st.sampled_from(["True", "FALSE", "-0", "1_0", "+.5", "5.", " 1e-3 ", "\t2", "inf", "1e999", "0x1",
                              "\uff11", "\x0b1", "", "nan", "1e-400", "0.1000000000000000055511151231257827"])


@st.composite
def near_plain_tables(draw) -> bytes:
    header = draw(st.permutations(HEADER))
    rows = [[draw(EDGE_CELLS) if draw(st.integers(0, 59)) == 0 else str(r) if c == "pose"
             else draw(GOOD_CELLS.get(c, ODD_CELLS)) for c in header] for r in range(draw(st.integers(1, 6)))]
    lines = [",".join(row) for row in [header, *rows]]
    if draw(st.integers(0, 3)) == 0:  # a line one field longer or shorter, or a blank line
        k = draw(st.integers(0, len(lines) - 1))
        lines[k] = draw(st.sampled_from([lines[k] + ",", lines[k] + ",1", lines[k].rpartition(",")[0], ""]))
    end = draw(st.sampled_from(["\n", "\r\n"]))
    return (end.join(lines) + draw(st.sampled_from([end, "", end + end]))).encode()


def outcome(path):
    """What read_measurements makes of a file: its arrays bit for bit, or its message."""
    try:
        data = read_measurements(path, PPS)
    except ModelError as exc:
        return str(exc)
    return [getattr(data, key).tobytes() for key in ("q", "w", "aux", "pose_ids", "pose", "target", "xyz", "station")]


@SETTINGS
@given(st.one_of(near_plain_tables(), tables()))
def test_the_fast_reader_reads_and_refuses_as_the_csv_module(folder, content):
    path = folder / "same.csv"
    path.write_bytes(content)
    with mock.patch("gecgen.model.table._plain_columns", return_value=None):  # the csv module reads every file
        careful = outcome(path)
    with mock.patch("gecgen.model.table.SMALL_BYTES", 0):  # pandas reads every file it can vouch for
        assert outcome(path) == careful


def test_a_wide_table_is_read_by_the_fast_reader(folder):
    """Lines far longer than a cell may be (2,000 extra columns: 24 kB a line) but short cells: the
    fast reader takes it (once, such lines sent every file to the csv module, and each of its columns
    was looked up through the whole header), and reads it as the csv module does."""
    from gecgen.model.table import MAX_CELL, read_table

    rng = np.random.default_rng(0)
    header = ["pose", "target", "x", "y", "z", *[f"q{k + 1}" for k in range(PPS.n)]]
    extra = [f"extra_{k}" for k in range(2000)]
    lines = [",".join(header + extra)]
    for r in range(3):
        cells = [str(r), next(iter(PPS.targets)), "0.5", "0.25", "0.125", *["0.0"] * PPS.n]
        lines.append(",".join(cells + [repr(v) for v in rng.normal(size=len(extra)).tolist()]))
    path = folder / "wide.csv"
    path.write_text("\n".join(lines) + "\n")
    assert max(map(len, lines)) > MAX_CELL
    with mock.patch("gecgen.model.table.SMALL_BYTES", 0):
        assert read_table(path, "measurement file", "", text=("target",))._columns is not None
        fast = outcome(path)
    with mock.patch("gecgen.model.table._plain_columns", return_value=None):
        assert outcome(path) == fast
