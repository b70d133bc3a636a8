"""Emit: print the symbolic functions of a robot and error model through each language's templates.

One folder per output language (`c/`, `casadi/`), each holding only its printer and templates;
the symbolic functions are built once and shared by all of them.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import jinja2

from gecgen import __version__
from gecgen.emit.c.printer import CPrinter
from gecgen.emit.c.printer import element as c_element
from gecgen.emit.casadi.printer import CasadiPrinter
from gecgen.emit.casadi.printer import element as casadi_element
from gecgen.emit.printing import straight_line
from gecgen.files import write_atomically
from gecgen.model.errors import ErrorModel
from gecgen.model.loads import catalog
from gecgen.model.robot import Mimic, Robot
from gecgen.symbolic.functions import all_functions
from gecgen.symbolic.program import Function

HERE = Path(__file__).parent


def _env(lang: str) -> jinja2.Environment:
    return jinja2.Environment(loader=jinja2.FileSystemLoader(HERE / lang / "templates"), trim_blocks=True,
                              lstrip_blocks=True, keep_trailing_newline=True, undefined=jinja2.StrictUndefined)


def _c_literal(x: float) -> str:
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return repr(float(x))


def _rows(values: list, per_row: int = 16) -> list[list]:
    return [values[k:k + per_row] for k in range(0, len(values), per_row)]


def context(robot: Robot, model: ErrorModel) -> dict:
    """Everything the templates need besides the printed functions."""
    terms = [t.text for t in model.unique_terms()]
    coefs = model.coefficients
    coef_error = [c.error for c in coefs]
    coef_term = [terms.index(c.term.text) for c in coefs]
    sources = list(robot.source_hashes) + ([Path(model.source).name] if model.source_hash else [])
    loads = catalog(robot)
    return dict(mimics=any(j.mimic for j in robot.chain), frame_names=frame_names(robot),
                nl=len(loads.signals), loads=[(s.name, loads.describe(s, robot)) for s in loads.signals],
                gravity=[repr(float(v)) for v in robot.gravity],
                name=robot.name, NAME=robot.name.upper(), version=__version__, sources=sources,
                nq=robot.n, nt=len(robot.targets), ne=robot.n_errors, nc=len(coefs), nf=len(terms),
                naux=len(model.aux), joint_names=list(robot.joint_names), target_names=list(robot.target_names),
                aux_names=list(model.aux), q_min=[_c_literal(j.lower) for j in robot.joints],
                q_max=[_c_literal(j.upper) for j in robot.joints], coef_error=_rows(coef_error),
                coef_term=_rows(coef_term), coef_error_flat=coef_error, coef_term_flat=coef_term, terms=terms)


def frame_names(robot: Robot) -> list[str]:
    """Each moving frame's joint, a mimic joint with the value it takes ("jaw2 = -1.0*q3 - 0.01")."""
    def value(m: Mimic) -> str:
        o = float(m.offset)
        return f"{float(m.multiplier)!r}*q{m.joint + 1} {'-' if o < 0 else '+'} {abs(o)!r}"
    return [j.name if j.mimic is None else f"{j.name} = {value(j.mimic)}" for j in robot.chain]


def _printed(fn: Function, printer, element, signature: bool) -> dict:
    temps, outs = straight_line(fn, printer, element)
    sig = ", ".join([f"const double *{k}" for k in fn.inputs] + [f"double *{k}" for k in fn.outputs])
    return dict(name=fn.name, doc=fn.doc, inputs=list(fn.inputs), temps=temps, outs=outs,
                signature=sig if signature else "")


def render(robot: Robot, model: ErrorModel, functions: list[Function] | None = None) -> dict[str, str]:
    """File name -> text of every generated file, manifest included; deterministic."""
    functions = functions or all_functions(robot, model)
    ctx = context(robot, model)
    c_env, ca_env = _env("c"), _env("casadi")
    c_fns = [_printed(f, CPrinter(), c_element, True) for f in functions]
    ca_fns = [_printed(f, CasadiPrinter(), casadi_element, False) for f in functions]
    files = {
        f"{robot.name}.h": c_env.get_template("header.h.j2").render(functions=c_fns, **ctx),
        f"{robot.name}.c": c_env.get_template("source.c.j2").render(functions=c_fns, **ctx),
        f"{robot.name}_casadi.py": ca_env.get_template("module.py.j2").render(functions=ca_fns, **ctx),
    }
    manifest = dict(
        gecgen_version=__version__, robot=robot.name, robot_files=robot.source_hashes,
        error_model={Path(model.source).name: model.source_hash} if model.source_hash else {"<constant>": ""},
        joints=list(robot.joint_names), targets=list(robot.target_names), aux=list(model.aux),
        errors=robot.error_names(), terms=ctx["terms"], coefficients=model.coefficient_names(robot),
        load_signals=[name for name, _ in ctx["loads"]],
        coef_error=ctx["coef_error_flat"], coef_term=ctx["coef_term_flat"],
        limits=[[j.lower, j.upper] for j in robot.joints],
        **({"frames": ctx["frame_names"]} if ctx["mimics"] else {}),
        files={k: hashlib.sha256(v.encode()).hexdigest() for k, v in sorted(files.items())},
    )
    files["manifest.json"] = json.dumps(manifest, indent=1, sort_keys=True, allow_nan=True) + "\n"
    return files


def generate(robot: Robot, model: ErrorModel, outdir: str | Path) -> dict[str, str]:
    """Write the generated files into outdir (created if needed), each atomically; returns them."""
    files = render(robot, model)
    for name, text in files.items():
        write_atomically(Path(outdir) / name, text)
    return files
