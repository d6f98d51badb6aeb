"""Comments and docstrings explain the code; trial results belong in docs/experiments.md.

Every comment (read with ``tokenize``) and docstring (read with ``ast``) of the packages dodt,
planner, sim and experiments is scanned for the marks of a research record: a p-value
(``p = 0.03``, ``p < 1e-4``), the seeds a trial ran on (``seeds 0-18``, ``40 seeds``) or its
success counts (``8 of 19 successes``). A hit names the file and line; move the figure to a dated
line of docs/experiments.md and leave the comment saying what the code means.
"""
from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dodt", "planner", "sim", "experiments")

NUMBER = r"(?:\d+(?:\.\d+)?(?:e-?\d+)?|\.\d+)"
PATTERNS = {
    # "p = 0.008", "p < 1e-4", "p <= 0.05", "p-value 0.03"; not p_hit, p95, p0 = 4 or "p = q + 1"
    # (lower case: "P = 2" is a matrix's weight)
    "p-value": re.compile(rf"(?<![\w.])p\s*(?:=|<=?|>=?|≤|≥)\s*{NUMBER}(?!\w|\.\d)"
                          rf"|\b[pP][- ]values?\s*(?:of|=|<|>)?\s*{NUMBER}"),
    # "seeds 0-18", "seeds 0:200", "seeds 3 and 4"; not the CLI's "--seeds 0:200"
    "seed range": re.compile(r"(?<![\w-])seeds?\s+\d+(?:\s*(?:-|–|\.\.|to|and)\s*\d+|:\d+)+\b", re.IGNORECASE),
    # "40 seeds", "200 dev seeds", "a 200-seed comparison"
    "seed count": re.compile(r"\b\d+\s+(?:(?:dev|test|fresh|more|other)\s+)?seeds\b|\b\d+-seed\b", re.IGNORECASE),
    # "8 of 19 successes", "75 -> 67 successes", "success 60 against 62", "45 % success"
    "success count": re.compile(
        r"\b\d+\s+(?:of|/|out of)\s+\d+\s+(?:successes|episodes|seeds|runs|trials)\b"
        r"|\b\d+\s+successes\b"
        r"|\bsuccess(?:es)?\s+\d+\s*(?:against|->|of|/)\s*\d+"
        rf"|\b{NUMBER}\s*%\s+success\b", re.IGNORECASE),
}


def _python_files(package: str) -> list[Path]:
    return sorted(p for p in (ROOT / package).rglob("*.py") if "__pycache__" not in p.parts)


def _comment_blocks(source: str) -> list[tuple[str, list[tuple[int, int]]]]:
    """Comments of consecutive lines joined into one text each (a figure may wrap from one line to
    the next), with (offset in the text, line number) of each line's start."""
    blocks: list[tuple[str, list[tuple[int, int]]]] = []
    text, starts, last = "", [], None
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type != tokenize.COMMENT:
            continue
        line = tok.start[0]
        if last is None or line != last + 1:
            if starts:
                blocks.append((text, starts))
            text, starts = "", []
        starts.append((len(text), line))
        text += tok.string.lstrip("#").strip() + " "
        last = line
    if starts:
        blocks.append((text, starts))
    return blocks


def _docstrings(source: str) -> list[tuple[str, list[tuple[int, int]]]]:
    """Each docstring's text with (offset, line number) of each of its lines' start."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        body = node.body
        if not (body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            continue
        text = body[0].value.value
        starts, offset = [], 0
        for i, line in enumerate(text.split("\n")):
            starts.append((offset, body[0].value.lineno + i))
            offset += len(line) + 1
        out.append((text, starts))
    return out


def research_record(source: str) -> list[tuple[int, str, str]]:
    """(line, kind, quoted text) of each research-record mark in the source's comments and docstrings."""
    hits = []
    for text, starts in _comment_blocks(source) + _docstrings(source):
        for kind, pattern in PATTERNS.items():
            for m in pattern.finditer(text):
                line = max(n for offset, n in starts if offset <= m.start())
                hits.append((line, kind, " ".join(m.group(0).split())))
    return sorted(set(hits))


@pytest.mark.parametrize("package", PACKAGES)
def test_no_research_record_in_comments(package):
    found = []
    for path in _python_files(package):
        for line, kind, quote in research_record(path.read_text(encoding="utf-8")):
            found.append(f"{path.relative_to(ROOT)}:{line}: {kind}: {quote!r}")
    assert not found, ("trial results in comments or docstrings (move them to a dated line of "
                       "docs/experiments.md):\n" + "\n".join(found))


@pytest.mark.parametrize("source", [
    "x = 1  # 20 Hz: 8 of 19 successes against 10 of 19 at 10 Hz\n",
    "# corridor seeds\n# 0-18, with the geofence\nx = 1\n",
    "# worse (p = 0.03)\nx = 1\n",
    "# sign test p < 1e-4\nx = 1\n",
    "# measured on 40 seeds\nx = 1\n",
    "# seeds 3 and 4, held out\nx = 1\n",
    "# 75 -> 67 successes\nx = 1\n",
    "# success 60 against 62\nx = 1\n",
    '"""Chosen on a 200-seed sweep."""\n',
    'def f():\n    """Within the churn,\n    p = 0.87."""\n',
])
def test_flags_research_record(source):
    assert research_record(source)


@pytest.mark.parametrize("source", [
    "def f(seed: int):\n    \"\"\"Run one episode; ``seed`` seeds the scenario's generator.\"\"\"\n",
    "p_hit = 0.2  # probability a ray hits, p_hit in [0, 1]\n",
    "# p95 and p99 of the plan time, in ms\nx = 1\n",
    "# ref e_p 0.25; p0 = 4 lets the measurements take over\nx = 1\n",
    '"""Usage: dodt-nav sweep corridor --seeds 400:600 --perception dodt"""\n',
    "# the same scenario and seed give the same episode\nx = 1\n",
    "# a point p = q + t * d on the ray\nx = 1\n",
    "# the QP's cost x' P x / 2 + q' x, P = 2 R on the inputs\nx = 1\n",
])
def test_leaves_legitimate_text(source):
    assert not research_record(source)
