"""Synthetic worlds generated in code from a seed: the embedded default for the main
command and most tests (no downloads). `make_world(name, seed)`; `WORLDS` lists names;
`tour_route(world)` is a route through any of them made from its floor plan."""

from __future__ import annotations

import functools

from ibr.synthetic.apartment import make_apartment
from ibr.synthetic.courtyard import make_courtyard
from ibr.synthetic.office import loop_route, make_office
from ibr.synthetic.routes import tour_route
from ibr.synthetic.world import Doorway, Room, SyntheticWorld

WORLDS = {"office": make_office, "courtyard": make_courtyard, "apartment": make_apartment}


@functools.lru_cache(maxsize=8)
def make_world(name: str, seed: int = 0) -> SyntheticWorld:
    """The world `name` (one of WORLDS) built from `seed`; cached per (name, seed)."""
    if name not in WORLDS:
        raise ValueError(f"unknown synthetic world {name!r}; choose one of {sorted(WORLDS)}")
    return WORLDS[name](seed)


__all__ = ["WORLDS", "Doorway", "Room", "SyntheticWorld", "loop_route", "make_world", "tour_route"]
