"""Emit: print the symbolic functions of a robot and error model through each language's templates.

One folder per output language (`c/`, `casadi/`), each holding only its printer and templates;
the symbolic functions are built once and shared by all of them. Rendering printed code that the
code cache kept (`runtime.compiled`), and a calibration's header and example, need no sympy: the
symbolic layer and the printers are imported by the functions that print.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import jinja2

from gecgen.version import __version__
from gecgen.model.files import write_atomically
from gecgen.model.errors import ErrorModel
from gecgen.model.loads import catalog
from gecgen.model.robot import Robot

if TYPE_CHECKING:
    from gecgen.symbolic.program import Function

HERE = Path(__file__).parent


def _env(lang: str) -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(HERE / lang / "templates"), trim_blocks=True,
                             lstrip_blocks=True, keep_trailing_newline=True, undefined=jinja2.StrictUndefined)
    env.filters["comment"] = comment_text
    return env


def comment_text(text: str) -> str:
    """A name as it may stand inside a C comment: a URDF joint named `a*/b` would end the comment
    and leave the rest as code, `/*` in it is an error under -Wall -Werror, and a line break would
    leave the comment's layout."""
    return " ".join(str(text).replace("*/", "*\\/").replace("/*", "/\\*").split())


def _c_literal(x: float) -> str:
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return repr(float(x))


def _rows(values: list, per_row: int = 16) -> list[list]:
    return [values[k:k + per_row] for k in range(0, len(values), per_row)]


