"""`--register`, in the one form every command that takes it shares. Apart from `common`, which
loads the numerical libraries: the CLI reads its arguments through `bare_register` before it knows
the command, and `gecgen --help` or `--version` need none of them."""
from __future__ import annotations

import argparse


#: the values of --register, the same for every command that takes it (each takes those that apply to it)
REGISTER = ("auto", "always", "never", "val")


def add_register(p, allowed: tuple[str, ...], bare: str, default: str, lead: str):
    """--register in the one form every command shares: `--register MODE`, MODE one of `allowed` (of
    REGISTER), and `--register` alone meaning `bare` (the command's "fit the new stationing"), so the
    flag of evaluate and calibrate and the choice of identify and diagnose are spelled alike. `lead`
    is the help, which says what each value does. `bare_register` lets `--register` alone stand
    before the positionals."""
    def parse(text: str) -> str:
        value = text or bare
        if value not in allowed:
            raise argparse.ArgumentTypeError(f"{text!r} is not a registration this command does; give one of "
                                             f"{', '.join(allowed)}, or --register alone ({bare})")
        return value

    p.add_argument("--register", nargs="?", const=bare, default=default, type=parse, metavar="MODE",
                   help=f"{lead} (MODE {', '.join(allowed)}; default {default}; --register alone: {bare})")


def bare_register(argv: list[str]) -> list[str]:
    """argv with a `--register` that no mode follows written `--register=`, so that the word after it
    (a positional, as in `evaluate --register CALIB DATA`) is not read as its mode."""
    return ["--register=" if a == "--register" and (i + 1 == len(argv) or argv[i + 1] not in REGISTER) else a
            for i, a in enumerate(argv)]
