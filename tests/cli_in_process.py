"""``experiments.cli.main`` run in this process for the generated corpora of malformed input (thousands of
cases): one parser, built once, parses every case's arguments (a command builds its parser anew each run,
which costs about as much as refusing the case)."""
from __future__ import annotations

from unittest import mock

import experiments.cli as cli

_BUILD = cli.build_parser
_PARSER = []  # the one parser, built on first use


def _parser():
    if not _PARSER:
        _PARSER.append(_BUILD())
    return _PARSER[0]


def run_main(args: list) -> int:
    """main(args) with the shared parser: the exit status, a SystemExit's as the interpreter would give it
    (None: 0, a number: itself, anything else: 1). Any other exception escapes: it would have been a
    traceback."""
    with mock.patch.object(cli, "build_parser", _parser):
        try:
            return cli.main([str(a) for a in args])
        except SystemExit as e:
            return 0 if e.code is None else e.code if isinstance(e.code, int) else 1
