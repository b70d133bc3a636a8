"""Error-model files: which basis terms f(q, w, aux) multiply each generalized error.

`eps_e = sum_j c_j f_j(q, w, aux)` (the seed paper's Eq. 5). Terms are parsed from a whitelist of
Python expression syntax (numbers, variables, + - * / **, sin, cos, sqrt, sign, abs, the load
signals of `model.loads` and the shorthands poly, fourier and gravity) by `symbolic.terms`, which
builds their expressions; user text is never evaluated. The nouns live here: a term is its
canonical text, its label and the variables it uses, so a model is read back from the cache, and
fitted, without a computer-algebra system.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from gecgen.model.loads import catalog
from gecgen.model.orientation import PREFIXES as ORIENTATION_PREFIXES
from gecgen.model.robot import ERROR_NAMES, RESERVED, WRENCH, Robot
from gecgen.model.validation import is_name

MAX_TERM_LENGTH = 200
MAX_EXPONENT = 16
#: constants in terms stay within 2**+-MAX_LOG2, inside double precision with room for products
MAX_LOG2 = 1000
#: a term's numbers stay within 1/MAX_SCALE..MAX_SCALE in magnitude: scale factors and periods of
#: any unit fit, and products of the fit's columns stay well inside double precision
MAX_SCALE = 1e12
ALLOWED = "use numbers, variables, + - * / **, sin, cos, sqrt, sign, abs, poly, fourier and the load signals"


@dataclass(frozen=True)
class Term:
    """One basis function. `text` is its canonical spelling in the variables q1..qn, fx.., aux (the
    identity of the term); `label` is how the model file spells it (what people read in names);
    `variables` the names of the joints, wrench components, aux and load signals it uses."""

    text: str
    label: str
    variables: tuple[str, ...] = ()


@dataclass(frozen=True)
class Coefficient:
    """One unknown c_j: the generalized error it scales (index into eps) and its term."""

    error: int
    term: Term

    def name(self, robot: Robot) -> str:
        return f"{robot.error_names()[self.error]}:{self.term.label}"


@dataclass(frozen=True)
class ErrorModel:
    """Terms per generalized error, in eps order; `aux` lists the auxiliary data columns used."""

    terms: tuple[tuple[Term, ...], ...]
    aux: tuple[str, ...]
    source: str = ""
    source_hash: str = ""

    @property
    def coefficients(self) -> list[Coefficient]:
        return [Coefficient(e, t) for e, terms in enumerate(self.terms) for t in terms]

    def coefficient_names(self, robot: Robot) -> list[str]:
        return [c.name(robot) for c in self.coefficients]

    def variables(self) -> set[str]:
        """The names of the variables (joints, wrench components, aux signals) its terms use."""
        return {v for t in self.unique_terms() for v in t.variables}

    def load_signals(self, robot: Robot) -> list[str]:
        """The load signals its terms use, in the robot's catalog order (`model.loads`): the ones its
        generated code computes (NAME_loads, NAME_NL)."""
        used = self.variables()
        return [name for name in catalog(robot).names if name in used]

    def unique_terms(self) -> list[Term]:
        """Distinct basis functions in first-use order: the generated code evaluates each once."""
        seen: dict[str, Term] = {}
        for terms in self.terms:
            for t in terms:
                seen.setdefault(t.text, t)
        return list(seen.values())

    def to_yaml_dict(self, robot: Robot) -> dict:
        """A dict that `load_error_model` reads back into this model, terms spelled as written:
        `default: ["1"]` and, under `frames`, only the errors whose terms differ from it."""
        frames: dict[int, dict[str, list[str]]] = {}
        for i in range(robot.n_frames + 1):
            for k, e in enumerate(ERROR_NAMES):
                labels = [t.label for t in self.terms[6 * i + k]]
                if labels != ["1"]:
                    frames.setdefault(i, {})[e] = labels
        out: dict = {"default": ["1"], "frames": frames}
        if self.aux:
            out["aux"] = list(self.aux)
        return out


def is_aux_name(name: str) -> bool:
    """Auxiliary columns become C and Python identifiers next to the generated temporaries; the
    prefixes of orientation columns are not theirs."""
    return (is_name(name) and not name.startswith(("_", *ORIENTATION_PREFIXES)) and name not in RESERVED
            and not re.fullmatch(r"[tq]\d+", name))


def variable_names(robot: Robot, aux: tuple[str, ...]) -> dict[str, str]:
    """The names a term may use -> the variable each stands for: q1..qn, joint names as aliases of
    theirs, the wrench components and the aux columns (themselves)."""
    names = {f"q{i + 1}": f"q{i + 1}" for i in range(robot.n)}
    names.update({j.name: f"q{i + 1}" for i, j in enumerate(robot.joints)})
    names.update({w: w for w in (*WRENCH, *aux)})
    return names
