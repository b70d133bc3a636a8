"""The one error type for bad user input, the checks that raise it, and the guarded readers."""
from __future__ import annotations

import codecs
import difflib
import re
import reprlib
from pathlib import Path

import yaml

#: robot, error-model and mapping files are a few kB; anything this large is the wrong file (bytes)
MAX_YAML_BYTES = 1_000_000
#: values that YAML aliases (*name) may stand for in one file, counted as expanded
MAX_ALIASED_VALUES = 10_000
#: characters of user text a message repeats
EXCERPT = 60


class ModelError(ValueError):
    """Bad input: the message is one line naming the file, key or row, and the fix."""


def is_name(value) -> bool:
    """An ASCII identifier: a name in a file that becomes a variable of the terms and of the generated
    code. Python reads a full-width `ｑ3` as `q3` (NFKC), so a non-ASCII name could alias another."""
    return isinstance(value, str) and value.isascii() and value.isidentifier()


def require(condition, message: str):
    if not condition:
        raise ModelError(message)
    return condition


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxdict, _SHORT.maxset, _SHORT.maxtuple = 2, 4, 4, 4, 4
_SHORT.maxstring = _SHORT.maxother = _SHORT.maxlong = EXCERPT


def excerpt(value) -> str:
    """The repr of user input cut to EXCERPT characters. Messages echo what the file holds, which
    can be a megabyte-long cell or a structure that YAML aliases made astronomically large; reprlib
    never walks more than a few elements of it."""
    text = repr(value[:EXCERPT + 1]) if isinstance(value, str) else _SHORT.repr(value)
    return text if len(text) <= EXCERPT else text[:EXCERPT] + "..."


#: names a "did you mean" lists at most
LISTED = 8


def nearest(name, choices) -> str:
    """What to say after an unknown `name`: the closest of `choices` ("did you mean 'x'? "), then
    the choices (the first LISTED of them, and how many in all)."""
    choices = [str(c) for c in choices]
    lower = {c.lower(): c for c in choices}
    close = difflib.get_close_matches(name.lower(), list(lower), n=1, cutoff=0.6) if isinstance(name, str) else []
    close = [lower[c] for c in close]
    listed = ", ".join(choices[:LISTED]) + (f", ... ({len(choices)} in all)" if len(choices) > LISTED else "")
    return (f"did you mean '{close[0]}'? " if close else "") + f"the choices: {listed}"


def require_keys(spec: dict, where: str, required: set = frozenset(), optional: set = frozenset()):
    for key in sorted(required):
        require(key in spec, f"{where}: missing key '{key}'")
    unknown = sorted(str(k) for k in spec if k not in required | optional)
    require(not unknown, f"{where}: unknown key {excerpt(unknown[0]) if unknown else ''}; "
                         f"allowed keys are {sorted(required | optional)}")


def read_utf8(path: Path, what: str) -> bytes:
    """The bytes of a file that must be UTF-8, a leading byte-order mark (as spreadsheets write it)
    dropped; `what` names it in messages ("robot file")."""
    path = Path(path)
    require(path.is_file(), f"{path}: no such {what}")
    data = path.read_bytes()
    try:
        if not data.isascii():  # ASCII, the usual case, is UTF-8 and is checked far faster
            data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ModelError(f"{path}: line {line}: byte 0x{data[exc.start]:02x} is not UTF-8; "
                         f"save the {what} as UTF-8") from None
    return data[len(codecs.BOM_UTF8):] if data.startswith(codecs.BOM_UTF8) else data


def read_text(path: Path, what: str) -> str:
    """The text of a file that must be UTF-8 (see `read_utf8`)."""
    return read_utf8(path, what).decode()


class _Loader(yaml.SafeLoader):
    """SafeLoader that counts the values aliases stand for. Nested anchors ("billion laughs") load
    in microseconds as shared references and then explode in whatever walks or prints them."""

    def __init__(self, stream, where: str):
        super().__init__(stream)
        self.where = where
        self.sizes: dict[int, int] = {}  # id(node) -> number of values in it, aliases expanded
        self.aliased = 0

    def compose_node(self, parent, index):
        alias = self.check_event(yaml.AliasEvent)
        mark = self.peek_event().start_mark
        node = super().compose_node(parent, index)
        if alias:
            # an alias inside its own anchor has no size yet: it would expand forever
            self.aliased += self.sizes.get(id(node), MAX_ALIASED_VALUES + 1)
            require(self.aliased <= MAX_ALIASED_VALUES,
                    f"{self.where}: line {mark.line + 1}: YAML aliases (*name) stand for more than "
                    f"{MAX_ALIASED_VALUES} values; write the values out instead of nesting anchors")
            return node
        children = (node.value if isinstance(node, yaml.SequenceNode) else
                    [n for pair in node.value for n in pair] if isinstance(node, yaml.MappingNode) else [])
        self.sizes[id(node)] = 1 + sum(self.sizes[id(c)] for c in children)
        return node

    def construct_mapping(self, node, deep=False):
        """A mapping whose keys are unique: YAML would keep the last of two `angle_unit`s, silently."""
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                if isinstance(key, (str, int, float, bool)) or key is None:
                    require(key not in seen, f"{self.where}: line {key_node.start_mark.line + 1}: key {excerpt(key)} "
                                             f"appears twice in one mapping; keep one")
                    seen.add(key)
        return super().construct_mapping(node, deep)


# YAML 1.1 reads 5e-2 (no decimal point) as a string; numbers are numbers however they are written
_Loader.add_implicit_resolver("tag:yaml.org,2002:float",
                              re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
                              list("-+0123456789."))


def read_yaml(path: Path, what: str):
    """The parsed YAML document of a `what` file ("robot", "error-model"), or a one-line refusal."""
    path = Path(path)
    require(path.is_file(), f"{path}: no such {what} file")
    size = path.stat().st_size
    require(size <= MAX_YAML_BYTES, f"{path}: {size} bytes; a {what} file may have at most {MAX_YAML_BYTES} "
                                    f"(they are a few kB): check that this is the right file")
    loader = _Loader(read_text(path, f"{what} file"), str(path))
    try:
        return loader.get_single_data()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        where = f"{path}: line {mark.line + 1}, column {mark.column + 1}" if mark else str(path)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ModelError(f"{where}: not valid YAML ({excerpt(problem)}); fix the file there (an indent, a missing "
                         f"bracket, quote or colon)") from None
    except RecursionError:
        raise ModelError(f"{path}: not a {what} file: its lists or mappings are nested too deeply") from None
    finally:
        loader.dispose()
