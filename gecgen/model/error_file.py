"""An error-model mapping (a model file's content) read into the terms of each generalized error.

Its keys, frame numbers, error names and aux columns are checked here, the coupling ratios added, and
each list of terms handed to a reader: `symbolic.parse.terms_of` reads the term language (it needs
sympy: a term's identity is sympy's canonical text); `simple_terms` reads constants, variables and
their whole powers (the shipped default models), products of those, the sine and cosine of one
variable, and the load functions (`model.loads`: a load signal standing as a term, or as a factor
of a product) without it, writing sympy's canonical text itself, so a first run with such a model
loads no computer algebra.
"""
from __future__ import annotations

import ast
import keyword
import re
from collections.abc import Callable

from gecgen.model.errors import MAX_EXPONENT, MAX_TERM_LENGTH, Term, is_aux_name, variable_names
from gecgen.model.loads import LOAD_FUNCTIONS, LoadTerms
from gecgen.model.robot import ERROR_NAMES, Robot
from gecgen.model.validation import excerpt, is_name, require, require_keys

#: (items, where, robot, variable names) -> the terms of one list
TermReader = Callable[[list, str, Robot, dict], tuple[Term, ...]]


class NeedsParser(Exception):
    """A list of terms that only the term parser reads."""


#: a term that is a variable or a whole power of one, such as "q2" or "q2**2": its canonical text is
#: the variable's name and the power as sympy prints them (`symbolic.parse`)
SIMPLE = re.compile(r"\s*([A-Za-z_]\w*)\s*(?:\*\*\s*(\d+)\s*)?")


#: the functions `simple_terms` reads, of one variable each
TRIGONOMETRIC = ("sin", "cos")


def simple_terms(items: list, where: str, robot: Robot, names: dict) -> tuple[Term, ...]:
    """The terms of a list of constants "1" (or 1), variables and their whole powers 2..MAX_EXPONENT,
    load signals ("gravity_torque(q6)", "gravity(q2)" expanding into its columns), products of
    different such variables and signals ("q2*q3**2", "fx*q2", "q2*wrench_torque(q2)"), and sin or
    cos of one variable, as the term parser reads them (`symbolic.parse.terms_of`: text, label and
    variables; sympy's text puts a product's factors in the order of their variables' names, a
    signal's name its canonical spelling); any other list, and one the parser would refuse, raises
    NeedsParser."""
    loads = LoadTerms(robot, names)
    out: dict[str, Term] = {}
    for item in items:
        if type(item) is int and item == 1 or item == "1":
            terms = [Term("1", "1", ())]
        elif type(item) is not str or len(item) > MAX_TERM_LENGTH:
            raise NeedsParser(where)
        elif found := SIMPLE.fullmatch(item):
            variable, power = _factor(found.group(1), found.group(2), names, where)
            terms = [Term(variable + (f"**{power}" if power > 1 else ""), item.strip(), (variable,))]
        else:
            terms = _composite(item, names, loads, where)
        for term in terms:
            if term.text in out:
                raise NeedsParser(where)  # the parser says which term repeats
            out[term.text] = term
    return tuple(out.values())


def _factor(name: str, power: str | None, names: dict, where: str) -> tuple[str, int]:
    """(the variable, its power) of a variable `name` to `power` (text, None for 1); NeedsParser for a
    name that is no variable or a power the parser refuses."""
    if name not in names or name == "pi" or not name.isascii() or keyword.iskeyword(name) \
            or power and not 2 <= int(power) <= MAX_EXPONENT:
        raise NeedsParser(where)
    return names[name], int(power) if power else 1


def _refused(where: str):
    """The load functions' `fail(text, why)`: the parser says why (`simple_terms`)."""
    def fail(text, why):
        raise NeedsParser(where)
    return fail


def _composite(item: str, names: dict, loads: LoadTerms, where: str) -> list[Term]:
    """The terms of a load signal, of the gravity shorthands (one per column, labelled as the parser
    labels them), of a product of different variables and signals, each to a whole power, or of sin
    or cos of one variable (`simple_terms`); NeedsParser for anything else."""
    try:
        tree = ast.parse(item.strip(), mode="eval").body
    except (SyntaxError, ValueError):
        raise NeedsParser(where) from None
    if loads.is_shorthand(tree):
        return [Term(name, label, (name,)) for name, label in loads.expand(item, tree, _refused(where))]
    return [_product_or_trigonometric(item, tree, names, loads, where)]


def _load_call(node) -> bool:
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in LOAD_FUNCTIONS


