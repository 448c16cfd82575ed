"""Every ```stl-example block in docs/oracles.md is a test."""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from tests.unit.runtime.oracles.stl_testkit import parse, robustness

from addt_dsl.runtime.oracles import satisfied

DOC = Path(__file__).resolve().parents[4] / "docs" / "oracles.md"
_BLOCK = re.compile(r"```stl-example\n(.*?)```", re.S)


def _examples():
    for i, block in enumerate(_BLOCK.findall(DOC.read_text())):
        period, signals, checks = None, {}, []
        for line in filter(None, (raw.strip() for raw in block.splitlines())):
            if "=>" in line:
                formula, want = line.split("=>")
                value, *verdict = want.split()
                checks.append((formula.strip(), float(value), verdict[0] if verdict else None))
            elif line.startswith("period:"):
                period = float(line.split(":")[1].split()[0])
            else:
                name, values = line.rsplit(":", 1)
                signals[name.strip()] = [float(v) for v in values.split(",")]
        for formula, value, verdict in checks:
            yield pytest.param(formula, signals, period, value, verdict, id=f"{i}:{formula}")


EXAMPLES = list(_examples())


def test_the_doc_has_examples():
    assert len(EXAMPLES) >= 15


@pytest.mark.parametrize("formula, signals, period, value, verdict", EXAMPLES)
def test_doc_example(formula, signals, period, value, verdict):
    got = robustness(formula, signals, period)
    assert got == value or math.isclose(got, value, abs_tol=1e-9), got
    if verdict is not None:
        arrays = {k: np.array(v) for k, v in signals.items()}
        assert satisfied(parse(formula), arrays, period) is (verdict == "satisfied")