def robot_model_hash(robot: Robot, model: ErrorModel) -> str:
    """sha256 (hex) of what the generated code computes: the robot files' contents and the error
    model's terms, not file names or the gecgen version. Coefficients fitted with one hash belong to
    code with that hash only; `NAME_MODEL_HASH` in NAME.h is its first 15 hex digits (60 bits, so
    the preprocessor can compare it)."""
    text = json.dumps([sorted(robot.source_hashes.values()), model.to_yaml_dict(robot)], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


#: hex digits of the model hash in the C macros: an integer the preprocessor compares (intmax_t)
C_HASH_DIGITS = 15


def context(robot: Robot, model: ErrorModel) -> dict:
    """Everything the templates need besides the printed functions."""
    terms = [t.text for t in model.unique_terms()]
    coefs = model.coefficients
    coef_error = [c.error for c in coefs]
    coef_term = [terms.index(c.term.text) for c in coefs]
    sources = list(robot.source_hashes) + ([Path(model.source).name] if model.source_hash else [])
    loads = catalog(robot)
    used = [loads.by_name(n) for n in model.load_signals(robot)]
    return dict(model_hash=robot_model_hash(robot, model)[:C_HASH_DIGITS],
                mimics=any(j.coupling for j in robot.chain) or bool(robot.branches),
                frame_names=frame_names(robot), branch_suffixes=branch_suffixes(robot),
                task_rows={suffix: robot.task_rows(k) for k, suffix in enumerate(branch_suffixes(robot))},
                nl=len(used), loads=[(s.name, loads.describe(s, robot)) for s in used],
                gravity=[repr(float(v)) for v in robot.gravity],
                name=robot.name, NAME=robot.name.upper(), version=__version__, sources=sources,
                nq=robot.n, nt=len(robot.targets), ne=robot.n_errors, nc=len(coefs), nf=len(terms),
                naux=len(model.aux), joint_names=list(robot.joint_names), target_names=list(robot.target_names),
                aux_names=list(model.aux), q_min=[_c_literal(j.lower) for j in robot.joints],
                q_max=[_c_literal(j.upper) for j in robot.joints], coef_error=_rows(coef_error),
                coef_term=_rows(coef_term), coef_error_flat=coef_error, coef_term_flat=coef_term, terms=terms)


def branch_suffixes(robot: Robot) -> list[str]:
    """The name suffix of each branch's fk, tool_jacobian and compensate: none on a serial chain."""
    return [f"_{b.name}" for b in robot.branches] or [""]


def frame_names(robot: Robot) -> list[str]:
    """Each moving frame's joint, a coupled joint with the value it takes ("jaw2 = -1.0*q3 - 0.01")."""
    names = [j.name if j.coupling is None else f"{j.name} = {j.coupling.text(robot)}" for j in robot.chain]
    return [f"{n} (on frame {robot.parent(i)})" if robot.branches else n for i, n in enumerate(names, start=1)]


def _printed(fn: Function, printer, element, signature: bool) -> dict:
    from gecgen.emit.printing import straight_line

    temps, outs = straight_line(fn, printer, element)
    sig = ", ".join([f"const double *{k}" for k in fn.inputs] + [f"double *{k}" for k in fn.outputs])
    return dict(name=fn.name, doc=fn.doc, inputs=list(fn.inputs), temps=temps, outs=outs,
                signature=sig if signature else "")


def _printed_all(functions) -> dict[str, list[dict]]:
    from gecgen.emit.c.printer import CPrinter
    from gecgen.emit.c.printer import element as c_element
    from gecgen.emit.casadi.printer import CasadiPrinter
    from gecgen.emit.casadi.printer import element as casadi_element

    return {"c": [_printed(f, CPrinter(), c_element, True) for f in functions],
            "casadi": [_printed(f, CasadiPrinter(), casadi_element, False) for f in functions]}


def printed_chain(robot: Robot) -> dict[str, list[dict]]:
    """`printed` of the robot's own functions (`symbolic.functions.chain_functions`), which no error
    model changes: nearly all of the symbolic work."""
    from gecgen.symbolic.functions import chain_functions

    robot.require_placed()
    return _printed_all(chain_functions(robot))


def printed(robot: Robot, model: ErrorModel, chain: dict[str, list[dict]] | None = None) -> dict[str, list[dict]]:
    """Every function's straight-line code as the C and the CasADi templates print it ({"c": [...],
    "casadi": [...]}, plain lists and strings): the symbolic build and its printing, the slow part of
    `render`, which depends on the robot's and the model's content alone (runtime.compiled keeps it
    in the code cache). `chain`: `printed_chain(robot)`, when already at hand."""
    from gecgen.symbolic.functions import model_functions

    robot.require_placed()
    chain = chain or printed_chain(robot)
    own = _printed_all(model_functions(robot, model))
    return {k: chain[k] + own[k] for k in ("c", "casadi")}


def render(robot: Robot, model: ErrorModel, code: dict[str, list[dict]] | None = None) -> dict[str, str]:
    """File name -> text of every generated file, manifest included; deterministic. `code`: what
    `printed` returns for this robot and model, when already at hand."""
    robot.require_placed()
    code = code or printed(robot, model)
    ctx = context(robot, model)
    casadi = _env("casadi").get_template("module.py.j2").render(functions=code["casadi"], **ctx)
    files = {**_c_files(robot.name, ctx, code["c"]), f"{robot.name}_casadi.py": casadi}
    manifest = dict(
        gecgen_version=__version__, robot=robot.name, robot_files=robot.source_hashes,
        error_model={Path(model.source).name: model.source_hash} if model.source_hash else {"<constant>": ""},
        joints=list(robot.joint_names), targets=list(robot.target_names), aux=list(model.aux),
        errors=robot.error_names(), terms=ctx["terms"], coefficients=model.coefficient_names(robot),
        load_signals=[name for name, _ in ctx["loads"]],
        coef_error=ctx["coef_error_flat"], coef_term=ctx["coef_term_flat"],
        limits=[[j.lower, j.upper] for j in robot.joints], model_hash=robot_model_hash(robot, model),
        **({"frames": ctx["frame_names"]} if ctx["mimics"] else {}),
        files={k: hashlib.sha256(v.encode()).hexdigest() for k, v in sorted(files.items())},
    )
    files["manifest.json"] = json.dumps(manifest, indent=1, sort_keys=True, allow_nan=True) + "\n"
    return files


def _c_files(name: str, ctx: dict, functions: list[dict], n_chain: int = 0) -> dict[str, str]:
    """NAME.h and NAME.c of the printed C functions; with n_chain, the first n_chain of them (the
    chain's) in NAME_chain.c of their own instead, which NAME.c then calls through NAME.h."""
    env = _env("c")
    files = {f"{name}.h": env.get_template("header.h.j2").render(functions=functions, **ctx),
             f"{name}.c": env.get_template("source.c.j2").render(functions=functions[n_chain:], **ctx)}
    if n_chain:
        files[f"{name}_chain.c"] = env.get_template("chain.c.j2").render(functions=functions[:n_chain], **ctx)
    return files


def render_c_parts(robot: Robot, model: ErrorModel, code: dict[str, list[dict]], n_chain: int) -> dict[str, str]:
    """The C of `render` as two translation units that link into the same functions: NAME_chain.c,
    the chain's functions (the first n_chain of `code`, `printed_chain`), which no error model
    changes and which the runtime therefore compiles once per robot, and NAME.c with the rest, the
    model's own code, beside NAME.h."""
    robot.require_placed()
    return _c_files(robot.name, context(robot, model), code["c"], n_chain)


def generate(robot: Robot, model: ErrorModel, outdir: str | Path,
             code: dict[str, list[dict]] | None = None) -> dict[str, str]:
    """Write the generated files into outdir (created if needed), each atomically; returns them.
    `code`: as for `render`."""
    files = render(robot, model, code)
    for name, text in files.items():
        write_atomically(Path(outdir) / name, text)
    return files


def _g17(x: float) -> str:
    """A C double literal that reads back as x exactly."""
    return "%.17g" % x


def render_calibration(robot: Robot, model: ErrorModel, c, std, command: dict, max_iter: int, tol: float,
                       origin: str, reasons: dict[str, str] | None = None) -> dict[str, str]:
    """NAME_calibration.h and NAME_example.c for coefficients c (nc,) with their std (nc,), NaN where
    eliminated. The header holds c as const data in NAME.h's coefficient order, each value with its
    name, and stops the build when NAME.h has another model hash; the example compensates one
    nominal command, `command` = {"q": (nq,), "w": (6,), "aux": (naux,)} (m, rad, N, N m), with
    NAME_compensate's max_iter and tol (m), and prints the corrected joints. `origin` names the
    calibration in the comments; `reasons` ({coefficient name: why eliminated}: structural,
    unexcited, weak, insignificant) says why each NaN-std coefficient is 0."""
    ctx = context(robot, model)
    names = model.coefficient_names(robot)
    reasons = reasons or {}
    notes = [f"eliminated: {reasons.get(n, 'not identifiable')}" if math.isnan(s) else f"std {s:.2g}"
             for n, s in zip(names, std)]
    coefficients = [(_g17(v), f"{n} ({note})") for v, n, note in zip(c, names, notes)]
    held, fitted = sum(r == "insignificant" for r in reasons.values()), sum(not math.isnan(s) for s in std)
    ctx["carried"] = f"{fitted} coefficients carry fitted values" + (
        f"; {held} identifiable ones the data did not determine (|value| / std < 2) are held at 0" if held else "")
    env = _env("c")
    values = {k: [_g17(v) for v in command[k]] for k in ("q", "w", "aux")}
    return {
        f"{robot.name}_calibration.h": env.get_template("calibration.h.j2").render(
            coefficients=coefficients, origin=origin, **ctx),
        f"{robot.name}_example.c": env.get_template("example.c.j2").render(
            command=values, max_iter=max_iter, tol=repr(float(tol)), joint_strings=map(_c_string, robot.joint_names),
            **ctx),
    }


def _c_string(text: str) -> str:
    """A C string literal of text: its UTF-8 bytes, all but letters, digits and `_-. ` as octal escapes."""
    keep = set(b"abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-. ")
    return '"' + "".join(chr(b) if b in keep else f"\\{b:03o}" for b in text.encode()) + '"'
