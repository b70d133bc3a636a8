"""The basis terms of an error model evaluated in numpy, from their term text (batched over poses).

A term's label is term-language text (`model.errors`) that reads back into that one term
(`symbolic.parse.term_expressions` relies on it too: poly and fourier labels are their expanded
terms, a gravity shorthand's labels its columns). Its syntax tree is walked here with numpy's
functions in place of sympy's: the same values the generated code computes from sympy's form, to
rounding. The load signals come from `model.loads.signal_values`, on the nominal chain as in the
generated code. Text is never evaluated as Python.
"""
from __future__ import annotations

import ast

import numpy as np

from gecgen.model.errors import ErrorModel
from gecgen.model.loads import LOAD_FUNCTIONS, LoadTerms, signal_values
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.validation import ModelError, excerpt

FUNCTIONS = {"sin": np.sin, "cos": np.cos, "sign": np.sign, "abs": np.abs, "sqrt": np.sqrt}
OPERATORS = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power}


def basis_values(robot: Robot, model: ErrorModel, q: np.ndarray, w: np.ndarray, aux: np.ndarray | None,
                 signals: np.ndarray | None = None) -> np.ndarray:
    """The distinct basis terms f (N, nf) (`model.unique_terms()` order) at joints q (N, n) (m or
    rad), wrenches w (N, 6) (N, N m) and auxiliary signals aux (N, len(model.aux)) (None when the
    model uses none). signals: the load signals `model.load_signals(robot)` (N, L) given instead of
    computed from q and w (the generated basis_at_loads: compensation holds them at the command's)."""
    q = np.atleast_2d(np.asarray(q, float))
    N = len(q)
    values = {f"q{i + 1}": q[:, i] for i in range(robot.n)}
    values.update({j.name: q[:, i] for i, j in enumerate(robot.joints)})
    values.update({name: np.asarray(w, float)[:, k] for k, name in enumerate(WRENCH)})
    values.update({name: np.asarray(aux, float)[:, k] for k, name in enumerate(model.aux)})
    variables = {f"q{i + 1}": f"q{i + 1}" for i in range(robot.n)}
    variables.update({j.name: f"q{i + 1}" for i, j in enumerate(robot.joints)})
    loads = LoadTerms(robot, variables)
    # a load signal's name is a call (the catalog, whose rank tests take a while, only when one is used)
    used = model.load_signals(robot) if any("(" in v for v in model.variables()) else []
    if used:
        values.update(zip(used, (signal_values(robot, q, w, used) if signals is None else np.asarray(signals, float)).T))
    where = model.source or "<error model>"

    def fail(text, why):
        raise ModelError(f"{where}: term {excerpt(text)}: {why}")

    def value(text: str, node) -> np.ndarray | float:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return float(node.value)
        if isinstance(node, ast.Name) and node.id == "pi":
            return np.pi
        if isinstance(node, ast.Name) and node.id in values:
            return values[node.id]
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            v = value(text, node.operand)
            return -v if isinstance(node.op, ast.USub) else v
        if isinstance(node, ast.BinOp) and type(node.op) in OPERATORS:
            return OPERATORS[type(node.op)](value(text, node.left), value(text, node.right))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS \
                and len(node.args) == 1 and not node.keywords:
            return FUNCTIONS[node.func.id](value(text, node.args[0]))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in LOAD_FUNCTIONS:
            return values[loads.name(text, node, fail)]
        fail(text, f"{excerpt(ast.unparse(node))} is not a term of this model; read the error-model file again")

    f = np.empty((N, len(model.unique_terms())))
    with np.errstate(all="ignore"):  # a root of a negative number is NaN, as in the generated C
        for k, t in enumerate(model.unique_terms()):
            f[:, k] = value(t.label, ast.parse(t.label.strip(), mode="eval").body)
    return f
