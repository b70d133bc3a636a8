"""Python printer for CasADi SX: the same straight-line code with casadi's math functions."""
from __future__ import annotations

from sympy.printing.pycode import PythonCodePrinter


class CasadiPrinter(PythonCodePrinter):
    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_Function(self, expr):
        return f"ca.{expr.func.__name__}({', '.join(self._print(a) for a in expr.args)})"

    _print_sin = _print_cos = _print_sign = _print_Function

    def _print_Abs(self, expr):
        return f"ca.fabs({self._print(expr.args[0])})"

    def _print_Pi(self, expr):
        return "ca.pi"

    def _print_Pow(self, expr):
        base, exp = expr.args
        if exp.is_Rational and exp.q == 2 and exp.p == 1:
            return f"ca.sqrt({self._print(base)})"
        return f"{self.parenthesize(base, 100)}**{self.parenthesize(exp, 100)}"


def element(name: str, k: int) -> str:
    return f"{name}[{k}]"
