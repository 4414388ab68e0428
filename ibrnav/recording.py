"""Rerun recording for every `ibrnav` command, the way rerun's examples do it:
`add_rerun_args` (rerun's standard --save / --connect / --headless ... flags), `rerun_setup`
and `rerun_teardown`. The entity tree is the same for every command (docs/ARCHITECTURE.md)."""

from __future__ import annotations

import argparse
import logging

import rerun as rr

SINK_FLAGS = ("save", "connect", "serve", "stdout", "headless", "serve_web", "serve_grpc")
log = logging.getLogger(__name__)


def add_rerun_args(parser: argparse.ArgumentParser) -> None:
    """rerun's standard --save/--connect/--headless/... flags."""
    rr.script_add_args(parser)


def recording_requested(args: argparse.Namespace) -> bool:
    """Whether the user gave a rerun sink flag (commands that record only when asked)."""
    return any(getattr(args, f, None) for f in SINK_FLAGS)


def rerun_setup(args: argparse.Namespace, app_id: str, default_save: str | None) -> None:
    """Start recording. With no sink flag given (and no viewer on a headless machine to
    spawn), record to `default_save` so a first run always leaves a file to open."""
    if default_save and not recording_requested(args):
        args.save = default_save
    rr.script_setup(args, app_id)
    rr.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    if getattr(args, "save", None):
        log.info("recording to %s (open it with: rerun %s)", args.save, args.save)


def rerun_teardown(args: argparse.Namespace) -> None:
    """End the recording: rerun's own teardown, then flush and close the sinks, so a
    `.rrd` is complete (footer included) when the command returns, also when the command
    ran in-process (a notebook, a test) rather than as its own process."""
    rr.script_teardown(args)
    rr.disconnect()
