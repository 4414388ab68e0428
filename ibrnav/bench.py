"""The one place benchmarks run. Each package and sub-package that has speed figures keeps
them in its `bench.py` as `FIGURES = {name: function}`; a function returns
`{"value": v, "unit": u, "baseline": b, "ratio": r}` measured against a naive baseline in
the same run (and may add keys of its own). `all_figures` gathers every `bench.py` of the
four library packages; `run_figures` runs some and returns `{"figures": {NAME: {...}}}`.
Progress goes to the log (stderr), never to stdout, which carries the JSON."""

from __future__ import annotations

import importlib
import importlib.util
import logging
import time
from pathlib import Path

PACKAGES = ("ibr", "localization", "explore", "robot")
log = logging.getLogger(__name__)


def bench_modules() -> list[str]:
    """Dotted names of every `bench.py` module in the library packages (sorted)."""
    names = []
    for pkg in PACKAGES:
        root = Path(importlib.util.find_spec(pkg).origin).parent
        for path in sorted(root.rglob("bench.py")):
            rel = path.relative_to(root.parent).with_suffix("")
            names.append(".".join(rel.parts))
    return names


def all_figures() -> dict:
    figures = {}
    for name in bench_modules():
        figures.update(importlib.import_module(name).FIGURES)
    return figures


class UnknownFigureError(KeyError):
    """Figure names that no bench.py defines."""


def run_figures(names: list[str] | None = None) -> dict:
    """Run the named figures (default: all), in order; `{"figures": {NAME: {...}}}`."""
    figures = all_figures()
    names = names or list(figures)
    unknown = [n for n in names if n not in figures]
    if unknown:
        raise UnknownFigureError(f"unknown figure(s) {unknown}; known: {sorted(figures)}")
    out = {"figures": {}}
    for n in names:
        t = time.perf_counter()
        log.info(f"{n} ...")
        fig = figures[n]()
        out["figures"][n] = fig
        log.info(f"{n}: {fig['value']:.4g} {fig['unit']} (baseline {fig['baseline']:.4g}, "
                 f"ratio {fig['ratio']:.3g}x) in {time.perf_counter() - t:.1f} s")
    return out
