"""Exact numbers of robot files, without a computer-algebra system.

A robot's constants are kept exact so that the symbolic chain prunes exact zeros and 90 degrees
stays pi/2 (`symbolic.exact` turns them into sympy numbers); everything numeric reads them with
`float()`. A number is one of:

- `int`: an integer of a robot file, or a URDF number that is an integer;
- `fractions.Fraction`: a decimal of a robot file, exactly as written (0.1 is 1/10);
- `float`: any other URDF number (printed with 17 significant digits);
- `PiMultiple`: a rational multiple of a power of pi (an angle in degrees; a coupling between a
  revolute and a prismatic joint in a file in degrees).
"""
from __future__ import annotations

import decimal
import math
from dataclasses import dataclass
from fractions import Fraction


@dataclass(frozen=True)
class PiMultiple:
    """factor * pi**power, exact; power is never 0 and factor never 0 (those are plain Fractions)."""

    factor: Fraction
    power: int

    def __float__(self) -> float:
        """As sympy's float() of factor * pi**power rounds it (not always the nearest double): joint
        limits and constants in degrees keep the values they have always had, to the last bit."""
        from mpmath import libmp  # sympy's arithmetic, without sympy; only robots in degrees need it

        def pi_power(prec: int):  # sympy's evalf of pi**power at prec bits (evalf_pow; pi rounds down)
            if self.power == 1:
                return libmp.mpf_pi(prec)
            base = libmp.mpf_pi(prec + int(math.log2(abs(self.power))) + 5)
            return libmp.mpf_pow_int(base, self.power, prec)

        prec = 53 + 4  # float() is evalf() at 53 bits, evaluated with 4 guard bits and rounded
        if self.factor == 1:
            value = pi_power(prec)
        else:  # evalf_mul: two factors at prec + 2 + 5 bits, their exact product rounded
            work = prec + 2 + 5
            factor = libmp.from_rational(self.factor.numerator, self.factor.denominator, work)
            sign, man, exp, _ = libmp.mpf_mul(factor, pi_power(work))
            value = libmp.normalize(sign, man, exp, libmp.bitcount(man), prec, libmp.round_nearest)
        sign, man, exp, bc = value
        return libmp.to_float(libmp.normalize(sign, man, exp, bc, 53, libmp.round_nearest))

    def __mul__(self, other):
        a, b = _parts(self), _parts(other)
        return pi_multiple(a[0] * b[0], a[1] + b[1])

    __rmul__ = __mul__

    def __truediv__(self, other):
        a, b = _parts(self), _parts(other)
        return pi_multiple(a[0] / b[0], a[1] - b[1])

    def __rtruediv__(self, other):
        a, b = _parts(other), _parts(self)
        return pi_multiple(a[0] / b[0], a[1] - b[1])

    def __neg__(self):
        return PiMultiple(-self.factor, self.power)


def _parts(value) -> tuple[Fraction, int]:
    if isinstance(value, PiMultiple):
        return value.factor, value.power
    return Fraction(value), 0


def pi_factor(value) -> Fraction:
    """The rational factor of an exact number (itself, unless it is a multiple of a power of pi)."""
    return _parts(value)[0]


def pi_multiple(factor, power: int):
    """factor * pi**power as the simplest kind of number (a Fraction when power or factor is 0)."""
    factor = Fraction(factor)
    return factor if power == 0 or factor == 0 else PiMultiple(factor, power)


def decimal_number(value: int | float):
    """A robot file's number, exactly as written: an int stays, a float is its decimal (repr)."""
    return Fraction(repr(value)) if isinstance(value, float) else value


def degrees(value):
    """An exact angle in degrees as an exact angle in rad (value * pi / 180)."""
    return pi_multiple(Fraction(value) / 180, 1)


def exact_norm(vector) -> float:
    """The length of a vector of exact rationals (gravity), rounded once."""
    square = sum(Fraction(v) ** 2 for v in vector)
    with decimal.localcontext() as ctx:
        ctx.prec = 60
        return float((decimal.Decimal(square.numerator) / decimal.Decimal(square.denominator)).sqrt())
