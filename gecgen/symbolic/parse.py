"""The term language parsed into sympy: each term's expression, its canonical text (sympy's, the
term's identity) and the variables it uses; `symbolic.terms` reads model files through it."""
from __future__ import annotations

import ast
import math

import sympy as sp

from gecgen.model.error_file import read_model
from gecgen.model.errors import (ALLOWED, MAX_EXPONENT, MAX_LOG2, MAX_SCALE, MAX_TERM_LENGTH, ErrorModel, Term,
                                 variable_names)
from gecgen.model.loads import LOAD_FUNCTIONS, LoadTerms
from gecgen.model.robot import Robot
from gecgen.model.validation import ModelError, excerpt, require

FUNCTIONS = {"sin": sp.sin, "cos": sp.cos, "sign": sp.sign, "abs": sp.Abs}  # and sqrt, a power


class TermParser:
    """Turns one term string into sympy expressions (a list: poly, fourier and gravity(J) expand)."""

    def __init__(self, symbols: dict[str, sp.Symbol], where: str, loads: LoadTerms):
        self.symbols, self.where, self.loads = symbols, where, loads

    def fail(self, text: str, why: str):
        raise ModelError(f"{self.where}: term {excerpt(text)}: {why}")

    def parse(self, text) -> list[tuple[sp.Expr, str]]:
        """(expression, label) per basis term: one for a plain term, several for poly and fourier."""
        if isinstance(text, (int, float)) and not isinstance(text, bool):
            text = repr(text)
        if not isinstance(text, str):
            self.fail(text, "terms must be strings such as \"q1**2\"")
        if len(text) > MAX_TERM_LENGTH:
            self.fail(text, f"longer than {MAX_TERM_LENGTH} characters")
        try:
            tree = ast.parse(text.strip(), mode="eval").body
        except (SyntaxError, ValueError):  # ValueError: a NUL character
            self.fail(text, f"not a valid expression; {ALLOWED}")
        if isinstance(tree, ast.Call) and isinstance(tree.func, ast.Name) and tree.func.id in ("poly", "fourier"):
            out = self.shorthand(text, tree)
        elif self.loads.is_shorthand(tree):
            out = [(sp.Symbol(name, real=True), label) for name, label in self.loads.expand(text, tree, self.fail)]
        else:
            out = [(self.expr(text, tree), text.strip())]
        for expr, _ in out:
            self.check(text, expr)
        return out

    def check(self, text: str, expr: sp.Expr):
        """Refuse what the generated code could not evaluate: infinities, complex numbers, numbers
        beyond floating point, and powers that nesting or products raised above MAX_EXPONENT."""
        if expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
            self.fail(text, "not finite (a division by zero?); rewrite the term")
        if any(sub.is_number and sub.is_extended_real is False for sub in sp.preorder_traversal(expr)):
            self.fail(text, "complex (a root of a negative number); rewrite the term")
        if any(abs(_log2(n)) > MAX_LOG2 for n in expr.atoms(sp.Number) if n != 0):
            self.fail(text, "holds a number beyond floating point; rewrite the term")
        # a factor only rescales the term's coefficient (fitted in any unit), but one of 1e300 puts
        # the fit's sums of squares beyond double precision: its figures come out as inf or 0
        odd = [n for n in expr.atoms(sp.Number) if n != 0 and abs(_log2(n)) > math.log2(MAX_SCALE)]
        if odd:
            self.fail(text, f"holds the number {float(odd[0]):.3g}, outside {1 / MAX_SCALE:g}..{MAX_SCALE:g} in "
                            f"magnitude: a term's scale is its coefficient's (fitted in any unit); drop the factor")
        for x in sorted(expr.free_symbols, key=str):
            if _degree(expr, x) > MAX_EXPONENT:
                self.fail(text, f"{x} appears to the power {_degree(expr, x):g} (nested powers and products "
                                f"multiply); at most {MAX_EXPONENT}")
        for p in expr.atoms(sp.Pow):
            if abs(p.exp) > MAX_EXPONENT:
                self.fail(text, f"exponent {p.exp} is larger than {MAX_EXPONENT}")

    def power(self, text: str, base: sp.Expr, k: float) -> sp.Expr:
        """base**k, refused before sympy works it out: nested powers multiply ((((2*q1)**16)**16)**16
        holds a number of millions of digits) and exact roots of high order take sympy minutes."""
        if abs(k) > MAX_EXPONENT:
            self.fail(text, f"exponent {k:g} is larger than {MAX_EXPONENT}")
        exponent = sp.Integer(int(k)) if k == int(k) else sp.Rational(repr(k))
        for e in [exponent] + [p.exp * exponent for p in base.atoms(sp.Pow)]:
            if e.q > MAX_EXPONENT:
                self.fail(text, f"a root of order above {MAX_EXPONENT} (nested roots multiply); "
                                f"exponents are multiples of 1/2 .. 1/{MAX_EXPONENT}")
        self.check(text, base)  # a complex or infinite base has no magnitude to bound below
        worst = max((_degree(base, x) for x in base.free_symbols), default=0.0) * abs(k)
        if worst > MAX_EXPONENT:
            self.fail(text, f"a variable appears to the power {worst:g} (nested powers multiply); "
                            f"at most {MAX_EXPONENT}")
        if not base.free_symbols and base != 0 and abs(k) * abs(_log2(base)) > MAX_LOG2:
            self.fail(text, "holds a number beyond floating point; rewrite the term")
        return base ** exponent

    def shorthand(self, text: str, node: ast.Call) -> list[tuple[sp.Expr, str]]:
        if node.keywords:
            self.fail(text, "keyword arguments are not allowed")
        args = node.args
        # how the labels spell the variable: as written, bracketed when it is an expression
        var = (ast.unparse(args[0]) if isinstance(args[0], ast.Name) else f"({ast.unparse(args[0])})") if args else ""
        if node.func.id == "poly":
            if len(args) != 2:
                self.fail(text, "poly takes (variable, order), e.g. poly(q1, 3)")
            v, k = self.expr(text, args[0]), self.number(text, args[1])
            if k != int(k) or not 1 <= k <= MAX_EXPONENT:
                self.fail(text, f"poly order must be an integer 1..{MAX_EXPONENT}")
            return [(self.power(text, v, j), var if j == 1 else f"{var}**{j}") for j in range(1, int(k) + 1)]
        if len(args) != 3:
            self.fail(text, "fourier takes (variable, period, harmonics), e.g. fourier(q1, 0.45, 2)")
        v, period, h = self.expr(text, args[0]), self.number(text, args[1]), self.number(text, args[2])
        if period <= 0:
            self.fail(text, "fourier period must be positive")
        if h != int(h) or not 1 <= h <= 32:
            self.fail(text, "fourier harmonics must be an integer 1..32")
        out = []
        for j in range(1, int(h) + 1):
            arg = 2 * sp.pi * j * v / sp.Rational(repr(float(period)))
            spelled = f"{2 * j}*pi*{var}/{float(period)!r}"
            out += [(sp.sin(arg), f"sin({spelled})"), (sp.cos(arg), f"cos({spelled})")]
        return out

    def number(self, text: str, node) -> float:
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -self.number(text, node.operand)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            if not math.isfinite(_magnitude(node.value)):
                self.fail(text, "holds a number beyond floating point; rewrite the term")
            return float(node.value)
        self.fail(text, "expected a number here")

    def expr(self, text: str, node) -> sp.Expr:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            self.number(text, node)
            return sp.Integer(node.value) if isinstance(node.value, int) else sp.Rational(repr(node.value))
        if isinstance(node, ast.Name):
            if node.id == "pi":
                return sp.pi
            robot = self.loads.robot
            passive = next((j.coupling for j in robot.chain if j.name == node.id and not j.reads), None)
            if passive is not None and node.id not in self.symbols:
                readings = ", ".join(f"q{robot.joint_names.index(n) + 1}" for n, _ in passive.terms)
                kind = "a passive coupled joint" if passive.declared else "a mimic joint"
                self.fail(text, f"'{node.id}' is {kind}, with no variable of its own; write its value "
                                f"{passive.text(robot)} in {readings}")
            if node.id not in self.symbols:
                self.fail(text, f"unknown variable '{node.id}'; known: {', '.join(self.symbols)} "
                                f"(declare a data column under 'aux:')")
            return self.symbols[node.id]
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            v = self.expr(text, node.operand)
            return -v if isinstance(node.op, ast.USub) else v
        if isinstance(node, ast.BinOp):
            ops = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
                   ast.Div: lambda a, b: a / b}
            if isinstance(node.op, ast.Pow):
                k = self.number(text, node.right)
                return self.power(text, self.expr(text, node.left), k)
            if type(node.op) in ops:
                return ops[type(node.op)](self.expr(text, node.left), self.expr(text, node.right))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in (*FUNCTIONS, "sqrt"):
            if len(node.args) != 1 or node.keywords:
                self.fail(text, f"{node.func.id} takes one argument")
            arg = self.expr(text, node.args[0])
            return self.power(text, arg, 0.5) if node.func.id == "sqrt" else FUNCTIONS[node.func.id](arg)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in LOAD_FUNCTIONS:
            return load_symbol(self.loads.name(text, node, self.fail))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("poly", "fourier"):
            self.fail(text, f"{node.func.id}(...) must stand alone as a whole term")
        self.fail(text, f"{excerpt(ast.unparse(node))} is not allowed; {ALLOWED}")


