"""OpenSCENARIO XML -> `.addt`: the common subset, everything else a diagnostic.

`import_xosc(path)` reads the file with defusedxml (no DTDs, no entities, no network),
resolves `$parameter` references and `${...}` arithmetic, and builds a `ScenarioPlan`
that the one printer (`addt_dsl/printer`) turns into `.addt` text; the text is compiled
once more before it is returned, so an import either gives a file that compiles or
errors. Files (the road network, vehicle catalogs, the side file of an exported run)
are read only inside the root directory (default: the scenario's directory), through
`addt_dsl/confine.py`.

Codes (docs/diagnostics.md): E0801 unreadable file (malformed XML, DTD or entity, too
large), E0802 invalid content (a missing element, attribute or reference), E0401/E0402
a missing file or one outside the root, W0801 an element that is not translated (no
equivalent in the language today), W0802 a value approximated or defaulted. Each names
the XML line and element. docs/openscenario.md has the mapping table.

The translation is one class, `Translate`, composed of one mixin per part of the standard
(the modules of this package, laid out like esmini's ScenarioEngine).
"""

import json
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_source
from addt_dsl.compiler.rules.oracles import NO_CLAUSES
from addt_dsl.diagnostics import Diagnostic, Span
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.actions import Actions
from addt_dsl.interop.openscenario.actions_global import Global
from addt_dsl.interop.openscenario.actions_lateral import Lateral
from addt_dsl.interop.openscenario.actions_longitudinal import Longitudinal
from addt_dsl.interop.openscenario.actions_misc import Misc
from addt_dsl.interop.openscenario.actions_routing import Routing
from addt_dsl.interop.openscenario.carla import CarlaCriteria, CarlaWalkers
from addt_dsl.interop.openscenario.conditions import Conditions
from addt_dsl.interop.openscenario.entities import Entities, safe_name
from addt_dsl.interop.openscenario.positions import Positions
from addt_dsl.interop.openscenario.reader import Importer
from addt_dsl.interop.openscenario.roads import Roads
from addt_dsl.interop.openscenario.sidefile import SIDECAR_PARAM, SideFile
from addt_dsl.interop.openscenario.storyboard import Storyboard
from addt_dsl.interop.openscenario.xml import Stop, child_at, first_of
from addt_dsl.plan import (
    ActorPlan,
    ClausePlan,
    ConcreteFault,
    ControllerPlan,
    OraclePlan,
    ParamPlan,
    ScenarioPlan,
    TriggerPlan,
    VariablePlan,
)
from addt_dsl.printer import PrinterError, params_referenced, pinned_fault_plan, print_plan, side_files
from addt_dsl.registry import STACKS
from addt_dsl.vehicles import VEHICLES

MAX_SCRIPTED_SPEED_MS = 70.0  # a scripted ego's default route is long enough at this speed [m/s]


@dataclass
class Imported:
    text: str | None  # the .addt source; None after errors
    plan: ScenarioPlan | None
    diagnostics: list[Diagnostic]
    sources: dict[str, str]  # file -> text, for rendering diagnostics
    side_files: dict[str, str] = field(default_factory=dict)  # files the .addt imports, by name
    entities: dict[str, str] = field(default_factory=dict)  # OpenSCENARIO entity name -> actor name


