from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="session")
def overtake_source() -> str:
    return (EXAMPLES / "overtake.addt").read_text(encoding="utf-8")