def _magnitude(number) -> float:
    """|number| as a float: inf beyond floating point (float() of a huge integer raises instead)."""
    try:
        return abs(float(number))
    except OverflowError:
        return math.inf


def _log2(number: sp.Expr) -> float:
    """log2 |number| of a nonzero real constant; exact for rationals, whose float() can overflow or underflow."""
    if number.is_Rational:
        return abs(number.p).bit_length() - number.q.bit_length()
    magnitude = _magnitude(number)
    return math.log2(magnitude) if magnitude else -math.inf


def _degree(expr: sp.Expr, x: sp.Symbol) -> float:
    """The highest power of x in expr through nested powers and products; a function's argument counts
    as it stands (sin(q1**20) varies as fast as q1**20)."""
    if expr == x:
        return 1.0
    if expr.is_Pow and expr.exp.is_number:
        return _degree(expr.base, x) * abs(float(expr.exp))
    if expr.is_Mul:
        return sum(_degree(a, x) for a in expr.args)
    return max((_degree(a, x) for a in expr.args), default=0.0)


def variables(robot: Robot, aux: tuple[str, ...]) -> dict[str, sp.Symbol]:
    """The names a term may use (`model.errors.variable_names`) -> their sympy symbols."""
    return {k: sp.Symbol(v, real=True) for k, v in variable_names(robot, aux).items()}


