"""The Euro NCAP AEB suites expand to the cells docs/stack.md lists."""

import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

KMH = 1.0 / 3.6


def cells(name: str) -> list[dict]:
    result = compile_file(EXAMPLES / "suites" / f"ncap_aeb_{name}.addt")
    assert result.ok, [d.message for d in result.diagnostics]
    return [spec.params for spec in expand(result.plan).specs]


def speeds_kmh(params: list[dict], name: str = "ego_speed") -> list[float]:
    return sorted({round(p[name] / KMH, 6) for p in params})


@pytest.mark.parametrize("suffix", ["", pytest.param("_learned", marks=pytest.mark.torch)])
def test_car_to_car_cells(suffix):
    if suffix:
        pytest.importorskip("torch")  # `perception learned` compiles only with the learned extra
    assert speeds_kmh(cells("ccrs" + suffix)) == [10, 20, 30, 40, 50]
    ccrm = cells("ccrm" + suffix)
    assert speeds_kmh(ccrm) == [30, 40, 50, 60, 70, 80] and speeds_kmh(ccrm, "target_speed") == [20]
    assert sorted((p["headway"], p["target_decel"]) for p in cells("ccrb" + suffix)) == [
        (12.0, 2.0), (12.0, 6.0), (40.0, 2.0), (40.0, 6.0)]


@pytest.mark.torch
def test_learned_variants_run_the_detector_on_its_lidar():
    pytest.importorskip("torch")
    for name in ("ccrs", "ccrm", "ccrb", "cpna", "cpfa", "cbla"):
        plan = compile_file(EXAMPLES / "suites" / f"ncap_aeb_{name}_learned.addt").plan
        assert plan.ego.stack.settings["perception"] == "learned"


@pytest.mark.parametrize("suffix", ["", pytest.param("_learned", marks=pytest.mark.torch)])
def test_vulnerable_road_user_cells(suffix):
    if suffix:
        pytest.importorskip("torch")
    cpna = cells("cpna" + suffix)
    assert sorted({p["impact_at"] for p in cpna}) == [0.25, 0.75]
    assert speeds_kmh(cpna) == [10, 20, 30, 40, 50, 60] and speeds_kmh(cpna, "walk_speed") == [5]
    cpfa = cells("cpfa" + suffix)
    assert speeds_kmh(cpfa) == [10, 20, 30, 40, 50, 60] and speeds_kmh(cpfa, "walk_speed") == [8]
    cbla = cells("cbla" + suffix)
    assert speeds_kmh(cbla) == [25, 30, 40, 50, 60] and speeds_kmh(cbla, "rider_speed") == [15]
