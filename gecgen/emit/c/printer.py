"""C99 printer: doubles everywhere, shortest round-trip literals, small powers as products."""
from __future__ import annotations

import math

from sympy.printing.c import C99CodePrinter


class CPrinter(C99CodePrinter):
    def _print_Float(self, expr):
        text = repr(float(expr))
        return text if any(ch in text for ch in ".eEn") else text + ".0"

    def _print_Integer(self, expr):
        return f"{int(expr)}.0"

    def _print_Pi(self, expr):
        return repr(math.pi)  # M_PI is POSIX, not C99

    def _print_Rational(self, expr):
        return self._print_Float(expr)

    def _print_sign(self, expr):
        # 1, 0 or -1 without a branch (copysign would give 1 at 0, where sign is 0)
        x = self._print(expr.args[0])
        return f"(({x} > 0.0) - ({x} < 0.0))"

    def _print_Pow(self, expr):
        base, exp = expr.args
        if exp.is_Integer and 1 <= abs(int(exp)) <= 4:
            prod = "*".join([self.parenthesize(base, 100)] * abs(int(exp)))
            return prod if exp > 0 else f"(1.0/({prod}))"
        if exp == -1:
            return f"(1.0/{self.parenthesize(base, 100)})"
        return super()._print_Pow(expr)


def element(name: str, k: int) -> str:
    return f"{name}[{k}]"
