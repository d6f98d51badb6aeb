"""What the hostile corpus shares: running a command in this process through ``experiments.cli.main`` and
checking what it printed.

A case passes when the command exits non-zero (never a silent 0), prints no traceback from the project's
code (a plug-in's own exception may be shown once, with its traceback, its last frame in the plug-in's
file) and, where the case says so, names what is wrong. The work a command would start (an episode, a
sweep's tasks, a simulation) is replaced by ``Reached``: a case that gets that far was accepted, which
for a broken input is the silent acceptance the corpus is there to catch.
"""
from __future__ import annotations

import re

import pytest

from cli_in_process import run_main

TRACEBACK = "Traceback (most recent call last)"


class Reached(BaseException):
    """Raised in place of the work a command starts: the input got through validation."""


def _refuse(*args, **kwargs):
    raise Reached("the command started its work")


@pytest.fixture
def no_work(monkeypatch):
    """Every command's work replaced by ``Reached`` (the modules that run episodes, sweeps, simulations)."""
    import experiments.episode as episode
    import experiments.simulate as simulate
    import experiments.sweep as sweep

    monkeypatch.setattr(episode, "run_episode", _refuse)
    monkeypatch.setattr(sweep, "run_episode", _refuse)
    monkeypatch.setattr(sweep, "run_tasks", _refuse)
    monkeypatch.setattr(simulate, "simulate", _refuse)


def cli(args: list[str], capsys) -> tuple[int, str, str]:
    """main(args) in this process: (exit status, stderr, stdout). Any other exception escaping main fails
    the test: it would have been a traceback."""
    code = run_main(args)
    out = capsys.readouterr()
    return code, out.err, out.out


def assert_refused(code: int, err: str, *names: str, status: int | None = None, plugin: str | None = None) -> None:
    """A broken input's outcome: a non-zero exit (``status`` when given), no traceback from the project's
    code, every text of ``names`` in stderr. ``plugin``: the file of a plug-in whose own traceback may
    appear once, with its last frame in that file."""
    assert code != 0, f"exit 0 on a broken input; stderr: {err[-2000:]}"
    if status is not None:
        assert code == status, (code, err[-2000:])
    tracebacks = err.count(TRACEBACK)
    if plugin is None:
        assert tracebacks == 0, err[-3000:]
        assert err.strip(), "no message"
        assert len(err.strip().splitlines()) <= 3, err[-3000:]
    else:
        assert tracebacks <= 1, err[-3000:]
        if tracebacks:
            frames = re.findall(r'File "([^"]+)"', err.split(TRACEBACK, 1)[1])
            assert frames and frames[-1].endswith(plugin), (plugin, frames)
    for name in names:
        assert name in err, (name, err[-2000:])
