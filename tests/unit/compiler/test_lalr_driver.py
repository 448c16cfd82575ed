"""The fast LALR loop (`compiler.lalr_driver`) and lark agree: on source that parses, the
same AST (spans included) and the same expression-depth verdict; on source that does not,
the driver gives up (and `parse_source` lets lark report, so diagnostics are lark's).
Checked on every example, every compiler case file and the fuzzers' generated programs."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from lark.exceptions import UnexpectedInput
from tests.unit.compiler.conftest import CASES_DIR, FUZZ, REPO
from tests.unit.compiler.test_fuzz import SEEDS, TOKENS, mutated, planted

from addt_dsl.compiler import parser as P
from addt_dsl.compiler.lalr_driver import NotParsed

FILES = sorted({*REPO.glob("examples/**/*.addt"), *CASES_DIR.glob("**/*.addt"), *REPO.glob("docs/**/*.addt"),
                *REPO.glob("tests/**/*.addt")})


def _both(text: str):
    """(lark's outcome, the driver's outcome): ('ok', AST, too_deep span) or ('error',)."""
    lark, builder, driver = P._parser()
    if not text.endswith("\n"):
        text += "\n"
    outcomes = []
    for run in (lambda: lark.parse(text), lambda: driver.parse(text)):
        with P._PARSE_LOCK:
            builder.path = "t.addt"
            builder.reset()
            try:
                tree = run()
            except (UnexpectedInput, NotParsed, RecursionError):
                outcomes.append(("error",))
            else:
                deep = builder.too_deep
                outcomes.append(("ok", tree, deep.span if deep is not None else None))
            finally:
                builder.reset()
    return outcomes


def test_the_corpus_is_large():
    assert len(FILES) > 80


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(REPO)))
def test_driver_equals_lark_on_every_file(path):
    text = path.read_text(encoding="utf-8", errors="replace")
    by_lark, by_driver = _both(text)
    assert by_driver == by_lark


def test_driver_equals_lark_on_deep_expressions():
    deep = "scenario d {\n  duration 1 s\n  param p = " + " + ".join(["1 m"] * 250) + "\n}\n"
    by_lark, by_driver = _both(deep)
    assert by_lark[0] == "ok" and by_lark[2] is not None  # over MAX_EXPR_DEPTH: the builder marks it
    assert by_driver == by_lark


@FUZZ
@given(mutated())
def test_driver_equals_lark_on_mutated_examples(text):
    by_lark, by_driver = _both(text)
    assert by_driver == by_lark


@FUZZ
@given(planted())
def test_driver_equals_lark_on_planted_faults(text):
    by_lark, by_driver = _both(text)
    assert by_driver == by_lark


@FUZZ
@given(st.lists(st.sampled_from(TOKENS), max_size=200).map(" ".join))
def test_driver_equals_lark_on_token_soup(text):
    by_lark, by_driver = _both(text)
    assert by_driver == by_lark


@FUZZ
@given(st.sampled_from(SEEDS), st.integers(0, 10_000), st.integers(0, 10_000))
def test_driver_equals_lark_on_splices(text, i, j):
    i, j = i % (len(text) + 1), j % (len(text) + 1)
    by_lark, by_driver = _both(text[:i] + text[j:])
    assert by_driver == by_lark
