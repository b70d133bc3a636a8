"""Exact numbers of robot files, without a computer-algebra system.

A robot's constants are kept exact so that the symbolic chain prunes exact zeros and 90 degrees
stays pi/2 (`symbolic.exact` turns them into sympy numbers); everything numeric reads them with
`float()`. A number is one of:

- `int`: an integer of a robot file, or a URDF axis component or `<mimic>` number that is one;
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
        if abs(self.power) != 1:
            raise ValueError(f"{self}: only factor * pi or factor / pi come from robot files")
        prec = 53 + 4  # float() is sympy's evalf at 53 bits: evaluated with 4 guard bits, then rounded
        if self.factor == 1:
            man, exp = _pi_power(self.power, prec)
        else:  # evalf of a product of two: each factor at prec + 2 + 5 bits, the exact product rounded
            work = prec + 2 + 5
            fm, fe = _bits(abs(self.factor.numerator), self.factor.denominator, work)
            pm, pe = _pi_power(self.power, work)
            man, exp = _round(fm * pm, fe + pe, prec)
        man, exp = _round(man, exp, 53)
        return math.copysign(math.ldexp(man, exp), self.factor)

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


#: pi to 83 decimals (an integer over 10**83): far more bits than the 69 that `_pi_power` takes
_PI_DIGITS = 314159265358979323846264338327950288419716939937510582097494459230781640628620899863


def _bits(p: int, q: int, prec: int) -> tuple[int, int]:
    """p / q (p, q > 0) rounded toward zero to prec bits: (mantissa, exponent) (mpmath's round_fast)."""
    shift = prec - (p.bit_length() - q.bit_length()) + 1
    man = (p << shift) // q if shift >= 0 else p // (q << -shift)
    extra = man.bit_length() - prec
    return man >> extra, extra - shift


def _round(man: int, exp: int, prec: int) -> tuple[int, int]:
    """man * 2**exp rounded to prec bits, to nearest, ties to even (mpmath's round_nearest)."""
    extra = man.bit_length() - prec
    if extra <= 0:
        return man, exp
    kept, rest = man >> extra, man & ((1 << extra) - 1)
    half = 1 << (extra - 1)
    if rest > half or rest == half and kept & 1:
        kept += 1
    return kept, exp + extra


def _pi_power(power: int, prec: int) -> tuple[int, int]:
    """sympy's evalf of pi (power 1) or 1/pi (power -1) at prec bits: pi rounded toward zero, and 1/pi
    the quotient of 1 by pi at prec + 5 bits, rounded toward zero."""
    if power == 1:
        return _bits(_PI_DIGITS, 10 ** 83, prec)
    pm, pe = _bits(_PI_DIGITS, 10 ** 83, prec + 5)  # pi = pm * 2**pe, pe < 0
    return _bits(1 << -pe, pm, prec)


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
    """The length of a vector of exact rationals (gravity), rounded once (sympy's float of the same
    square root can differ in the last bit; this length only scales a rank tolerance)."""
    square = sum(Fraction(v) ** 2 for v in vector)
    with decimal.localcontext() as ctx:
        ctx.prec = 60
        return float((decimal.Decimal(square.numerator) / decimal.Decimal(square.denominator)).sqrt())
