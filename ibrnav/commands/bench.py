"""`ibrnav bench [--only NAME ...] [--json FILE]`: run the speed figures (`ibrnav.bench`); the
JSON `{"figures": {NAME: {"value", "unit", "baseline", "ratio", ...}}}` is printed on stdout
(progress goes to stderr, so stdout stays parseable)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from ibrnav import jsonout
from ibrnav.bench import UnknownFigureError, run_figures

log = logging.getLogger(__name__)


def run(args: argparse.Namespace) -> int:
    try:
        out = run_figures(args.only)
    except UnknownFigureError as e:
        log.error("%s", e.args[0])
        return 2
    text = jsonout.dumps(out)
    if args.json:
        Path(args.json).write_text(text + "\n")
    print(text)
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("bench", help="run the speed figures (JSON out)")
    p.add_argument("--json", help="write the figures to this file")
    p.add_argument("--only", action="append", metavar="NAME", help="run only this figure (repeatable)")
    p.set_defaults(func=run)
