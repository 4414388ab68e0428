"""Logging for the `ibrnav` command: one handler on stderr for the packages' loggers
(`ibr`, `localization`, `explore`, `robot`, `ibrnav`), so stdout carries only a command's
result (JSON where it prints JSON). Lines are `[COMMAND  SECONDS s] message`; -q shows
warnings only (and hides progress bars), -v adds debug lines. Log lines go through
`tqdm.write`, so they print above a running progress bar (`ibr.progress`) instead of
through it."""

from __future__ import annotations

import logging
import sys
import time

from tqdm import tqdm

PACKAGES = ("ibrnav", "ibr", "localization", "explore", "robot")


class _TqdmHandler(logging.Handler):
    """Writes records to stderr through tqdm, which keeps an active bar below them."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            tqdm.write(self.format(record), file=sys.stderr)
        except Exception:  # a broken stderr must not stop the command
            self.handleError(record)


class _ElapsedFormatter(logging.Formatter):
    def __init__(self, tag: str):
        super().__init__()
        self.tag, self.t0 = tag, time.perf_counter()

    def format(self, record: logging.LogRecord) -> str:
        prefix = "" if record.levelno == logging.INFO else f"{record.levelname.lower()}: "
        return f"[{self.tag} {time.perf_counter() - self.t0:4.0f} s] {prefix}{record.getMessage()}"


def setup_logging(command: str, verbosity: int = 0) -> None:
    """Route the packages' log records to stderr. verbosity: -1 quiet (warnings), 0 progress
    (info, the default), 1 verbose (debug)."""
    level = {-1: logging.WARNING, 0: logging.INFO}.get(verbosity, logging.DEBUG)
    handler = _TqdmHandler()
    handler.setFormatter(_ElapsedFormatter(f"ibrnav {command}"))
    for name in PACKAGES:
        logger = logging.getLogger(name)
        logger.handlers = [h for h in logger.handlers if not isinstance(h, _TqdmHandler)] + [handler]
        logger.setLevel(level)
        logger.propagate = False
