"""Every function the emitters print for one robot and error model."""
from __future__ import annotations

import sympy as sp

from gecgen.model.errors import ErrorModel
from gecgen.model.robot import WRENCH, Robot
from gecgen.symbolic.chain import fk_function, jacobian_function, targets_function, tool_jacobian_function
from gecgen.symbolic.loads import load_values, loads_function
from gecgen.symbolic.parse import joint_symbols, load_symbol, term_expressions
from gecgen.symbolic.program import Builder, Function


def basis_function(robot: Robot, model: ErrorModel, loads_given: bool = False) -> Function:
    """Values f (n_terms) of the distinct basis terms at joints q, wrench w (6) and aux signals.

    The load signals the terms use are computed from q and w on the nominal chain, or, with
    `loads_given`, read from an input L (every signal of the robot, as `loads` returns them):
    compensation holds them at the command's values while it moves the joints."""
    b = Builder()
    q = joint_symbols(robot)
    w = tuple(sp.Symbol(n, real=True) for n in WRENCH)
    aux = tuple(sp.Symbol(n, real=True) for n in model.aux)
    expr = term_expressions(robot, model)
    terms = model.unique_terms()
    names = model.load_signals(robot)
    if loads_given:
        L = tuple(load_symbol(n) for n in names)
        f = [b.let(expr[t.text]) for t in terms]
        return b.function("basis_at_loads", f"Basis terms f as {robot.name}_basis computes them, with the load "
                          f"signals L ({robot.name.upper()}_NL, as {robot.name}_loads returns them) given instead of "
                          f"computed from q and w.", {"q": q, "w": w, "aux": aux, "L": L}, {"f": f})
    values = load_values(b, robot, q, w, names)
    f = [b.let(expr[t.text].xreplace(values)) for t in terms]
    return b.function("basis", "Distinct basis terms f of the error model at joints q, wrench w "
                      "(fx fy fz mx my mz) and auxiliary signals aux.", {"q": q, "w": w, "aux": aux}, {"f": f})


def chain_functions(robot: Robot) -> list[Function]:
    """The robot's own functions, the same for every error model: fk, the targets, J_e and the tool
    Jacobian (on a tree, fk and tool_jacobian once per branch: `fk_left`, ...). They are nearly all
    of the symbolic work, which is why `runtime.compiled` keeps their printed code per robot."""
    branches = range(len(robot.tips()))
    return [*(fk_function(robot, b) for b in branches), targets_function(robot), jacobian_function(robot),
            *(tool_jacobian_function(robot, b) for b in branches)]


def model_functions(robot: Robot, model: ErrorModel) -> list[Function]:
    """The error model's functions: its basis terms, and the load signals its terms use."""
    return [basis_function(robot, model), loads_function(robot, model.load_signals(robot)),
            basis_function(robot, model, loads_given=True)]


def all_functions(robot: Robot, model: ErrorModel) -> list[Function]:
    """Every generated function, the chain's first."""
    return [*chain_functions(robot), *model_functions(robot, model)]
