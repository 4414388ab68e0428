"""Sweeps of the capture mission over many worlds, each mission checked against the bars of a
finished capture.

A result on one world or one seed is an anecdote: the missions are deterministic, but any
change to what the robot does moves its whole path, and single worlds swing by tens of
centimetres either way (the closing notes of issue 14). `run_sweep` runs `ibrnav explore`
once per world, a child process each, `jobs` at a time, and keeps each mission's JSON and log
in one folder; a sweep stopped half way runs again from where it stopped (a world whose JSON
is there is not run again). A mission's own draws (start, noise, planner) are seeded by its
world's seed plus an offset: a sweep at another offset, into another folder, is a second
draw of the same worlds, which tells a change's effect from the draw's. `mission_bars` reads
one mission's report against the bars of issue 14, `summarise` counts the worlds that meet
each bar and gives the median and the worst world of each figure, and `compare` sets two
sweeps side by side (a change against main).

Seconds: missions sharing the 2 cores take longer (apartment 6: 210 s alone, 423 s beside
another mission), so the summary records how many ran at once.
"""

from __future__ import annotations

import json
import logging
import re
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from ibr.errors import InputError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Bars:
    """The bars of a finished capture (issue 14, "Done when"): targets the issue sets, not
    settings of any method, so nothing here is tuned."""

    median_m: float = 0.05
    """Localisation error of the adaptive stage's photos, median (m)."""
    p95_m: float = 0.15
    """... and 95th percentile (m)."""
    heading_deg: float = 1.0
    """Heading error, median (degrees)."""
    scale: float = 0.01
    """Map scale error (fraction)."""
    given_up: float = 0.10
    """Goals given up, as a share of the goals tried."""
    seconds: float = 300.0
    """A mission on 2 cores."""
    over_random: float = 0.15
    """Coverage above the random strategy's at the same budget."""
    of_achievable: float = 0.90
    """Coverage as a share of the world's achievable coverage."""


BAR_NAMES = ("median", "p95", "heading", "scale", "rooms", "given_up", "seconds", "over_random", "of_achievable")
"""The bars `mission_bars` checks, in the order of the summary's table."""


def parse_worlds(spec: str) -> list[tuple[str, int]]:
    """[(world, seed)] of "apartment:0-9,office:0-4" (a seed, a range a-b, or both joined by
    commas: "apartment:1,3,office:0")."""
    out, world = [], None
    for part in (p.strip() for p in spec.split(",") if p.strip()):
        m = re.fullmatch(r"(?:([a-z_]+):)?(\d+)(?:-(\d+))?", part)
        if m is None or (m.group(1) is None and world is None):
            raise ValueError(f"--worlds: cannot read {part!r} (expected WORLD:SEED or WORLD:FIRST-LAST, "
                             "e.g. apartment:0-9,office:0-4)")
        world = m.group(1) or world
        first, last = int(m.group(2)), int(m.group(3) or m.group(2))
        if last < first:
            raise ValueError(f"--worlds: the range in {part!r} runs backwards")
        out += [(world, s) for s in range(first, last + 1)]
    if not out:
        raise ValueError("--worlds: no world given")
    return out


def mission_name(world: str, seed: int, strategy: str = "adaptive") -> str:
    """File stem of a mission's JSON and log in a sweep's folder."""
    return f"{world}_{seed}" + ("" if strategy == "adaptive" else f".{strategy}")


def explore_command(world: str, seed: int, strategy: str, out: Path, options: list[str],
                    seed_offset: int = 0) -> list[str]:
    """The `ibrnav explore` command line of one mission (`options`: further explore flags).
    The world is `seed`'s; the mission's own draws (start pose, noise, planner) come from
    `seed + seed_offset`: another offset is another run of the same worlds."""
    return [sys.executable, "-m", "ibrnav", "explore", f"synthetic:{world}?seed={seed}", "--strategy", strategy,
            "--seed", str(seed + seed_offset), "--headless", "--json",
            str(out / f"{mission_name(world, seed, strategy)}.json"), *options]


def run_sweep(worlds: list[tuple[str, int]], out: Path, options: list[str], jobs: int = 1,
              strategies: tuple[str, ...] = ("adaptive",), timeout_s: float = 3000.0, command=explore_command,
              seed_offset: int = 0) -> list[str]:
    """Run every mission of `worlds` x `strategies` not yet in `out` (no JSON there), `jobs` at
    once, each with its log in `out`/NAME.log, its own draws seeded `seed_offset` after its
    world's (`explore_command`); a mission past `timeout_s` is stopped. Returns the names of
    the missions that failed (non-zero exit or no JSON), each logged with its log."""
    out.mkdir(parents=True, exist_ok=True)
    todo = [(w, s, st) for w, s in worlds for st in strategies
            if not (out / f"{mission_name(w, s, st)}.json").exists()]
    if len(todo) < len(worlds) * len(strategies):
        log.info(f"{len(worlds) * len(strategies) - len(todo)} missions already in {out}: not run again")

    def one(world: str, seed: int, strategy: str) -> tuple[str, int, float]:
        name, t0 = mission_name(world, seed, strategy), time.perf_counter()
        with open(out / f"{name}.log", "w") as f:
            try:
                rc = subprocess.run(command(world, seed, strategy, out, options, seed_offset), stdout=f,
                                    stderr=subprocess.STDOUT, timeout=timeout_s).returncode
            except subprocess.TimeoutExpired:
                rc = -1
        return name, rc, time.perf_counter() - t0

    failed = []
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = [pool.submit(one, *t) for t in todo]
        for k, fut in enumerate(as_completed(futures), 1):
            name, rc, seconds = fut.result()
            ok = rc == 0 and (out / f"{name}.json").exists()
            if not ok:
                failed.append(name)
            log.info(f"{k}/{len(todo)} {name}: " + (f"done in {seconds:.0f} s" if ok else
                     f"FAILED ({'timed out' if rc == -1 else f'exit {rc}'}; see {out / (name + '.log')})"))
    return failed


