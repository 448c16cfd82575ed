"""How the pytest plugin sizes its search from Hypothesis profiles."""

from addt_dsl.pytest_plugin import SEARCH_RUNS, search_runs_for


def test_profile_table():
    assert search_runs_for("default", 100, []) == 0
    assert search_runs_for("ci", 100, []) == SEARCH_RUNS["ci"] == 10
    assert search_runs_for("nightly", 1000, []) == 300
    assert search_runs_for("mine", 42, []) == 42  # unlisted profiles use max_examples


def test_ini_overrides():
    assert search_runs_for("ci", 100, ["ci=25", "nightly=5000"]) == 25
    assert search_runs_for("default", 100, ["default=3"]) == 3
    assert search_runs_for("ci", 100, ["ci=lots"]) == 10  # not a number: ignored


def test_nightly_profile_is_registered():
    from hypothesis import settings

    assert settings.get_profile("nightly").max_examples >= 300
