"""`ibrnav bench`: the one place benchmarks run. Each package lists its figures in a
`bench*.py` module as `FIGURES = {name: function}`; a function returns
`{"value": v, "unit": u, "baseline": b, "ratio": r}` measured against a naive baseline
in the same run. Output: `{"figures": {NAME: {...}, ...}}`."""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

FIGURE_MODULES = ["ibr.bench", "ibr.bench_ulr", "explore.bench_vueplan", "explore.scenic_bench", "explore.bench_mission", "localization.bench", "localization.bench_pnp"]


def all_figures() -> dict:
    figures = {}
    for name in FIGURE_MODULES:
        figures.update(importlib.import_module(name).FIGURES)
    return figures


def run(args: argparse.Namespace) -> int:
    figures = all_figures()
    names = args.only or list(figures)
    unknown = [n for n in names if n not in figures]
    if unknown:
        print(f"unknown figure(s) {unknown}; known: {sorted(figures)}", file=sys.stderr)
        return 2
    out = {"figures": {}}
    for n in names:
        t = time.perf_counter()
        print(f"[bench] {n} ...", file=sys.stderr, flush=True)
        fig = figures[n]()
        out["figures"][n] = fig
        print(f"[bench] {n}: {fig['value']:.4g} {fig['unit']} (baseline {fig['baseline']:.4g}, "
              f"ratio {fig['ratio']:.3g}x) in {time.perf_counter() - t:.1f} s", file=sys.stderr)
    text = json.dumps(out, indent=2)
    if args.json:
        Path(args.json).write_text(text + "\n")
    print(text)
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("bench", help="run the speed figures (JSON out)")
    p.add_argument("--json", help="write the figures to this file")
    p.add_argument("--only", action="append", metavar="NAME", help="run only this figure (repeatable)")
    p.set_defaults(func=run)