class Translate(SideFile, Roads, Entities, Positions, Actions, Longitudinal, Lateral, Routing, Misc, Global, Conditions,
                Storyboard, CarlaCriteria, CarlaWalkers, Importer):
    def run(self) -> ScenarioPlan | None:
        got = self.read(self.path.name, self.path.parent, None)
        if got is None:
            return None
        _, text = got
        self.sources[self.display] = text
        root = self.parse(text, self.display)
        if root is None:
            return None
        self.doc = root
        if root.tag != "OpenSCENARIO":
            self.error(root, f"the root element is <{root.tag}>, not <OpenSCENARIO>")
            return None
        header = child_at(root, "FileHeader")
        if header is not None and (header.get("description") or "").startswith("CARLA:"):
            self.carla = True
            self.sink.warning("W0803", "read in CARLA's coordinate frame (the description starts with 'CARLA:'): "
                              "world y, headings and lateral offsets are mirrored into OpenDRIVE's",
                              self.span(header), "as CARLA ScenarioRunner reads such a file: its frame is "
                              "left-handed, y and yaw grow to the right", label="<FileHeader>")
        # Global declarations first; those of stories, acts and maneuvers after them (one
        # scope: a name declared twice keeps its global value).
        for decl in [*root.iterfind("ParameterDeclarations/ParameterDeclaration"),
                     *root.iterfind("Storyboard//ParameterDeclaration")]:
            name, kind, value = decl.get("name"), decl.get("parameterType", "string"), decl.get("value", "")
            if name:
                self.params.setdefault(name, (kind, value))
        if SIDECAR_PARAM in self.params:
            self.load_sidecar(root.find("ParameterDeclarations"), header)
        if child_at(root, "Storyboard") is None or child_at(root, "Entities") is None:
            self.error(root, "no <Storyboard> or <Entities>: not a scenario (a catalog?)")
            return None
        try:
            self.road_network(root)
            self.entities(root)
            self.init(root.find("Storyboard/Init"))
            duration = self.stop_trigger(root.find("Storyboard/StopTrigger"))
            for story in root.iterfind("Storyboard/Story"):
                self.story(story)
            self.end_trigger(root.find("Storyboard/StopTrigger"))
            if self.act_stop is not None:  # (a CARLA file's storyboard stop trigger is its criteria)
                self.end = TriggerPlan(condition=self.act_stop) if self.end is None else \
                    self.end.model_copy(update={"condition": E.Binary(op="or", left=self.end.condition,
                                                                      right=self.act_stop)})
            if self.act_stop_s is not None:
                duration = min(duration, max(self.act_stop_s, 0.1))
        except Stop:
            return None
        if self.sink.has_errors:
            return None
        plan = self.plan(header, duration)
        return None if self.sink.has_errors else plan

    # -- the plan

    def dead_end(self, who: str) -> bool:
        """Whether the road the actor starts on ends without a link the way it drives (where
        esmini holds it; a linked road it would drive on, which the twin does not follow)."""
        at = self.placed[who]
        road_id = next(i for i, r in self.roads.items() if r.name == at.road)
        odr = self.network.road(road_id)
        return (odr.successor if self.driving_way(who) > 0 else odr.predecessor) is None

    def controller_assigned(self, obj) -> bool:
        """Whether the file gives the entity a controller of its own (an ObjectController, or
        an AssignControllerAction in Init: CARLA's external agent, esmini's driver models):
        someone else drives it, not OpenSCENARIO's default controller."""
        name = obj.get("name")
        return obj.find("ObjectController") is not None or any(
            p.get("entityRef") == name and p.find(".//AssignControllerAction") is not None
            for p in self.doc.iterfind("Storyboard/Init/Actions/Private"))

    def plan(self, header, duration: float) -> ScenarioPlan:
        sc = self.sidecar or {}
        # The side file's groups read the states of steps outside them (`when ended(ego.x) then
        # parallel {...}`): those events' steps get their names.
        for ref in sorted({m.group(1) for g in sc.get("groups", {}).values()
                           for m in re.finditer(r"(?:started|ended)\(\w+\.(\w+)\)", json.dumps(g))}):
            if ref not in sc.get("group_events", ()):
                self.event_state(ref, "endTransition")
        actors = []
        for who, info in self.actors.items():
            at = self.placed[who]
            road, lane, s, offset = at.road, at.lane, at.s, at.offset
            kind = VEHICLES[info["vehicle"]]
            extra = sc.get("actors", {}).get(who, {})
            fields = dict(name=who, vehicle=info["vehicle"], road=road, lane=E.Num(value=float(lane)), s=s,
                          speed=info.get("speed", E.Num(value=0.0)),
                          length_m=extra.get("length_m") or info["length_m"] or kind.length_m,
                          width_m=extra.get("width_m") or info["width_m"] or kind.width_m,
                          height_m=extra.get("height_m") or info["height_m"],
                          behaviors=info["behaviors"], triggers=info["triggers"])
            if extra.get("mass_kg") is not None:
                fields.update(mass_kg=extra["mass_kg"], wheelbase_m=extra["wheelbase_m"])
            if extra.get("route"):
                fields["route"] = [str(r) for r in extra["route"]]
            elif info.get("route_el") is not None or info.get("route_from_position") is not None:
                if info.get("route_el") is None:
                    self.approx(info["route_from_position"], f"{who} is placed on a route that nothing assigns: "
                                                             "it drives that route")
                got = self.route(first_of(info.get("route_el"), info.get("route_from_position")), who, lane, s)
                if got is not None:
                    fields["route"], fields["s"] = got
            if extra.get("yaw") is not None:
                fields["yaw"] = E.Num(value=float(extra["yaw"]))
            if extra.get("reverse") is not None:
                fields["reverse"] = bool(extra["reverse"])
            elif info.get("against_s") and info["vehicle"] != "obstacle" and not fields.get("route"):
                fields["reverse"] = True  # it faces against its lane: it drives that way
            if extra.get("yaw") is None and info.get("heading") is not None:
                # The file's heading, relative to the way the actor drives where it is placed.
                yaw = self.heading_from_lane(info["heading"], at, bool(fields.get("reverse")))
                if abs(yaw) > HEADING_TOL_RAD:
                    fields["yaw"] = E.Num(value=yaw)
                    if (who != "ego" or self.scripted_ego) and \
                            float(eval_param_expr(fields["speed"], self.param_values())) > 0.0:
                        self.approx(info["el"], f"{who} moves from the start: its body follows its path from "
                                                f"t = 0, not the file's heading ({yaw:.3g} rad off it)")
            if sc:
                fields["stop_at_road_end"] = bool(extra.get("stop_at_road_end", False))
            elif (who != "ego" or self.scripted_ego) and not fields.get("route") and self.dead_end(who):
                fields["stop_at_road_end"] = True  # esmini holds an entity at the end of its road
            if sc:
                fields["ignore_lights"] = bool(extra.get("ignore_lights", False))
            elif self.light_ctls and (who != "ego" or self.scripted_ego):
                fields["ignore_lights"] = True  # OpenSCENARIO's actors follow their actions, not the lights
            if eval_param_expr(offset, self.param_values()) != 0.0:
                # OpenSCENARIO's lane offset is along the road's t (left of +s); the language's is
                # to the driver's left: the other way for an actor driving against s.
                fields["offset"] = offset if self.driving_way(who) > 0 else \
                    E.Num(value=-offset.value) if isinstance(offset, E.Num) else E.Unary(op="neg", arg=offset)
            fields["triggers"] = fields["triggers"] + [TriggerPlan.model_validate(g)
                                                       for g in sc.get("groups", {}).get(who, [])]
            if who == "ego" and self.scripted_ego:
                # The ego follows the file's actions like any entity: no stack, no sensors. With
                # none, it keeps its speed (OpenSCENARIO's default controller), said as a behaviour:
                # an ego without behaviours or steps is the stack's.
                if not fields["behaviors"] and not fields["triggers"]:
                    fields["behaviors"] = [ClausePlan(keyword="behavior", name="cruise",
                                                      settings={"speed": fields["speed"], "shape": "step"})]
                if not sc and not fields.get("route"):
                    route = self.straight_on(road, lane, s, MAX_SCRIPTED_SPEED_MS * duration + 50.0)
                    if route is not None and len(route) > 1:
                        fields["route"] = route
                        self.approx(info["el"], f"the ego has no route in the file: it drives on through junctions, "
                                                f"straight where it can, else to the kerb side, else the other way "
                                                f"(roads {' -> '.join(route)})")
            elif who == "ego":
                fields.update(behaviors=[], triggers=[])
                if extra.get("stack"):
                    fields["stack"] = ClausePlan.model_validate(extra["stack"])
                    fields["sensors"] = [ClausePlan.model_validate(x) for x in extra.get("sensors", [])]
                elif not sc and eval_param_expr(fields["speed"], self.param_values()) > 0:
                    # The stack cruises at the ego's initial speed, as OpenSCENARIO's default
                    # controller keeps the speed the file gives it.
                    fields["stack"] = ClausePlan(keyword="stack", name="bev",
                                                 settings={"cruise_speed": fields["speed"]})
                elif not sc and any(eval_param_expr(v, self.param_values()) > 0
                                    for v, _ in info.get("speed_targets", ())):
                    # The file starts its ego standing and its actions set it going: the stack
                    # cruises at the first speed they ask, not its own default.
                    v, el = next((v, el) for v, el in info["speed_targets"]
                                 if eval_param_expr(v, self.param_values()) > 0)
                    fields["stack"] = ClausePlan(keyword="stack", name="bev", settings={"cruise_speed": v})
                    self.approx(el, "the ego starts standing and the file's actions set it going: the stack "
                                    "drives from the start, cruising at this first speed they ask",
                                "`addtc import --ego scripted` makes the ego follow the file's actions")
                elif not sc:
                    limit = self.speed_limit_at(road, s) if self.controller_assigned(info["el"]) else None
                    if limit is not None:
                        # A standing ego is someone else's to drive (CARLA's examples leave it to an
                        # external agent): the stack drives at the map's limit, not its own default.
                        fields["stack"] = ClausePlan(keyword="stack", name="bev",
                                                     settings={"cruise_speed": E.Num(value=limit)})  # exact: `50 km/h`
                        self.approx(info["el"], f"the ego starts standing: the stack cruises at its road's speed "
                                                f"limit, {units.from_si(limit, 'km/h'):.4g} km/h")
                    elif self.controller_assigned(info["el"]):
                        self.approx(info["el"], "the ego starts standing and the file gives it a controller to "
                                                "drive it: the stack drives at its default cruise speed")
                    else:
                        # Standing, on OpenSCENARIO's default controller, and nothing in the file
                        # sets it going: the stack keeps it standing, as that controller keeps the
                        # speed it is given (without a stack line the stack's default drove it off).
                        fields["stack"] = ClausePlan(keyword="stack", name="bev",
                                                     settings={"cruise_speed": fields["speed"]})
                        self.approx(info["el"], "the ego starts standing and nothing in the file sets it going: "
                                                "the stack keeps it standing (cruise_speed 0 m/s)")
                if not sc and not fields.get("route"):
                    # Without a route the ego leaves the map where its road ends (a `left_road`
                    # event): give it the way straight on, as far as it can drive in the run.
                    stack = fields.get("stack")
                    cruise = stack.settings.get("cruise_speed") if stack is not None else None
                    speed = (float(eval_param_expr(cruise, self.param_values())) if cruise is not None
                             else next(p.default for p in STACKS.get("bev").params if p.name == "cruise_speed"))
                    route = self.straight_on(road, lane, s, speed * duration + 50.0)
                    if route is not None:
                        fields["route"] = route
                        self.approx(info["el"], "the ego has no route in the file: it drives on through junctions, "
                                                "straight where it can, else to the kerb side, else the other way "
                                                f"(roads {' -> '.join(route)})")
                for key in ("goal_s", "mu"):
                    if extra.get(key) is not None:
                        fields[key] = E.Num(value=float(extra[key]))
            actors.append(ActorPlan(**fields))
        ego = next(a for a in actors if a.name == "ego")
        agents = [a for a in actors if a.name != "ego"]
        faults = [pinned_fault_plan(ConcreteFault.model_validate(f)) for f in sc.get("faults", [])]
        oracles = [OraclePlan.model_validate(o) for o in sc.get("oracles", [])]
        if not sc:
            oracles = self.pass_criteria(ego)
        if not sc and not oracles:  # OpenSCENARIO states no pass criteria: the one every scenario here has
            oracles = [OraclePlan(name="no_collision", formula=NO_CLAUSES["collision"]("ego", None))]
        description = sc["description"] if sc else (header.get("description", "") if header is not None else "")
        name = sc.get("scenario") or safe_name(self.path.stem, set())
        if self.light_ctls and not sc and agents:
            self.approx(first_of(self.signals_el, self.doc), "OpenSCENARIO's actors follow their actions, not the "
                                                           "traffic lights: the agents get `at_red run`")
        controllers = []
        for cname, info in self.light_ctls.items():
            if info.get("solo"):  # a signal set by actions only: no program, green until a step sets it
                info["green"] = duration
                if not any(tr.clause.name == cname and tr.at_s is None and tr.after_s is None and tr.condition is None
                           for tr in self.light_steps):
                    self.approx(info["el"], f"signal {info['signals'][0]} has no controller and no state in Init: "
                                            "green until an action sets it")
            controllers.append(ControllerPlan(
                name=cname, road=next(iter(self.roads.values())).name, signals=info["signals"],
                green_s=E.Num(value=info["green"]), yellow_s=E.Num(value=info["yellow"]),
                red_s=E.Num(value=info["red"]), offset_s=E.Num(value=info["offset"])))
        plan = ScenarioPlan(name=name, description=description[:500], duration_s=duration,
                            step_s=sc.get("step_s", 0.01), seed=sc.get("seed", 0), run_seed=sc.get("run_seed"),
                            roads=list(self.roads.values()), ego=ego, agents=agents, faults=faults, oracles=oracles,
                            environment=self.environment, environment_steps=self.environment_steps,
                            controllers=controllers, light_steps=self.light_steps,
                            variables=[VariablePlan(name=k, value=v) for k, v in self.variables.items()],
                            variable_steps=self.variable_steps, end=self.end)
        values = {**self.param_values(), **sc.get("params", {})}
        dims = {**{k: v for k, v in self.param_dims.items()},
                **{k: units.DIMENSIONLESS for k in sc.get("params", {}) if k not in self.param_dims}}
        for k, d in sc.get("param_dims", {}).items():
            dims[k] = units.dim_from_name(d)
        params = []
        for p in sorted(params_referenced(plan)):
            dim = dims.get(p)
            if dim is None or p not in values:
                self.error(None, f"parameter '{p}' is used with two dimensions or has no number value")
                raise Stop
            params.append(ParamPlan(name=p, dimension=units.dim_name(dim), default=float(values[p])))
        return plan.model_copy(update={"params": params})


