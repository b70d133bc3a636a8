"""Straight-line symbolic programs: the form every emitter prints.

A `Function` is a list of assignments `t_k = expr(inputs, t_<k)` and named outputs. Building the
chain through `Builder.let` names every non-trivial intermediate once, so common subexpressions
are shared by construction (no global CSE pass over huge trees is needed) and exact zeros of
the constant transforms vanish while building.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp


@dataclass(frozen=True)
class Function:
    """inputs: name -> symbols (a flat array each); outputs: name -> expressions (flat, row-major)."""

    name: str
    doc: str
    inputs: dict[str, tuple[sp.Symbol, ...]]
    assignments: tuple[tuple[sp.Symbol, sp.Expr], ...]
    outputs: dict[str, tuple[sp.Expr, ...]]

    def evaluate(self, **values) -> dict[str, np.ndarray]:
        """Evaluate with sympy in floating point, one input set (the reference for C and CasADi)."""
        env: dict = {}
        for name, syms in self.inputs.items():
            vals = np.asarray(values[name], float).ravel()
            env.update({s: sp.Float(float(v), 30) for s, v in zip(syms, vals)})
        for sym, expr in self.assignments:
            env[sym] = sp.Float(expr.xreplace(env).evalf(30), 30)
        return {name: np.array([float(sp.sympify(e).xreplace(env).evalf(30)) for e in exprs])
                for name, exprs in self.outputs.items()}


class Builder:
    """Collects assignments; `let` names an expression unless it is already trivial."""

    def __init__(self, prefix: str = "t"):
        self.prefix = prefix
        self.assignments: list[tuple[sp.Symbol, sp.Expr]] = []
        self._cache: dict[sp.Expr, sp.Symbol] = {}

    def let(self, expr) -> sp.Expr:
        expr = sp.sympify(expr)
        if expr.is_number:
            return sp.Float(sp.N(expr, 17), 17) if not expr.is_Integer else expr
        if expr.is_Symbol or (expr.is_Mul and len(expr.args) == 2 and expr.args[0] == -1 and expr.args[1].is_Symbol):
            return expr
        expr = _numeric(expr)
        if expr in self._cache:
            return self._cache[expr]
        sym = sp.Symbol(f"{self.prefix}{len(self.assignments)}", real=True)
        self.assignments.append((sym, expr))
        self._cache[expr] = sym
        return sym

    def function(self, name: str, doc: str, inputs: dict, outputs: dict) -> Function:
        """Freeze into a Function, dropping assignments no output needs (C warns on unused ones)."""
        outputs = {k: tuple(_numeric(sp.sympify(e)) for e in v) for k, v in outputs.items()}
        needed = set().union(*(e.free_symbols for v in outputs.values() for e in v)) if outputs else set()
        kept = []
        for sym, expr in reversed(self.assignments):
            if sym in needed:
                kept.append((sym, expr))
                needed |= expr.free_symbols
        kept.reverse()
        # renumber densely so the printed code does not depend on what was pruned
        rename = {sym: sp.Symbol(f"{self.prefix}{k}", real=True) for k, (sym, _) in enumerate(kept)}
        kept = tuple((rename[s], e.xreplace(rename)) for s, e in kept)
        outputs = {k: tuple(e.xreplace(rename) for e in v) for k, v in outputs.items()}
        return Function(name, doc, inputs, kept, outputs)


def _numeric(expr: sp.Expr) -> sp.Expr:
    """Exact irrational constants (pi, sqrt(2)) become floats; integers and symbols stay."""
    if any(a.is_number and not a.is_Integer and not a.is_Float for a in sp.preorder_traversal(expr)):
        return sp.N(expr, 17)
    return expr
