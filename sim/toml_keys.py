"""How many parts the longest dotted key of a TOML text has, found before the text is parsed.

Python's TOML parser spends time and memory quadratic in the parts of one dotted key (``a.a.a...``: a
40 KB key takes seconds and gigabytes), so a reader refuses a text whose keys are deeper than it allows
before parsing it. Shared by the scenario reader (sim.scenario_toml) and the configuration reader
(experiments.config), which may both import sim.
"""
from __future__ import annotations

import re

_BASIC = r'"(?:[^"\\\n]|\\.)*+"'  # a one-line string, escapes as TOML's
_LITERAL = r"'[^'\n]*+'"
_PART = rf"(?:[\w\-]++|{_BASIC}|{_LITERAL})"  # a bare or quoted key part, or a number's digits
# One pass, token after token, every alternative possessive and each one that starts matching also ending
# somewhere, so no character is read more than a few times. In order: multi-line strings (up to two
# quotes may end the text before the closing three; an unterminated one runs to the end of the text, as the
# parser, failing there, never reads what follows), runs of parts joined by dots (spaces around a dot
# allowed: a dotted key, a table name, or a number's point: 1.5 is two parts), one-line strings left
# unterminated (to the end of the line), comments, and the characters between.
_TOKEN = re.compile(rf'''
    (?P<text>"""(?:[^"\\]|\\[\s\S]|"{{1,2}}(?!"))*+(?:"{{3,5}}|\Z)
           |\'\'\'(?:[^']|'{{1,2}}(?!'))*+(?:'{{3,5}}|\Z))
  | (?P<run>{_PART}(?:[ \t]*+\.[ \t]*+{_PART})*+)
  | "[^\n]*+ | '[^\n]*+ | \#[^\n]*+ | [^"'\#\w\-]++ | [\s\S]
''', re.VERBOSE)
_QUOTED = re.compile(rf"{_BASIC}|{_LITERAL}")


def longest_key(text: str) -> int:
    """The most parts of any dotted key (or table name) in ``text``, dots inside quoted parts not counted;
    a number with a point counts as two parts, so the answer is never less than the true depth of a key.
    Time linear in the text."""
    most = 1
    for m in _TOKEN.finditer(text):
        run = m.group("run")
        if run is not None and "." in run:
            most = max(most, (_QUOTED.sub("", run) if ('"' in run or "'" in run) else run).count(".") + 1)
    return most
