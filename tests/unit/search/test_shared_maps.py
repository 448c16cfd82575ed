"""Counterexamples written to one directory (the pytest corpus, `addtc shrink --out`) share
one copy of each imported map, named by its content: a map is not copied per entry, and a
map edited since never overwrites the one an older entry replays."""

from __future__ import annotations

import shutil

from addt_dsl.compiler import compile_file
from addt_dsl.printer import compile_pinned
from addt_dsl.search import RunCache, Shrinker
from addt_dsl.search.artifacts import shared_map_name, write_counterexample
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

SCENARIO = """scenario town {
  duration 2 s
  road main import "town.xodr" road 1
  ego car on main lane -1 at 20 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
  }
  param gap = 30 m in [20 m, 40 m]
  agent lead car on main lane -1 at 20 m + gap speed 8 m/s
  expect {
    slow: always speed(ego) < 5 m/s
  }
  sweep {
    grid gap in [20, 40] m
  }
}
"""


def _shrunk(src, spec_index):
    plan = compile_file(src / "town.addt").plan
    spec = expand(plan).specs[spec_index]
    return Shrinker(spec, nominal_plan=plan, cache=RunCache(), max_simulations=2).run()


def test_counterexamples_share_one_map_file_named_by_content(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    shutil.copy(EXAMPLES / "maps" / "straight_500m.xodr", src / "town.xodr")
    (src / "town.addt").write_text(SCENARIO)
    out = tmp_path / "corpus"
    first = write_counterexample(_shrunk(src, 0), out, str(src / "town.addt"), animate=False)
    second = write_counterexample(_shrunk(src, 1), out, str(src / "town.addt"), animate=False)
    assert first.addt != second.addt
    maps = sorted(p.name for p in out.glob("*.xodr"))
    road = compile_file(src / "town.addt").plan.roads[0]
    assert maps == [shared_map_name(road)] and maps[0].startswith("town-"), maps
    assert f'import "{maps[0]}"' in first.addt.read_text() and f'import "{maps[0]}"' in second.addt.read_text()
    # The map changes: the next entry gets its own file; the older entries still replay theirs.
    (src / "town.xodr").write_text((src / "town.xodr").read_text().replace("<header", "<!-- edited -->\n<header", 1))
    third = write_counterexample(_shrunk(src, 0), out, str(src / "town.addt"), animate=False)
    assert len(list(out.glob("*.xodr"))) == 2
    assert (out / maps[0]).read_text() == (EXAMPLES / "maps" / "straight_500m.xodr").read_text()
    for entry in (first, second, third):
        compile_pinned(entry.addt.read_text(), path=str(entry.addt), base_dir=out)
