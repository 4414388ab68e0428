"""A watchdog for the mission's steps: a step that runs longer than its limit is an error with
a clear message (`StepTimeout`), never a silent stall.

`watchdog(step, limit_s)` arms a SIGALRM timer (main thread only: signals reach no other
thread) whose handler raises `StepTimeout` naming the step, and `faulthandler` to dump every
thread's stack at the same moment: Python delivers the signal only between bytecodes, so a
step stuck inside a C library (COLMAP, Poisson, a GL read-back) raises when that call
returns, and the dump shows where it was stuck meanwhile. Elsewhere than the main thread, or
with no limit, the watchdog only times the step.
"""

from __future__ import annotations

import faulthandler
import logging
import signal
import sys
import threading
import time
from contextlib import contextmanager

log = logging.getLogger(__name__)


class StepTimeout(RuntimeError):
    """A mission step ran past its time limit."""


@contextmanager
def watchdog(step: str, limit_s: float | None):
    """Run the body as the mission step `step`; raise `StepTimeout` when it takes longer
    than `limit_s` seconds (None or <= 0: no limit). Logs the step's duration at debug level."""
    armed = bool(limit_s and limit_s > 0) and threading.current_thread() is threading.main_thread()
    t0 = time.perf_counter()

    def expired(signum, frame):
        raise StepTimeout(f"mission step '{step}' took more than {limit_s:.0f} s (the step limit; "
                          f"the stack of every thread was dumped to stderr)")

    if armed:
        previous = signal.signal(signal.SIGALRM, expired)
        faulthandler.dump_traceback_later(limit_s, exit=False, file=sys.stderr)
        signal.setitimer(signal.ITIMER_REAL, limit_s)
    try:
        yield
    finally:
        if armed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            faulthandler.cancel_dump_traceback_later()
            signal.signal(signal.SIGALRM, previous)
        log.debug(f"{step}: {time.perf_counter() - t0:.1f} s")
