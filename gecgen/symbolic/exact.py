"""A robot's exact numbers (`model.exact`) as the sympy numbers the symbolic chain is built from."""
from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import sympy as sp

from gecgen.model.exact import PiMultiple
from gecgen.model.robot import Elementary, Joint, Robot


def sympy_number(value) -> sp.Expr:
    """int -> Integer, Fraction -> Rational, float (a URDF number) -> Float of 17 digits, PiMultiple ->
    Rational * pi**k; a sympy number stays as it is."""
    if isinstance(value, sp.Basic):
        return value
    if isinstance(value, PiMultiple):
        return sp.Rational(value.factor.numerator, value.factor.denominator) * sp.pi ** value.power
    if isinstance(value, Fraction):
        return sp.Rational(value.numerator, value.denominator)
    if isinstance(value, float):
        return sp.Float(value, 17)
    return sp.Integer(value)


def _ops(ops: tuple[Elementary, ...]) -> tuple[Elementary, ...]:
    return tuple((kind, tuple(tuple(sympy_number(v) for v in row) for row in value) if kind == "H"
                  else sympy_number(value)) for kind, value in ops)


def _joint(joint: Joint) -> Joint:
    c = joint.coupling
    return replace(joint, axis=tuple(sympy_number(a) for a in joint.axis), pre=_ops(joint.pre), post=_ops(joint.post),
                   coupling=c and replace(c, terms=tuple((n, sympy_number(m)) for n, m in c.terms),
                                          offset=sympy_number(c.offset)))


def sympy_robot(robot: Robot) -> Robot:
    """The robot with every constant of its chain, tools and gravity a sympy number."""
    return replace(robot, chain=tuple(_joint(j) for j in robot.chain), base=_ops(robot.base), tool=_ops(robot.tool),
                   branches=tuple(replace(b, tool=_ops(b.tool)) for b in robot.branches),
                   gravity=tuple(sympy_number(v) for v in robot.gravity))
