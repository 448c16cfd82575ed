"""Malformed and hostile distribution files: a diagnostic with the line, never a traceback
(a bounded mutation test with Hypothesis, and the classic attacks by name)."""

from __future__ import annotations

import shutil

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from addt_dsl.interop.openscenario.importer import import_xosc
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"
VALID = """<?xml version="1.0" encoding="UTF-8"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="2" date="2026-12-06T00:00:00" description="v" author="t"/>
  <ParameterValueDistribution>
    <ScenarioFile filepath="acc-test.xosc"/>
    <Deterministic>
      <DeterministicSingleParameterDistribution parameterName="EgoS">
        <DistributionRange stepWidth="5"><Range lowerLimit="10" upperLimit="20"/></DistributionRange>
      </DeterministicSingleParameterDistribution>
      <DeterministicMultiParameterDistribution>
        <ValueSetDistribution>
          <ParameterValueSet><ParameterAssignment parameterRef="TargetS" value="80"/></ParameterValueSet>
        </ValueSetDistribution>
      </DeterministicMultiParameterDistribution>
    </Deterministic>
  </ParameterValueDistribution>
</OpenSCENARIO>
"""
STOCHASTIC = VALID.replace("""    <Deterministic>
      <DeterministicSingleParameterDistribution parameterName="EgoS">
        <DistributionRange stepWidth="5"><Range lowerLimit="10" upperLimit="20"/></DistributionRange>
      </DeterministicSingleParameterDistribution>
      <DeterministicMultiParameterDistribution>
        <ValueSetDistribution>
          <ParameterValueSet><ParameterAssignment parameterRef="TargetS" value="80"/></ParameterValueSet>
        </ValueSetDistribution>
      </DeterministicMultiParameterDistribution>
    </Deterministic>""", """    <Stochastic numberOfTestRuns="3" randomSeed="7">
      <StochasticDistribution parameterName="EgoS">
        <NormalDistribution expectedValue="20" variance="4"/>
      </StochasticDistribution>
      <StochasticDistribution parameterName="TargetS">
        <ProbabilityDistributionSet>
          <Element value="80" weight="1"/><Element value="90" weight="2"/>
        </ProbabilityDistributionSet>
      </StochasticDistribution>
    </Stochastic>""")
HOSTILE_VALUES = ["", "-1", "0", "nan", "inf", "-inf", "1e400", "1e300", "1e-320", "$nobody", "${1/0}", "${2**99999}",
                  "${(((((1)))))}", "x" * 300, "4294967296", "0.5", "acc-test.xosc", "../../../etc/passwd",
                  "/etc/passwd", "variation.xosc", "1,5", " 7 "]


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile") / "esmini"
    shutil.copytree(ESMINI, root)
    return root


def check(corpus, text: str):
    path = corpus / "xosc" / "variation.xosc"
    path.write_text(text)
    got = import_xosc(path, root=corpus)  # must not raise
    assert (got.text is None) == any(d.is_error for d in got.diagnostics)
    for d in got.diagnostics:
        assert d.code != "E0900"
        if d.is_error:
            assert d.span is not None and d.span.line >= 1 and d.span.file, d
    return got


def test_the_valid_files_import(corpus):
    assert check(corpus, VALID).text is not None
    assert check(corpus, STOCHASTIC).text is not None


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_files_are_diagnostics(corpus, data):
    text = data.draw(st.sampled_from([VALID, STOCHASTIC]))
    for _ in range(data.draw(st.integers(1, 3))):
        how = data.draw(st.sampled_from(["value", "cut", "insert", "duplicate"]))
        if how == "value":  # an attribute value replaced by a hostile one
            quotes = [i for i, c in enumerate(text) if c == '"']
            k = data.draw(st.integers(0, len(quotes) // 2 - 1)) * 2
            a, b = quotes[k], quotes[k + 1]
            text = text[:a + 1] + data.draw(st.sampled_from(HOSTILE_VALUES)) + text[b:]
        elif how == "cut":  # a span of text removed (tags broken, elements lost)
            a = data.draw(st.integers(0, len(text) - 1))
            text = text[:a] + text[a + data.draw(st.integers(1, 80)):]
        elif how == "insert":
            a = data.draw(st.integers(0, len(text)))
            text = text[:a] + data.draw(st.sampled_from(["<", ">", "&", "<X/>", "</Deterministic>", "\x00", "é",
                                                          '"', "<Stochastic numberOfTestRuns=\"1\"/>"])) + text[a:]
        else:  # a line repeated (an element twice)
            lines = text.split("\n")
            k = data.draw(st.integers(0, len(lines) - 1))
            text = "\n".join(lines[:k + 1] + lines[k:])
    check(corpus, text)


@pytest.mark.parametrize("text, code", [
    ('<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;">]>\n'
     "<OpenSCENARIO><ParameterValueDistribution>&lol2;</ParameterValueDistribution></OpenSCENARIO>", "E0801"),
    (VALID.replace('filepath="acc-test.xosc"', 'filepath="../../../../../../etc/passwd"'), "E0402"),
    (VALID.replace('filepath="acc-test.xosc"', 'filepath="variation.xosc"'), "E0802"),  # itself
    (VALID.replace('filepath="acc-test.xosc"', 'filepath="missing.xosc"'), "E0401"),
    (VALID[:400], "E0801"),  # truncated
])
def test_known_attacks(corpus, text, code):
    got = check(corpus, text)
    assert got.text is None and any(d.code == code for d in got.diagnostics), \
        [(d.code, d.message) for d in got.diagnostics]
