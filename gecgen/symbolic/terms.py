"""Error-model files read into `model.errors.ErrorModel`s, through the cache.

Reading a model's terms needs sympy (`symbolic.parse`: a term's identity is sympy's canonical text),
except those of constants, variables, their powers and products, sin and cos of one variable and the
load signals (`model.error_file.simple_terms`); a model read before, for the same robot, is read back
from the cache (`model.files.cache_dir`, by the content of the mapping, the robot and the parser), so
a command whose code is compiled loads no sympy at all: this module imports the parser only on a miss.
"""
from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

from gecgen.model.error_file import NeedsParser, read_model, simple_terms
from gecgen.model.errors import ErrorModel, Term
from gecgen.model.files import cache_dir, write_atomically
from gecgen.model.robot import Robot
from gecgen.model.validation import read_yaml


def load_error_model(path: str | Path | None, robot: Robot, aux_columns: tuple[str, ...] = ()) -> ErrorModel:
    """Read an error-model file for `robot`; `aux_columns` are data columns usable as variables.

    `path=None` gives the constant-only model (every error gets the term "1").
    """
    if path is None:
        spec, where, digest = {"default": ["1"]}, "<constant model>", ""
    else:
        path = Path(path)
        where = str(path)
        spec = read_yaml(path, "error-model")
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return error_model_from_dict(spec, robot, where, aux_columns, digest)


def error_model_from_dict(spec, robot: Robot, where: str, aux_columns: tuple[str, ...] = (),
                          digest: str = "") -> ErrorModel:
    """The error model of a mapping (a model file's content) for `robot`; problems as one line naming `where`."""
    key = _key(spec, robot, aux_columns)
    path = cache_dir() / f"{robot.name}-{key}.terms.json" if key else None
    found = _cached(path) if path else None
    if found is None:
        found = _parsed(spec, robot, where, aux_columns)
        unique = list(dict.fromkeys(t for ts in found[0] for t in ts))
        text = json.dumps({"terms": [[t.text, t.label, list(t.variables)] for t in unique],
                           "errors": [[unique.index(t) for t in ts] for ts in found[0]], "aux": list(found[1])})
        keys = [key]
        # the model as a calibration stores it (`to_yaml_dict`) is read by every command after
        # identify: it is kept too, once it has read back into the same model
        written = ErrorModel(*found).to_yaml_dict(robot)
        if written != spec and _parsed(written, robot, where) == found:
            keys.append(_key(written, robot, ()))
        for k in dict.fromkeys(filter(None, keys)):
            write_atomically(cache_dir() / f"{robot.name}-{k}.terms.json", text + "\n")
    return ErrorModel(terms=found[0], aux=found[1], source=where, source_hash=digest)


def _parsed(spec, robot: Robot, where: str, aux_columns: tuple[str, ...] = ()):
    """(terms per error, aux) of a model mapping: of the terms `simple_terms` reads without sympy, any
    other with it."""
    try:
        return read_model(spec, robot, where, aux_columns, simple_terms)
    except NeedsParser:
        from gecgen.symbolic.parse import parse_model

        return parse_model(spec, robot, where, aux_columns)


@functools.cache
def _parser_hash() -> str:
    """Hash of the code that reads terms: a change to it reads every model again."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in (root / "symbolic" / "parse.py", root / "model" / "errors.py", root / "model" / "loads.py",
                 root / "model" / "error_file.py"):
        h.update(path.read_bytes())
    return h.hexdigest()


def _key(spec, robot: Robot, aux_columns) -> str | None:
    """The cache key of a model mapping for a robot: everything the terms' reading depends on (the
    robot's chain and files, which give its joints and load signals); the mapping by the repr of its
    items, which tells 0 from "0" and 1 from 1.0 as the parser does, in an order of keys that does
    not depend on the file's (the terms do not). None when it cannot be written down."""
    try:
        text = json.dumps([repr(_sorted(spec)), repr((robot.name, robot.chain, robot.parents, robot.branches, robot.wrench_frame,
                                       robot.gravity, robot.urdf, robot.base_link, robot.tip_link)),
                           robot.source_hashes, list(aux_columns), _parser_hash()], sort_keys=True)
    except (TypeError, ValueError, RecursionError):
        return None
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _sorted(value):
    """value with every mapping's items sorted by key (type first: 0 and "0" are different keys)."""
    if isinstance(value, dict):
        return sorted(((type(k).__name__, repr(k)), _sorted(v)) for k, v in value.items())
    return [_sorted(v) for v in value] if isinstance(value, list) else value


def _cached(path: Path) -> tuple[tuple[tuple[Term, ...], ...], tuple[str, ...]] | None:
    """(terms per error, aux) stored at path, or None when there is none or it is not whole."""
    try:
        stored = json.loads(path.read_text())
        unique = [Term(str(text), str(label), tuple(str(v) for v in names)) for text, label, names in stored["terms"]]
        return tuple(tuple(unique[k] for k in ks) for ks in stored["errors"]), tuple(str(a) for a in stored["aux"])
    except (OSError, ValueError, TypeError, KeyError, IndexError):
        return None
