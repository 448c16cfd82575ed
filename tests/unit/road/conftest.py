from pathlib import Path

import pytest

DATA_DIR = Path(__file__).resolve().parents[2] / "data" / "xodr"
SAMPLE_MAPS = sorted(DATA_DIR.glob("*.xodr"))


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA_DIR