def load_reports(folder: Path) -> dict[str, dict]:
    """{mission name: explore report} of every JSON in `folder` but the sweep's summary; a
    JSON that does not read is an error naming it (`InputError`)."""
    reports = {}
    for path in sorted(Path(folder).glob("*.json")):
        if path.name == "summary.json":
            continue
        try:
            reports[path.stem] = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise InputError(f"{path}: not an explore report ({e})") from None
    return reports


def mission_figures(report: dict) -> dict:
    """The figures the bars read from one adaptive mission's explore report, and its lost photos
    (> 15 cm) and obstacles met (its drives a bumper stopped), which `compare` sets side by
    side; None where the report has none (a world without rooms, a mission that never
    localised, a report from before `obstacles_met`)."""
    loc = report.get("localization_error_m") or {}
    reached, given_up = report.get("goals_reached") or 0, report.get("goals_given_up") or 0
    rooms = report.get("rooms")
    return {"median_m": loc.get("median"), "p95_m": loc.get("p95"),
            "heading_deg": (report.get("heading_error_deg") or {}).get("median"),
            "scale": report.get("map_scale_error"),
            "given_up": given_up / (reached + given_up) if reached + given_up else None,
            "rooms": None if not rooms else f"{len(report.get('rooms_visited') or [])}/{len(rooms)}",
            "all_rooms": None if not rooms else set(report.get("rooms_visited") or []) >= set(rooms),
            "seconds": report.get("seconds"), "coverage": report.get("coverage"),
            "achievable": report.get("achievable_coverage"), "stopped_because": report.get("stopped_because"),
            "lost_photos": (report.get("lost_photos") or {}).get("lost"),
            "obstacles": sum(report["obstacles_met"].values()) if "obstacles_met" in report else None}


def mission_bars(report: dict, random_report: dict | None = None, bars: Bars = Bars()) -> dict[str, bool | None]:
    """{bar: met} of one adaptive mission (None: the report cannot say, e.g. no random arm or
    no achievable coverage)."""
    f = mission_figures(report)
    below = lambda v, bar: None if v is None else bool(v <= bar)  # noqa: E731
    cov, achievable = f["coverage"], f["achievable"]
    random_cov = None if random_report is None else random_report.get("coverage")
    over_random = None if random_cov is None or cov is None else bool(cov >= random_cov + bars.over_random)
    of_achievable = None if not achievable or cov is None else bool(cov >= bars.of_achievable * achievable)
    return {"median": below(f["median_m"], bars.median_m), "p95": below(f["p95_m"], bars.p95_m),
            "heading": below(f["heading_deg"], bars.heading_deg), "scale": below(f["scale"], bars.scale),
            "rooms": f["all_rooms"], "given_up": below(f["given_up"], bars.given_up),
            "seconds": below(f["seconds"], bars.seconds), "over_random": over_random, "of_achievable": of_achievable}


def summarise(reports: dict[str, dict], bars: Bars = Bars()) -> dict:
    """Per adaptive mission its figures and bars (its random arm, NAME.random, read beside it);
    per bar how many missions meet it of those that can say; per figure the median and the
    worst mission."""
    missions = {}
    for name, rep in sorted(reports.items()):
        if rep.get("strategy", "adaptive") != "adaptive":
            continue
        rand = reports.get(f"{name}.random")
        missions[name] = {**mission_figures(rep), "random_coverage": None if rand is None else rand.get("coverage"),
                          "bars": mission_bars(rep, rand, bars)}
    met = {}
    for bar in BAR_NAMES:
        said = [m["bars"][bar] for m in missions.values() if m["bars"][bar] is not None]
        met[bar] = {"met": sum(said), "of": len(said)}
    spread = {}
    for key, worst in (("median_m", max), ("p95_m", max), ("heading_deg", max), ("scale", max),
                       ("given_up", max), ("seconds", max), ("coverage", min)):
        vals = {n: m[key] for n, m in missions.items() if m[key] is not None}
        if vals:
            w = worst(vals, key=vals.get)
            spread[key] = {"median": statistics.median(vals.values()), "worst": vals[w], "worst_mission": w}
    return {"missions": missions, "bars_met": met, "spread": spread}


def compare(before: dict[str, dict], after: dict[str, dict]) -> dict[str, dict]:
    """{mission: {figure: [before, after]}} of the adaptive missions in both sweeps, for the
    figures a change is judged on (localisation, lost photos, coverage, rooms, goals, seconds)."""
    out = {}
    for name in sorted(set(before) & set(after)):
        b, a = before[name], after[name]
        if b.get("strategy", "adaptive") != "adaptive":
            continue
        fb, fa = mission_figures(b), mission_figures(a)
        out[name] = {k: [fb[k], fa[k]]
                     for k in ("median_m", "p95_m", "lost_photos", "coverage", "rooms", "given_up", "obstacles",
                               "seconds")}
    return out
