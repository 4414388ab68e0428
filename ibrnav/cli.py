"""`ibrnav`: the one console script. Each command is one module of `ibrnav.commands` with
`register(subparsers)` (its flags) and `run(args)`. `COMMANDS` names each command's module
and one-line help, so `ibrnav --help` lists them without importing any of them, and
`ibrnav CMD ...` imports CMD's module alone (the library code it needs comes with it).
Global flags: -q / -v set how much goes to stderr (`ibrnav.log`), --version."""

from __future__ import annotations

import argparse
import importlib
import logging
from importlib.metadata import PackageNotFoundError, version

from ibrnav.log import setup_logging

COMMANDS: dict[str, tuple[str, str]] = {
    "scene": ("ibrnav.commands.scene", "inspect scenes"),
    "render": ("ibrnav.commands.render", "render novel views of a scene (ULR, light field, nearest view)"),
    "sfm": ("ibrnav.commands.sfm", "pose unposed photos (FOLDER/images) with COLMAP via pycolmap"),
    "eval-ibr": ("ibrnav.commands.eval_ibr", "leave-one-out PSNR/SSIM/coverage of the renderers"),
    "localize": ("ibrnav.commands.localize", "localise one photo against a posed scene (pnp, pf, hybrid)"),
    "eval-loc": ("ibrnav.commands.eval_loc", "leave-one-out localisation of a scene's photos"),
    "eval-track": ("ibrnav.commands.eval_track", "particle-filter tracking + kidnapping in a synthetic world"),
    "eval-capture": ("ibrnav.commands.eval_capture", "ULR of a capture's final model against the world's true views"),
    "eval-missions": ("ibrnav.commands.eval_missions", "the capture mission over many worlds, against the issue's bars"),
    "drive": ("ibrnav.commands.drive", "a robot drives a loop in synthetic:office, recorded to rerun"),
    "demo": ("ibrnav.commands.demo", "the autonomous scene-capture mission in synthetic:office"),
    "explore": ("ibrnav.commands.explore", "run a capture strategy in a synthetic scene with a photo budget"),
    "vueplan": ("ibrnav.commands.vueplan", "VuePlan two-phase view planning on a site (Blaer & Allen)"),
    "scenic": ("ibrnav.commands.scenic", "scenic route planning with one or two cameras (Mendez et al.)"),
    "robot": ("ibrnav.commands.robot_check", "the real robot (LEGO NXT over Bluetooth serial)"),
    "bench": ("ibrnav.commands.bench", "run the speed figures (JSON out)"),
    "export": ("ibrnav.commands.export", "write a scene as a COLMAP model and/or a (textured) mesh file"),
}
"""command name -> (module with register/run, one-line help for `ibrnav --help`)."""
log = logging.getLogger("ibrnav")


class HelpFormatter(argparse.HelpFormatter):
    """argparse's help with each option's default appended, as ArgumentDefaultsHelpFormatter
    does, but not for defaults that say nothing (None, False, an empty list)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        d = action.default
        if ("%(default)" not in text and not (d is None or d is False or d == [] or d == argparse.SUPPRESS)
                and (action.option_strings or action.nargs in ("?", "*"))):
            text += " (default: %(default)s)"
        return text


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose help shows defaults; its sub-parsers inherit the class."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)


def _version() -> str:
    try:
        return version("ibrnav")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown"


def _requested(argv: list[str]) -> str | None:
    """The command named in argv (the first word that is one), or None."""
    return next((a for a in argv if a in COMMANDS), None)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The `ibrnav` parser. With argv, only the command argv names is imported and given its
    flags (the others are listed by name and help); without, every command is."""
    parser = Parser(prog="ibrnav", description="Image-based rendering, localisation and view planning "
                    "for robots that see with a camera. Every command records to rerun.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    parser.add_argument("-q", "--quiet", action="count", default=0,
                        help="only warnings and errors on stderr (no progress bars)")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="debug lines on stderr too")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    wanted = list(COMMANDS) if argv is None else [_requested(argv)]
    for name, (module, help_line) in COMMANDS.items():
        if name in wanted:
            importlib.import_module(module).register(sub)
        else:
            sub.add_parser(name, help=help_line, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    import sys

    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    setup_logging(args.command, args.verbose - args.quiet)
    from ibr.errors import InputError
    from ibr.gl import GLContextError

    args.command_line = ["ibrnav", *argv]  # the recording logs it (ibrnav.recording)
    try:
        return int(args.func(args) or 0)
    except (InputError, GLContextError) as e:  # they name the bad input: no traceback
        log.error("%s", e)
        return 2
