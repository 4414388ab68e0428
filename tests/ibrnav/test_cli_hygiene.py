"""The `ibrnav` command line itself: subcommands are imported only when run, every option
has help text with its default shown, and every command's --help works."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from ibrnav.cli import COMMANDS, build_parser


def _subparsers(parser: argparse.ArgumentParser, path=()):
    """(command path, parser) of every (sub)command under parser."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*path, name), sub
                yield from _subparsers(sub, (*path, name))


def test_top_level_help_imports_no_command_and_no_heavy_library():
    code = ("import sys\nfrom ibrnav.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print('IMPORTED:', ' '.join(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('moderngl', 'pycolmap', 'rerun', 'trimesh', 'cv2', 'numpy', 'ibr', 'localization', 'explore', "
            "'robot') or m.startswith('ibrnav.commands.'))))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "usage: ibrnav" in run.stdout and "eval-loc" in run.stdout
    imported = run.stdout.split("IMPORTED:")[1].split()
    assert imported == [], imported


def test_a_command_imports_its_own_module_only():
    parser = build_parser(["drive", "--max-legs", "1"])
    (_, sub), = [(a, a) for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    real = [n for n, p in sub.choices.items() if p.add_help]
    assert real == ["drive"]
    assert parser.parse_args(["drive", "--max-legs", "1"]).max_legs == 1


def test_the_commands_table_names_the_command_each_module_registers():
    for name, (module, _) in COMMANDS.items():
        parser = build_parser([name])
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        assert sub.choices[name].add_help, (name, module)  # registered by its module, not a stub


def test_every_option_has_help_and_shows_its_default():
    missing, hidden = [], []
    for path, sub in _subparsers(build_parser()):
        for a in sub._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            if not a.help:
                missing.append((path, a.option_strings or a.dest))
            elif a.option_strings and not (a.default is None or a.default is False or a.default == []):
                text = sub._get_formatter()._expand_help(a)  # the help line as --help prints it
                if str(a.default) not in text:
                    hidden.append((path, a.option_strings, text))
    assert not missing, missing
    assert not hidden, hidden


@pytest.mark.parametrize("name", list(COMMANDS))
def test_help_of_every_command_works(name, capsys):
    parser = build_parser([name])
    nested = [p for path, p in _subparsers(parser) if path[0] == name]
    for argv in [[name, "--help"]] + [[*path, "--help"] for path, _ in _subparsers(parser)
                                       if path[0] == name and len(path) > 1]:
        with pytest.raises(SystemExit) as e:
            build_parser(argv).parse_args(argv)
        assert e.value.code == 0
        assert f"usage: ibrnav {' '.join(argv[:-1])}" in capsys.readouterr().out
    assert nested
