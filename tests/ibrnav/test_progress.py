"""Progress: one tqdm bar on stderr (count, rate, ETA) for long work, shown at the default
verbosity of `ibrnav` and hidden by -q; stdout keeps only the command's result."""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest

from ibr.progress import counter, progress
from ibrnav.log import setup_logging


@pytest.fixture
def restore_loggers():
    saved = {n: (logging.getLogger(n).handlers[:], logging.getLogger(n).level, logging.getLogger(n).propagate)
             for n in ("ibrnav", "ibr", "localization", "explore", "robot")}
    yield
    for n, (handlers, level, propagate) in saved.items():
        lg = logging.getLogger(n)
        lg.handlers, lg.level, lg.propagate = handlers, level, propagate


def test_the_bar_shows_at_the_default_verbosity_and_hides_when_quiet(capsys, restore_loggers):
    setup_logging("test", 0)
    assert list(progress(range(5), desc="trials")) == list(range(5))
    err = capsys.readouterr().err
    assert "trials:" in err and "0/5 [00:00<?" in err  # count / total [elapsed<ETA, rate]
    setup_logging("test", -1)
    assert list(progress(range(5), desc="trials")) == list(range(5))
    bar = counter(3, "photos")
    bar.update(3)
    bar.close()
    assert capsys.readouterr().err == ""


def test_library_code_is_silent_without_an_application_setting_up_logging(capsys, restore_loggers):
    for n in ("ibr", "explore"):
        logging.getLogger(n).setLevel(logging.NOTSET)
    logging.getLogger("ibr").handlers, logging.getLogger("ibr").propagate = [], True
    assert sum(progress(range(4), desc="views")) == 6
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_explore_counts_photos_on_stderr_and_q_silences_it(tmp_path):
    argv = ["explore", "synthetic:office", "--strategy", "random", "--photos", "8", "--random-photos", "8",
            "--circle-step-deg", "45"]
    loud = subprocess.run([sys.executable, "-m", "ibrnav", *argv], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert loud.returncode == 0, loud.stderr
    assert "photos:" in loud.stderr and "/8 [" in loud.stderr
    assert loud.stdout.startswith("random: coverage") and "photos:" not in loud.stdout
    quiet = subprocess.run([sys.executable, "-m", "ibrnav", "-q", *argv], capture_output=True, text=True,
                           timeout=300, cwd=tmp_path)
    assert quiet.returncode == 0 and quiet.stderr == "", quiet.stderr
