"""The road network: the OpenDRIVE file a scenario names, its roads as plan roads, speed limits."""

import re
from pathlib import Path

from addt_dsl.confine import Refused, confine
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.entities import safe_name
from addt_dsl.interop.openscenario.params import NAME_RE
from addt_dsl.interop.openscenario.xml import Stop, first_of
from addt_dsl.plan import RoadPlan
from addt_dsl.road import XodrError, parse_xodr


class Roads:
    # -- road network

    def road_network(self, root) -> None:
        logic = root.find("RoadNetwork/LogicFile")
        if logic is None:
            self.error(first_of(root.find("RoadNetwork"), root),
                       "no <RoadNetwork><LogicFile>: addt-dsl actors need a road")
            raise Stop
        got = self.read_road_network(self.raw(logic, "filepath"), logic)
        if got is None:
            raise Stop
        path, text = got
        if not path.name.lower().endswith(".xodr"):
            self.error(logic, f"'{path.name}' is not an OpenDRIVE file")
            raise Stop
        try:
            self.network = parse_xodr(text, path.name)
        except XodrError as exc:
            self.error(logic, f"cannot use {path.name}: {exc}", code="E0403")
            raise Stop from None
        except (ValueError, ArithmeticError, RecursionError) as exc:
            self.error(logic, f"cannot use {path.name}: {exc}", code="E0403")
            raise Stop from None
        self.xodr_name, self.xodr_text = path.name, text
        self.signals_el = root.find("RoadNetwork/TrafficSignals")
        for ctl in root.iterfind("RoadNetwork/TrafficSignals/TrafficSignalController"):
            self.signal_controller(ctl)

    def read_road_network(self, name: str, logic):
        """(path, text) of the road network `name` names: the file itself, relative to the
        scenario; else, for a name without `.xodr` (CARLA names its towns, `Town01`), NAME.xodr
        there or in a maps directory (`maps`); None after a diagnostic."""
        bare = not name.lower().endswith(".xodr")
        tries = [(name, self.path.parent, self.root)]
        if bare:
            tries.append((name + ".xodr", self.path.parent, self.root))
        if bare or Path(name).name == name:
            file = Path(name).name + (".xodr" if bare else "")
            tries += [(file, folder, folder) for folder in self.maps]
        looked = []
        for relative, base, root in tries:
            try:
                confine(relative, base, root)
            except Refused as refused:
                if refused.code == "E0401" and refused.message.startswith("cannot find"):
                    looked.append(str(base / relative))
                    continue
            if (relative, base) != (name, self.path.parent):
                self.sink.warning("W0803", f"road network '{name}' read from {base / relative}", self.span(logic),
                                  label="<LogicFile>")
            return self.read(relative, base, logic, root=root)
        self.error(logic, f"cannot find the road network '{name}'", "looked for " + ", ".join(looked),
                   "a map named without a folder is also looked for in each `--maps DIR`"
                   + (" (none given)" if not self.maps else ""), code="E0401")
        return None

    def road(self, road_id: str, el) -> str:
        if road_id not in self.network.roads:
            self.error(el, f"{self.xodr_name} has no road '{road_id}'")
            raise Stop
        if road_id not in self.roads:
            odr = self.network.road(road_id)
            name = safe_name(f"r{road_id}" if not odr.name or not NAME_RE.fullmatch(str(odr.name))
                              else str(odr.name), {r.name for r in self.roads.values()} | set(self.actors))
            if not re.fullmatch(r"\d+", road_id):
                self.error(el, f"road id '{road_id}' is not a number: the language imports roads by number")
                raise Stop
            self.roads[road_id] = RoadPlan(name=name, source="xodr", xodr_file=self.xodr_name,
                                           xodr_text=self.xodr_text, xodr_road_id=road_id)
        return self.roads[road_id].name

    def speed_limit_at(self, road_name: str, s) -> float | None:
        """The map's speed limit [m/s] where an actor is placed (None: the map gives none)."""
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        odr = self.network.road(road_id)
        try:
            return odr.speed_limit(min(max(float(eval_param_expr(s, self.param_values())), 0.0), odr.length))
        except (KeyError, ValueError, ArithmeticError):
            return None
