"""`ibrnav eval-missions --worlds apartment:0-9,office:0-4 --out DIR`: the capture mission swept
over many worlds (`robot.mission.sweep`), each mission one `ibrnav explore` whose JSON and log
stay in DIR (run again, a stopped sweep goes on where it stopped), then a table of every
world against the bars of a finished capture (issue 14) and how many worlds meet each, with
the median and the worst world beside it. `--random` adds the random strategy at the same
budget (the coverage-over-random bar); `--baseline DIR` sets another sweep's figures beside
each world's (a change against main); `--explore-flags` passes further flags to every mission
(to sweep one, e.g. `--explore-flags=--bundle-adjust`); `--mission-seed-offset K` seeds each
mission's own draws K from its world's (a second run of the same worlds, into another DIR);
`--summary-only` reads DIR without running anything."""

from __future__ import annotations

import argparse
import logging
import shlex
from pathlib import Path

from ibr.errors import InputError
from ibrnav import jsonout

log = logging.getLogger(__name__)


class EvalMissionsError(InputError):
    """A flag or folder `ibrnav eval-missions` cannot use; names it."""


def _cm(v) -> str:
    return "—" if v is None else f"{100 * v:.1f}"


def table(summary: dict) -> str:
    """Markdown table of a `sweep.summarise` result: one row per mission, the bars it misses
    last, then one line per bar: how many missions meet it."""
    from robot.mission.sweep import BAR_NAMES

    rows = ["| mission | med cm | p95 cm | head ° | scale % | cov | random cov | achievable | rooms | given up % | s "
            "| stopped | bars missed |", "|" + "---|" * 13]
    for name, m in summary["missions"].items():
        missed = [b for b in BAR_NAMES if m["bars"][b] is False]
        num = lambda v, f: "—" if v is None else f.format(v)  # noqa: E731
        rows.append(f"| {name} | {_cm(m['median_m'])} | {_cm(m['p95_m'])} | {num(m['heading_deg'], '{:.2f}')} | "
                    f"{_cm(m['scale'])} | {num(m['coverage'], '{:.3f}')} | {num(m['random_coverage'], '{:.3f}')} | "
                    f"{num(m['achievable'], '{:.3f}')} | {m['rooms'] or '—'} | {_cm(m['given_up'])} | "
                    f"{num(m['seconds'], '{:.0f}')} | {m['stopped_because'] or '—'} | {', '.join(missed) or 'none'} |")
    rows.append("")
    rows += [f"{bar}: met on {v['met']} of {v['of']}" for bar, v in summary["bars_met"].items() if v["of"]]
    for key, v in summary["spread"].items():
        rows.append(f"{key}: median {v['median']:.4g}, worst {v['worst']:.4g} ({v['worst_mission']})")
    return "\n".join(rows)


def comparison_table(pairs: dict) -> str:
    """Markdown table of `sweep.compare`: baseline → this sweep for each mission."""
    rows = ["| mission | med cm | p95 cm | lost photos | cov | rooms | given up % | obstacles met | s |",
            "|" + "---|" * 9]
    for name, c in pairs.items():
        arrow = lambda k, f: " → ".join("—" if v is None else f(v) for v in c[k])  # noqa: E731
        rows.append(f"| {name} | {arrow('median_m', _cm)} | {arrow('p95_m', _cm)} | {arrow('lost_photos', str)} | "
                    f"{arrow('coverage', '{:.3f}'.format)} | {arrow('rooms', str)} | {arrow('given_up', _cm)} | "
                    f"{arrow('obstacles', str)} | {arrow('seconds', '{:.0f}'.format)} |")
    return "\n".join(rows)


def explore_flags(text: str, own: set[str]) -> list[str]:
    """`--explore-flags`' words, checked against `ibrnav explore`'s own flags before any mission
    runs (a typo would otherwise fail every mission alike); the flags in `own`, which the
    sweep sets itself, are refused, and so are abbreviations (written after the sweep's own,
    `--phot 3` would silently override its `--photos`)."""
    from ibrnav.cli import Parser
    from ibrnav.commands import explore

    words = shlex.split(text)
    if clash := sorted(own & {w.split("=")[0] for w in words}):
        raise EvalMissionsError(f"--explore-flags {text!r}: {', '.join(clash)} is set by eval-missions itself")
    subparsers = Parser(prog="ibrnav").add_subparsers()
    explore.register(subparsers)
    parser = subparsers.choices["explore"]
    parser.exit_on_error, parser.allow_abbrev = False, False
    try:
        _, unknown = parser.parse_known_args(["synthetic:office", *words])
    except argparse.ArgumentError as e:
        raise EvalMissionsError(f"--explore-flags {text!r}: {e}") from None
    if unknown:
        raise EvalMissionsError(f"--explore-flags {text!r}: not flags of `ibrnav explore`: {' '.join(unknown)}")
    return words


