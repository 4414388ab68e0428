"""The one progress bar of ibrnav: a tqdm on stderr, shown only when the package's logger
would print INFO. Library code reports with `logging.getLogger(__name__)` and, for long
loops, `progress(...)`; nothing is printed unless the application configures logging
(`ibrnav` does, with -q / -v), so the packages stay quiet when used from Python."""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterable

from tqdm import tqdm


def progress(iterable: Iterable | None, total: int | None = None, desc: str | None = None,
             logger: logging.Logger | None = None, initial: int = 0) -> tqdm:
    """`iterable` wrapped in a tqdm bar on stderr (count, rate and ETA), disabled unless
    `logger` (default: the `ibr` package logger, which `ibrnav` sets with the others) is
    enabled for INFO, so `ibrnav -q` hides it."""
    log = logger or logging.getLogger("ibr")
    return tqdm(iterable, total=total, desc=desc, file=sys.stderr, leave=False, dynamic_ncols=True,
                initial=initial, disable=not log.isEnabledFor(logging.INFO))


def counter(total: int | None, desc: str, logger: logging.Logger | None = None, initial: int = 0) -> tqdm:
    """A bar advanced by hand (`bar.update()`), for work counted in callbacks (photos taken
    by a mission, next-best views of a planner); shown under the same rule as `progress`.
    Close it (`bar.close()`) when the work ends."""
    return progress(None, total=total, desc=desc, logger=logger, initial=initial)