def joint_symbols(robot: Robot) -> tuple[sp.Symbol, ...]:
    return tuple(sp.Symbol(f"q{i + 1}", real=True) for i in range(robot.n))


def _canonical(expr: sp.Expr) -> str:
    return sp.sstr(expr, order="lex")


def terms_of(items: list, where: str, robot: Robot, names: dict[str, str]) -> tuple[Term, ...]:
    """The terms of one list of the term language (`model.error_file.TermReader`), names the variables
    a term may use (`model.errors.variable_names`)."""
    parser = TermParser({k: sp.Symbol(v, real=True) for k, v in names.items()}, where, LoadTerms(robot, names))
    out: dict[str, Term] = {}
    for item in items:
        for expr, label in parser.parse(item):
            if expr.is_number:
                require(expr == 1, f"{where}: term {excerpt(item)} is a constant; write the constant term as \"1\"")
            text = _canonical(expr)
            require(text not in out, f"{where}: term {excerpt(item)} repeats {excerpt(text)}; each term may appear once")
            out[text] = Term(text, "1" if expr == 1 else label, _names(expr))
    return tuple(out.values())


def parse_model(spec, robot: Robot, where: str, aux_columns: tuple[str, ...] = ()
                ) -> tuple[tuple[tuple[Term, ...], ...], tuple[str, ...]]:
    """The terms of each generalized error, and the aux columns used, of an error-model mapping
    (`model.error_file.read_model` with the term parser)."""
    return read_model(spec, robot, where, aux_columns, terms_of)


def load_symbol(name: str) -> sp.Symbol:
    """The sympy symbol of a load signal, by canonical spelling (e.g. 'gravity(q2,1)')."""
    return sp.Symbol(name, real=True)


def _names(expr: sp.Expr) -> tuple[str, ...]:
    return tuple(sorted(s.name for s in expr.free_symbols))


def term_expressions(robot: Robot, model: ErrorModel) -> dict[str, sp.Expr]:
    """Canonical text -> expression of each distinct term: its label parsed again, as it was when
    the model was read (a label that poly or fourier expanded parses to that one term)."""
    symbols = variables(robot, model.aux)
    parser = TermParser(symbols, f"{model.source or '<error model>'}", LoadTerms(robot, {k: s.name for k, s in symbols.items()}))
    out = {}
    for t in model.unique_terms():
        found = [e for e, _ in parser.parse(t.label) if _canonical(e) == t.text]
        require(len(found) == 1, f"{model.source}: term {excerpt(t.label)} no longer reads as {excerpt(t.text)}; "
                                 f"read the error-model file again")
        out[t.text] = found[0]
    return out
