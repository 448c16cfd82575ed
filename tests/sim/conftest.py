from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="session")
def overtake_source() -> str:
    return (EXAMPLES / "overtake.addt").read_text(encoding="utf-8")


OVERTAKE_LIDAR = "sensor lidar rate 10 Hz rays 360 range 80 m"


@pytest.fixture(scope="session")
def learned_overtake_source(overtake_source) -> str:
    """The overtake example with the lidar the learned detector is trained for."""
    from addt_dsl.stack.bev_grid import DETECTOR_LIDAR

    assert OVERTAKE_LIDAR in overtake_source
    return overtake_source.replace(OVERTAKE_LIDAR, DETECTOR_LIDAR.clause())