# ---------------------------------------------------------------- entry point

# Documents other than a scenario, translated elsewhere: (recognise(path) -> bool,
# translate(path, root, maps, lenient=, ego=) -> Imported). openscenario/distribution.py
# registers the ParameterValueDistribution (a logical scenario: a distribution and the
# template it names); the interop package loads it.
DOCUMENT_KINDS: list[tuple] = []


# A heading this close to the lane's is the lane's: the files' own rounding (alks_cut-in's h =
# 3.141593 turning an entity round) [rad].
HEADING_TOL_RAD = 1e-6


def import_xosc(path: str | Path, root: str | Path | None = None, maps=(), lenient: bool = False,
                ego: str = "stack", translator=None) -> Imported:
    """Translate an OpenSCENARIO file; files are read only under `root` (default: its
    directory), and a road network named without a folder also from the `maps` directories.
    An element that is not translated is an error (E0803) unless `lenient`; `ego` is "stack"
    (the stack under test drives the ego; actions on it are not translated) or "scripted"
    (the ego follows every action the file gives it). A ParameterValueDistribution is
    translated with the template it names (`translator`: the class that translates a
    template, openscenario/distribution.py)."""
    path = Path(path)
    for recognise, translate in DOCUMENT_KINDS if translator is None else ():
        if recognise(path):
            return translate(path, root, maps, lenient=lenient, ego=ego)
    imp = (translator or Translate)(path, Path(root) if root is not None else path.parent,
                                     tuple(Path(m) for m in maps), lenient=lenient, ego=ego)
    if not path.resolve().is_relative_to(imp.root):
        imp.sink.error("E0402", f"{path} is outside the root directory", None)
        return Imported(None, None, imp.sink.items, imp.sources)
    try:
        plan = imp.run()
    except Stop:
        plan = None
    except RecursionError:
        imp.sink.error("E0801", "the document is nested too deeply", Span.point(imp.display, 1, 1))
        plan = None
    if plan is None:
        return Imported(None, None, imp.sink.items, imp.sources)
    comment = (f"Imported from {path.name} by addtc import" + (" (with its addt-dsl side file)"
                                                               if imp.sidecar else "")
               + f"\n{sum(d.code.startswith('W08') for d in imp.sink.items)} element(s) not translated "
                 "or approximated: see the diagnostics"
               + ("" if imp.sidecar else "\nThe oracles are CARLA ScenarioRunner's criteria_* conditions that translate"
                  if imp.criteria else "\nOpenSCENARIO states no pass criteria: `no collision` is the default oracle"))
    try:
        text = print_plan(plan, comment=comment)
    except PrinterError as exc:
        imp.sink.error("E0802", f"the translated scenario cannot be printed: {exc}", Span.point(imp.display, 1, 1))
        return Imported(None, None, imp.sink.items, imp.sources)
    files = side_files(plan)
    with tempfile.TemporaryDirectory() as tmp:
        for name, body in files.items():
            (Path(tmp) / name).write_text(body)
        check = compile_source(text, path=f"{path.stem}.addt", base_dir=tmp)
    if not check.ok:
        for d in check.diagnostics:
            if d.is_error:
                imp.sink.error("E0802", f"the translated scenario does not compile: [{d.code}] {d.message}",
                               Span.point(imp.display, 1, 1))
        return Imported(None, None, imp.sink.items, {**imp.sources, **check.sources})
    return Imported(text, check.plan, imp.sink.items, imp.sources, files, dict(imp.renames))