def _product_or_trigonometric(item: str, tree, names: dict, loads: LoadTerms, where: str) -> Term:
    """The term of `tree`, the parsed item: a load signal, a product of different variables and
    signals, each to a whole power, or sin or cos of one variable; NeedsParser for anything else."""
    if _load_call(tree):
        name = loads.name(item, tree, _refused(where))
        return Term(name, item.strip(), (name,))
    if isinstance(tree, ast.Call) and isinstance(tree.func, ast.Name) and tree.func.id in TRIGONOMETRIC \
            and len(tree.args) == 1 and not tree.keywords and isinstance(tree.args[0], ast.Name):
        variable, _ = _factor(tree.args[0].id, None, names, where)
        return Term(f"{tree.func.id}({variable})", item.strip(), (variable,))
    factors, stack = [], [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult):
            stack += [node.right, node.left]
        elif isinstance(node, ast.Name):
            factors.append(_factor(node.id, None, names, where))
        elif _load_call(node) and not loads.is_shorthand(node):
            factors.append((loads.name(item, node, _refused(where)), 1))
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow) and isinstance(node.left, ast.Name) \
                and isinstance(node.right, ast.Constant) and type(node.right.value) is int:
            factors.append(_factor(node.left.id, str(node.right.value), names, where))
        else:
            raise NeedsParser(where)
    variables = sorted(v for v, _ in factors)
    if len(factors) < 2 or len(set(variables)) < len(variables):
        raise NeedsParser(where)  # one variable twice: the parser multiplies the powers out
    text = "*".join(v + (f"**{k}" if k > 1 else "") for v, k in sorted(factors))
    return Term(text, item.strip(), tuple(variables))


def read_model(spec, robot: Robot, where: str, aux_columns: tuple[str, ...], read_terms: TermReader
               ) -> tuple[tuple[tuple[Term, ...], ...], tuple[str, ...]]:
    """The terms of each generalized error, and the aux columns used, of an error-model mapping;
    every problem is one line naming `where`, the key and the fix."""
    require(isinstance(spec, dict), f"{where}: expected a mapping with 'default' and/or 'frames'")
    require_keys(spec, where, optional={"default", "frames", "aux", "description"})
    declared = spec.get("aux", [])
    require(isinstance(declared, list) and all(is_name(a) for a in declared),
            f"{where}: aux: expected a list of data column names")
    names = variable_names(robot, ())
    clash = [a for a in declared if a in names or not is_aux_name(a)]
    require(not clash, f"{where}: aux: {excerpt(clash[0]) if clash else ''} is a joint, wrench or reserved name "
                       f"(q, eps, w, aux, c, f, p, J, T, Jq, t<k>); rename the data column")
    aux_all = tuple(dict.fromkeys(list(declared) + [a for a in aux_columns if a not in names and is_aux_name(a)]))
    names = variable_names(robot, aux_all)

    def parse_list(items, w) -> tuple[Term, ...]:
        require(isinstance(items, list), f"{w}: expected a list of terms such as [\"1\", \"q1\"]")
        return read_terms(items, w, robot, names)

    default = parse_list(spec.get("default", ["1"]), f"{where}: default")
    terms = [default] * robot.n_errors
    frames = spec.get("frames") or {}
    require(isinstance(frames, dict), f"{where}: frames: expected a mapping from frame number to terms")
    for key, block in frames.items():
        require(isinstance(key, int) and not isinstance(key, bool) and 0 <= key <= robot.n_frames,
                f"{where}: frames: key {excerpt(key)} is not a frame number 0..{robot.n_frames}")
        fw = f"{where}: frames.{key}"
        if isinstance(block, list):
            terms[6 * key:6 * key + 6] = [parse_list(block, fw)] * 6
            continue
        require(isinstance(block, dict), f"{fw}: expected a list of terms or a mapping from ex..ep to terms")
        for err, items in block.items():
            require(err in ERROR_NAMES, f"{fw}: unknown error {excerpt(str(err))}; use one of {', '.join(ERROR_NAMES)}")
            terms[6 * key + ERROR_NAMES.index(err)] = parse_list(items, f"{fw}.{err}")
    for error, ratios in robot.ratio_terms().items():
        if any(t.text == "1" for t in terms[error]):  # its coupling's offset is modelled: so are its ratios
            have = {t.text for t in terms[error]}
            terms[error] = terms[error] + tuple(Term(r, r, (r,)) for r in ratios if r not in have)
    used = set()
    for ts in terms:
        for t in ts:
            used |= set(t.variables)
    aux = tuple(a for a in aux_all if a in used or a in declared)
    require(any(terms), f"{where}: the model has no terms at all")
    return tuple(terms), aux