def run(args: argparse.Namespace) -> int:
    from robot.mission.sweep import (compare, explore_command, load_reports, mission_name, parse_worlds, run_sweep,
                                     summarise)

    try:
        worlds = parse_worlds(args.worlds)
    except ValueError as e:
        raise EvalMissionsError(str(e)) from None
    out = Path(args.out)
    if args.baseline and not Path(args.baseline).is_dir():
        raise EvalMissionsError(f"--baseline {args.baseline}: no such folder (a folder an earlier sweep wrote)")
    options = ["--photos", str(args.photos), "--random-photos", str(args.random_photos),
               "--achievable-poses", str(args.achievable_poses), "--eval-poses", str(args.eval_poses)]
    own = {w for w in explore_command(*worlds[0], "adaptive", out, options) if w.startswith("--")}
    options += explore_flags(args.explore_flags, own)
    failed = []
    if not args.summary_only:
        strategies = ("adaptive", "random") if args.random else ("adaptive",)
        log.info(f"{len(worlds) * len(strategies)} missions, {args.jobs} at a time, into {out}")
        failed = run_sweep(worlds, out, options, args.jobs, strategies, args.timeout,
                           seed_offset=args.mission_seed_offset)
    elif not out.is_dir():
        raise EvalMissionsError(f"{out}: no such folder (run the sweep first, without --summary-only)")
    wanted = {mission_name(w, s) for w, s in worlds}
    reports = {n: r for n, r in load_reports(out).items() if n.split(".")[0] in wanted}
    if not any("." not in n for n in reports):
        raise EvalMissionsError(f"{out}: none of the {len(wanted)} missions asked for has a report")
    summary = {**summarise(reports), "jobs": args.jobs, "mission_seed_offset": args.mission_seed_offset,
               "failed": failed}
    print(table(summary))
    if args.baseline:
        summary["baseline"] = {"folder": str(args.baseline), "missions": compare(load_reports(Path(args.baseline)),
                                                                                 reports)}
        print()
        print(comparison_table(summary["baseline"]["missions"]))
    jsonout.write(args.json or out / "summary.json", summary)
    return 1 if failed else 0


def register(subparsers) -> None:
    e = subparsers.add_parser("eval-missions", help="the capture mission over many worlds, against the issue's bars")
    e.add_argument("--worlds", default="apartment:0-9,office:0-4",
                   help="WORLD:SEED or WORLD:FIRST-LAST, comma-separated")
    e.add_argument("--out", required=True, help="folder of the missions' JSONs and logs (kept; a mission already "
                   "there is not run again)")
    e.add_argument("--photos", type=int, default=261, help="photo budget of each mission")
    e.add_argument("--random-photos", type=int, default=108, help="photos of the random stage")
    e.add_argument("--jobs", type=int, default=1, help="missions at once (their seconds grow with it: the "
                   "5-minute bar is for a mission alone on 2 cores)")
    e.add_argument("--random", action="store_true", help="also the random strategy at the same budget")
    e.add_argument("--achievable-poses", type=int, default=2000, help="explore's --achievable-poses (0: none)")
    e.add_argument("--eval-poses", type=int, default=50, help="explore's --eval-poses (0: none)")
    e.add_argument("--explore-flags", default="", help="further `ibrnav explore` flags for every mission, as one "
                   "string (e.g. --explore-flags=--bundle-adjust); a folder's missions are not run again, so "
                   "give each setting its own --out")
    e.add_argument("--mission-seed-offset", type=int, default=0, help="seed each mission's own draws (start, "
                   "noise, planner) this far from its world's seed: another offset, into another --out, is a "
                   "second run of the same worlds (one run per world cannot tell a change from the draw)")
    e.add_argument("--timeout", type=float, default=3000.0, help="seconds after which a mission is stopped")
    e.add_argument("--baseline", default=None, help="another sweep's folder, set beside this one")
    e.add_argument("--summary-only", action="store_true", help="read --out's reports without running a mission")
    e.add_argument("--json", default=None, help="write the summary here (default: OUT/summary.json)")
    e.set_defaults(func=run)
