"""What every language printer shares: mapping input symbols to array elements."""
from __future__ import annotations

import sympy as sp

from gecgen.symbolic.program import Function


def array_symbols(fn: Function, element) -> dict:
    """Input symbol -> Symbol printed as that array element, e.g. q2 -> `element("q", 1)`."""
    return {s: sp.Symbol(element(name, k), real=True) for name, syms in fn.inputs.items() for k, s in enumerate(syms)}


def straight_line(fn: Function, printer, element) -> tuple[list[tuple[str, str]], dict[str, list[str]]]:
    """(temporaries [(name, code)], outputs {name: [code per element]}) in the printer's language."""
    sub = array_symbols(fn, element)
    temps = [(str(s), printer.doprint(e.xreplace(sub))) for s, e in fn.assignments]
    outs = {k: [printer.doprint(sp.sympify(e).xreplace(sub)) for e in v] for k, v in fn.outputs.items()}
    return temps, outs
