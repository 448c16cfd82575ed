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
"""

from __future__ import annotations

import ast
import json
import math
import operator
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from defusedxml import DefusedXmlException
from xml.etree.ElementTree import Element  # an empty <Init> only: files are parsed with defusedxml

from defusedxml.ElementTree import DefusedXMLParser
from pydantic import TypeAdapter

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_source
from addt_dsl.compiler.rules.oracles import NO_CLAUSES, stay_in_lane_formula
from addt_dsl.confine import Refused, confine
from addt_dsl.diagnostics import Diagnostic, DiagnosticSink, Span
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.xosc_export import CONTROLLER_PREFIX, SIDECAR_FORMAT, SIDECAR_PARAM, lamps_of, state_of_lamps
from addt_dsl.plan import (LIGHT_PROGRAM, LIGHT_STATES, ActorPlan, ClausePlan, ConcreteFault, ControllerPlan, GroupPlan,
                           OraclePlan, ParamPlan, RoadPlan, ScenarioPlan, TriggerPlan)
from addt_dsl.printer import PrinterError, params_referenced, pinned_fault_plan, print_plan, side_files
from addt_dsl.registry import BEHAVIORS, STACKS
from addt_dsl.runtime.behaviors import PEAK_SLOPE
from addt_dsl.road.route import RouteError, exits, resolve_route, turn_of
from addt_dsl.road import XodrError, parse_xodr
from addt_dsl.vehicles import VEHICLES

MAX_XML_BYTES = 8 * 1024 * 1024
MAX_STATION_M = 1e6  # a road station beyond this is refused as content, not translated [m]
MAX_LANE_ID = 100
MAX_EXPRESSION_CHARS = 10_000  # a `${...}` expression's length (docs/limits.md)
DEFAULT_DURATION_S = 60.0
MAX_DURATION_S = 3600.0
CATEGORY_KIND = {"car": "car", "van": "car", "motorbike": "cyclist", "bicycle": "cyclist", "bus": "truck",
                 "truck": "truck", "semitrailer": "truck", "trailer": "truck", "train": "truck", "tram": "truck"}
MAX_SCRIPTED_SPEED_MS = 70.0  # a scripted ego's default route is long enough at this speed [m/s]
EDGES = {"none": None, "rising": "rising", "falling": "falling", "risingOrFalling": "changing"}
RULE_OPS = {"lessThan": "<", "lessOrEqual": "<=", "greaterThan": ">", "greaterOrEqual": ">=", "equalTo": "==",
            "notEqualTo": "!="}
_NAME = re.compile(r"[A-Za-z_]\w*")
EXPR = TypeAdapter(E.Expr)


@dataclass
class Imported:
    text: str | None  # the .addt source; None after errors
    plan: ScenarioPlan | None
    diagnostics: list[Diagnostic]
    sources: dict[str, str]  # file -> text, for rendering diagnostics
    side_files: dict[str, str] = field(default_factory=dict)  # files the .addt imports, by name
    entities: dict[str, str] = field(default_factory=dict)  # OpenSCENARIO entity name -> actor name


class _Stop(Exception):
    """An error that ends the import (already reported)."""


class _LineParser(DefusedXMLParser):
    """defusedxml's parser (DTDs forbidden, entities refused) that records each element's line."""

    def __init__(self):
        super().__init__(forbid_dtd=True, forbid_entities=True, forbid_external=True)
        self.lines: dict[int, int] = {}

    def _start(self, tag, attr_list):
        element = super()._start(tag, attr_list)
        self.lines[id(element)] = self.parser.CurrentLineNumber
        return element


# ---------------------------------------------------------------- values

_BINOPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.Pow: operator.pow, ast.Mod: operator.mod}


def _arith(node) -> float:
    """A `${...}` expression: numbers, + - * / % **, unary minus, parentheses."""
    if isinstance(node, ast.Expression):
        return _arith(node.body)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        v = _arith(node.operand)
        return -v if isinstance(node.op, ast.USub) else v
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        left, right = _arith(node.left), _arith(node.right)
        if isinstance(node.op, ast.Pow) and abs(right) > 64:
            raise ValueError("exponent too large")
        return float(_BINOPS[type(node.op)](left, right))
    raise ValueError("unsupported expression")


class _Importer:
    def __init__(self, path: Path, root: Path, maps: tuple[Path, ...] = (), lenient: bool = False,
                 ego: str = "stack"):
        self.path = path
        # What is not translated is refused (E0803): a run without it is not the scenario in the
        # file. `lenient` imports the rest and says what was left out (W0801).
        self.lenient = lenient
        self.ego_mode = ego  # "stack": the stack under test drives the ego; "scripted": its actions do
        self.root = root.resolve()
        self.maps = tuple(Path(m).resolve() for m in maps)  # where a road network named bare is looked for
        # CARLA ScenarioRunner's frame (FileHeader description "CARLA:..."): left-handed, so
        # world y, headings and lateral offsets are mirrored into OpenDRIVE's (`mirror`).
        self.carla = False
        self.criteria = False  # pass criteria came from the file (CARLA's `criteria_*` conditions)
        self.display = str(path)
        self.sink = DiagnosticSink()
        self.sources: dict[str, str] = {}
        self.lines: dict[int, int] = {}
        self.params: dict[str, tuple[str, str]] = {}  # name -> (type, raw value)
        self.resolved: dict[tuple[str, str], str] = {}  # (name, raw value) -> resolved value
        self.catalog_docs: dict[Path, object] = {}  # catalog file -> its parsed root (None: unreadable)
        self.param_dims: dict[str, units.Dim | None] = {}  # used as a number: its dimension (None: clash)
        self.sidecar: dict | None = None
        self.renames: dict[str, str] = {}  # OpenSCENARIO entity name -> addt actor name
        self.actors: dict[str, dict] = {}  # addt name -> fields
        self.roads: dict[str, RoadPlan] = {}  # OpenDRIVE road id -> plan road
        self.network = None
        self.xodr_name = ""
        self.xodr_text = ""
        self.events: dict[str, tuple] = {}  # event name -> (actor, kind, fields, clause)
        self.maneuvers: dict[str, list[str]] = {}  # maneuver name -> its events' names
        self.end: TriggerPlan | None = None  # the storyboard's stop trigger beyond its time
        self.pending: list[tuple] = []  # events started by another event: linked at the end
        self.anchors: dict[str, tuple] = {}  # no-op events that start a group: name -> (actor, start fields)
        self.placed: dict[str, tuple] = {}  # actor -> (road name, lane, s, offset)
        self.environment: list[ClausePlan] = []  # weather and light from an EnvironmentAction
        # Traffic lights: controllers by name (signal ids, phase times, the element), the
        # controller of each signal, phase name -> state per controller, the light steps.
        self.light_ctls: dict[str, dict] = {}
        self.ctl_names: dict[str, str] = {}  # a controller's name in the file -> in the language
        self.signal_owner: dict[str, str] = {}
        self.light_steps: list[TriggerPlan] = []
        self.signals_el = None
        self.doc = None

    # -- diagnostics

    def span(self, el) -> Span:
        return Span.point(self.display, self.lines.get(id(el), 1), 1) if el is not None else \
            Span.point(self.display, 1, 1)

    def error(self, el, message: str, *notes: str, code: str = "E0802") -> None:
        self.sink.error(code, message, self.span(el), *notes, label=f"<{el.tag}>" if el is not None else "")

    def skip(self, el, message: str, *notes: str) -> None:
        if self.lenient:
            self.sink.warning("W0801", message, self.span(el), *notes, label=f"<{el.tag}>")
            return
        self.sink.error("E0803", message, self.span(el), *notes,
                        "`addtc import --lenient` imports the rest without it (the run is then not the "
                        "scenario in the file)", label=f"<{el.tag}>")

    @property
    def scripted_ego(self) -> bool:
        """Whether the ego follows the file's actions: asked for, or an exported scripted ego
        (its side file gives it no stack)."""
        if self.ego_mode == "scripted":
            return True
        ego = next((n for n, a in self.renames.items() if a == "ego"), None)
        actor = (self.sidecar or {}).get("actors", {}).get(ego or "ego")
        return actor is not None and not actor.get("stack")

    def approx(self, el, message: str, *notes: str) -> None:
        self.sink.warning("W0802", message, self.span(el), *notes, label=f"<{el.tag}>" if el is not None else "")

    # -- files

    def read(self, relative: str, base: Path, el, limit: int = MAX_XML_BYTES,
             root: Path | None = None) -> tuple[Path, str] | None:
        try:
            path = confine(relative, base, self.root if root is None else root)
        except Refused as refused:
            self.sink.error(refused.code, refused.message, self.span(el), *([refused.note] if refused.note else []),
                            label=f"<{el.tag}>" if el is not None else "")
            return None
        try:
            if path.stat().st_size > limit:
                self.error(el, f"'{relative}' is too large (limit {limit} bytes)", code="E0401")
                return None
            return path, path.read_bytes().decode("utf-8", errors="replace")
        except OSError as exc:
            self.error(el, f"cannot read '{relative}': {exc.strerror or exc}", code="E0401")
            return None

    def parse(self, text: str, display: str):
        parser = _LineParser()
        try:
            parser.feed(text)
            root = parser.close()
        except DefusedXmlException as exc:
            self.sink.error("E0801", f"{display}: refused: {type(exc).__name__} (DTDs and entities are not read)",
                            Span.point(display, 1, 1))
            return None
        except Exception as exc:  # noqa: BLE001 - expat's ParseError, and any error on hostile input
            line = getattr(exc, "position", (1, 0))[0] if hasattr(exc, "position") else 1
            self.sink.error("E0801", f"{display}: not well-formed XML: {exc}", Span.point(display, max(1, line), 1))
            return None
        self.lines.update(parser.lines)
        return root

    # -- attribute values

    def raw(self, el, attr: str, required: bool = True) -> str | None:
        value = el.get(attr)
        if value is None:
            if required:
                self.error(el, f"<{el.tag}> has no attribute '{attr}'")
                raise _Stop
            return None
        try:
            return self.resolve(value)
        except KeyError as exc:
            self.error(el, f"unknown parameter '${exc.args[0]}' in {attr}")
            raise _Stop from None
        except (SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
            self.error(el, f"cannot evaluate {attr}=\"{value[:80]}\"")
            raise _Stop from None

    def resolve(self, value: str, depth: int = 0) -> str:
        """`$name` and `${expression}` resolved (parameters may refer to parameters). Each
        parameter's value is resolved once (a file whose parameters each refer to the one
        before many times would otherwise take exponential time)."""
        if depth > 16:
            raise ValueError("parameters refer to each other too deeply")
        if value.startswith("${") and value.endswith("}"):
            if len(value) > MAX_EXPRESSION_CHARS:
                raise ValueError(f"an expression of {len(value)} characters (at most {MAX_EXPRESSION_CHARS})")
            body = re.sub(r"\$([A-Za-z_]\w*)", lambda m: self.resolve("$" + m.group(1), depth + 1), value[2:-1])
            return repr(_arith(ast.parse(body, mode="eval")))
        if value.startswith("$"):
            if value[1:] not in self.params:
                raise KeyError(value[1:])
            raw = self.params[value[1:]][1]
            key = (value[1:], raw)
            if key not in self.resolved:
                self.resolved[key] = self.resolve(raw, depth + 1)
            return self.resolved[key]
        return value

    def number(self, el, attr: str, dim=units.DIMENSIONLESS, default: float | None = None,
               keep: bool = True) -> E.Expr:
        """The attribute as an expression: a parameter reference (`$name`) stays a parameter."""
        text = self.raw(el, attr, required=default is None)
        if text is None:
            return E.Num(value=float(default))
        try:
            value = float(text)
        except ValueError:
            self.error(el, f"{attr}=\"{text[:40]}\" is not a number")
            raise _Stop from None
        if not math.isfinite(value):
            self.error(el, f"{attr}=\"{text[:40]}\" is not finite")
            raise _Stop
        ref = el.get(attr, "")
        plain = _is_number(self.params.get(ref[1:], ("", ""))[1])
        if keep and plain and ref.startswith("$") and not ref.startswith("${") and _NAME.fullmatch(ref[1:]):
            name = ref[1:]
            known = self.param_dims.get(name, dim)
            self.param_dims[name] = dim if known == dim else None
            return E.Param(name=name)
        return E.Num(value=value)

    def value(self, el, attr: str, dim=units.DIMENSIONLESS, default: float | None = None) -> float:
        return float(eval_param_expr(self.number(el, attr, dim, default, keep=False), {}))

    def mirror(self, value):
        """A lateral coordinate or a heading (y, t, an offset, h; a float or an expression) in
        OpenDRIVE's right-handed frame: negated in a CARLA-frame file, where y, t, lane offsets
        and yaw grow to the right (ScenarioRunner's `use_carla_coordinate_system`)."""
        if not self.carla:
            return value
        if isinstance(value, (int, float)):
            return -value
        if isinstance(value, E.Num):
            return E.Num(value=-value.value)
        return E.Unary(op="neg", arg=value)

    def param_values(self) -> dict[str, float]:
        out = {}
        for name, (_, raw) in self.params.items():
            try:
                out[name] = float(self.resolve(raw))
            except (KeyError, SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
                pass
        return out

    def actor_name(self, el, attr: str = "entityRef") -> str | None:
        name = self.raw(el, attr)
        if name not in self.renames:
            self.error(el, f"no entity '{name}'", f"entities: {', '.join(self.renames) or 'none'}")
            return None
        return self.renames[name]


# ---------------------------------------------------------------- the document

def _lane_ids(odr, s: float) -> tuple[int, ...]:
    """Every lane id of a road's lane section at s (driving or not)."""
    try:
        return tuple(odr.lane_ids(s))
    except ValueError:
        return ()


def _child(el, *path):
    for tag in path:
        if el is None:
            return None
        el = el.find(tag)
    return el


def _first(*elements):
    """The first element that is not None (elements without children are false)."""
    return next((e for e in elements if e is not None), None)


def _only_child(el):
    kids = list(el) if el is not None else []
    return kids[0] if len(kids) == 1 else None


# StoryboardElementStateCondition states on another actor's event, as step states.
STATE_SIGNAL = {"startTransition": "started",
                "endTransition": "ended", "completeState": "ended"}


def _safe_name(name: str, taken: set[str]) -> str:
    base = re.sub(r"\W", "_", name) or "actor"
    if not _NAME.fullmatch(base):
        base = f"a_{base}"
    out, i = base, 2
    while out in taken:
        out, i = f"{base}_{i}", i + 1
    return out


class _Translate(_Importer):
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
        header = _child(root, "FileHeader")
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
        if _child(root, "Storyboard") is None or _child(root, "Entities") is None:
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
        except _Stop:
            return None
        if self.sink.has_errors:
            return None
        plan = self.plan(header, duration)
        return None if self.sink.has_errors else plan

    # -- side file of an exported run

    def load_sidecar(self, decls, header) -> None:
        name = self.params[SIDECAR_PARAM][1]
        try:
            confine(name, self.path.parent, self.root)
        except Refused as refused:
            self.approx(decls, f"side file {name}: {refused.message}; the ego's stack and sensors, the faults, "
                               "oracles and exact behaviours it carries are not imported")
            return
        got = self.read(name, self.path.parent, decls)
        if got is None:
            return
        try:
            data = json.loads(got[1])
        except ValueError as exc:
            self.error(decls, f"side file {name} is not JSON: {exc}")
            return
        if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
            self.error(decls, f"side file {name} is not an addt-dsl export side file ({SIDECAR_FORMAT})")
            return
        problem = _sidecar_problem(data)
        if problem:
            self.error(decls, f"side file {name} is not what addtc export writes: {problem}")
            return
        # `addtc export` names the scenario in the FileHeader and in the side file: a side
        # file of another export would bring its stack, faults and oracles into this one.
        written_for = header.get("description") if header is not None else None
        if written_for and data.get("scenario") and written_for != data["scenario"]:
            self.error(decls, f"side file {name} was written for scenario {data['scenario']!r}, but this file is "
                              f"scenario {written_for!r}: it belongs to another export; export the run again, or "
                              f"remove the `{SIDECAR_PARAM}` parameter to import the OpenSCENARIO alone")
            return
        self.sidecar = data

    # -- road network

    def road_network(self, root) -> None:
        logic = root.find("RoadNetwork/LogicFile")
        if logic is None:
            self.error(_first(root.find("RoadNetwork"), root), "no <RoadNetwork><LogicFile>: addt-dsl actors need a road")
            raise _Stop
        got = self.read_road_network(self.raw(logic, "filepath"), logic)
        if got is None:
            raise _Stop
        path, text = got
        if not path.name.lower().endswith(".xodr"):
            self.error(logic, f"'{path.name}' is not an OpenDRIVE file")
            raise _Stop
        try:
            self.network = parse_xodr(text, path.name)
        except XodrError as exc:
            self.error(logic, f"cannot use {path.name}: {exc}", code="E0403")
            raise _Stop from None
        except (ValueError, ArithmeticError, RecursionError) as exc:
            self.error(logic, f"cannot use {path.name}: {exc}", code="E0403")
            raise _Stop from None
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

    # -- traffic lights

    def signal_state(self, sid: str, text: str, el) -> str | None:
        """green, yellow or red shown by signal `sid` in state `text` (its lamps from the map's
        signal type); None after a diagnostic."""
        found = self.network.signal(sid)
        if found is None:
            self.skip(el, f"{self.xodr_name} has no signal '{sid}'",
                      f"traffic lights on the map: {', '.join(self.network.signal_ids(dynamic_only=True)) or '(none)'}")
            return None
        lamps = lamps_of(found[1].type, found[1].subtype)
        state = state_of_lamps(lamps, text)
        if state is None:
            self.skip(el, f"state '{text}' of signal {sid} shows no one colour of its lamps ({';'.join(lamps)})",
                      "translated: one lamp on or flashing, or a word green, yellow (amber), red")
        return state

    def signal_controller(self, ctl) -> None:
        """A TrafficSignalController: its phases as one green -> yellow -> red cycle (phases in
        a rotation of that order: the offset is where the cycle's first colour starts). A
        phase's colour is its first signal's."""
        name = _safe_name(self.raw(ctl, "name"), set(self.light_ctls))
        self.ctl_names.setdefault(self.raw(ctl, "name"), name)
        phases, signals = [], []
        for phase in ctl.iterfind("Phase"):
            states = list(phase.iterfind("TrafficSignalState"))
            for st in states:
                sid = self.raw(st, "trafficSignalId")
                if sid not in signals and self.network.signal(sid) is not None:
                    signals.append(sid)
            state = self.signal_state(self.raw(states[0], "trafficSignalId"), self.raw(states[0], "state"),
                                      states[0]) if states else None
            if state is None:
                state = {"amber": "yellow"}.get((phase.get("name") or "").lower(), (phase.get("name") or "").lower())
                if state not in LIGHT_STATES:
                    self.approx(phase, f"phase '{phase.get('name')}' shows no traffic-light colour: read as red")
                    state = "red"
            phases.append((self.raw(phase, "name"), state, self.value(phase, "duration", units.TIME)))
        if ctl.get("delay") is not None or ctl.get("reference") is not None:
            self.skip(ctl, "a controller's delay to a reference controller is not translated: its phases start at 0 s")
        if not signals:
            self.skip(ctl, f"controller '{name}' switches no signal of {self.xodr_name}: not translated")
            return
        cycle = {"green": 0.0, "yellow": 0.0, "red": 0.0}
        for _, st, d in phases:
            cycle[st] += d
        total = sum(cycle.values())
        timed = [(st, d) for _, st, d in phases if d > 0]
        # Runs of one colour, the last joined to the first when they match (the cycle repeats).
        runs = [st for i, (st, _) in enumerate(timed) if i == 0 or timed[i - 1][0] != st]
        if len(runs) > 1 and runs[0] == runs[-1]:
            runs.pop()
        wanted = [k for k in ("green", "yellow", "red") if cycle[k] > 0]
        offset = 0.0
        if runs and any(runs[i:] + runs[:i] == wanted for i in range(len(runs))):
            # The language's program starts its first colour at the offset: where that run starts.
            lead = wanted[0]
            i = next(i for i, (st, _) in enumerate(timed) if st == lead and timed[i - 1][0] != lead) \
                if len(timed) > 1 else 0
            offset = sum(d for _, d in timed[:i]) % total if total > 0 else 0.0
        elif timed:
            self.approx(ctl, f"controller '{name}': phases {', '.join(st for st, _ in timed)} as one green, "
                             "yellow, red cycle of their summed times")
        exact = ((self.sidecar or {}).get("lights") or {}).get("controllers", {}).get(name)
        if exact:  # the export's program exactly (its offset has no OpenSCENARIO form)
            cycle = {k: float(exact[f"{k}_s"]) for k in cycle}
            offset = float(exact["offset_s"])
        self.light_ctls[name] = {"signals": signals, "el": ctl, "offset": offset,
                                 "phases": {pname: st for pname, st, _ in phases}, **cycle}
        for sid in signals:
            self.signal_owner.setdefault(sid, name)

    def light_controller(self, sid: str, el) -> str | None:
        """The controller that switches signal `sid`: the file's, or one of its own (a signal
        set directly, as esmini's files do: `controller signal_N signals [N]`)."""
        if sid in self.signal_owner:
            return self.signal_owner[sid]
        if self.network.signal(sid) is None:
            self.skip(el, f"{self.xodr_name} has no signal '{sid}'",
                      f"traffic lights on the map: {', '.join(self.network.signal_ids(dynamic_only=True)) or '(none)'}")
            return None
        name = _safe_name(f"signal_{sid}" if re.fullmatch(r"\w+", sid) else "signal", set(self.light_ctls))
        self.light_ctls[name] = {"signals": [sid], "el": el, "offset": 0.0, "phases": {}, "solo": True,
                                 "green": 0.0, "yellow": 0.0, "red": 0.0}
        self.signal_owner[sid] = name
        return name

    def light_clauses(self, action) -> list[ClausePlan]:
        """A GlobalAction's TrafficSignalAction as `light C state S` clauses ([] after a diagnostic)."""
        state_action = _child(action, "InfrastructureAction", "TrafficSignalAction", "TrafficSignalStateAction")
        ctl_action = _child(action, "InfrastructureAction", "TrafficSignalAction", "TrafficSignalControllerAction")
        if ctl_action is not None:
            raw = self.raw(ctl_action, "trafficSignalControllerRef")
            ref = self.ctl_names.get(raw, raw)
            if ref not in self.light_ctls or self.light_ctls[ref].get("solo"):
                self.error(ctl_action, f"no traffic signal controller '{raw}'",
                           f"controllers: {', '.join(c for c, v in self.light_ctls.items() if not v.get('solo'))}")
                return []
            self.approx(ctl_action, f"phase '{self.raw(ctl_action, 'phase')}': the controller resumes its program "
                                    "(`state program`), in its own cycle")
            return [ClausePlan(keyword="light", name=ref, settings={"state": LIGHT_PROGRAM})]
        if state_action is None:
            return []
        sid = self.raw(state_action, "name")
        ctl = self.light_controller(sid, state_action)
        state = self.signal_state(sid, self.raw(state_action, "state"), state_action) if ctl else None
        if state is None:
            return []
        return [ClausePlan(keyword="light", name=ctl, settings={"state": state})]

    def light_event(self, pairs: list) -> list[ClausePlan]:
        """The light clauses of one event's TrafficSignalActions ((action element, clause)
        pairs): one per controller; setting some of a controller's signals switches it all."""
        out, seen = [], {}
        for el, clause in pairs:
            seen.setdefault((clause.name, clause.settings["state"]), []).append(el)
        for (ctl, state), els in seen.items():
            info = self.light_ctls[ctl]
            if state != LIGHT_PROGRAM and len(els) < len(info["signals"]):
                self.approx(els[0], f"sets {len(els)} of the {len(info['signals'])} signals of controller '{ctl}': "
                                    "the language switches the whole controller")
            out.append(ClausePlan(keyword="light", name=ctl, settings={"state": state}))
        return out

    def road(self, road_id: str, el) -> str:
        if road_id not in self.network.roads:
            self.error(el, f"{self.xodr_name} has no road '{road_id}'")
            raise _Stop
        if road_id not in self.roads:
            odr = self.network.road(road_id)
            name = _safe_name(f"r{road_id}" if not odr.name or not _NAME.fullmatch(str(odr.name))
                              else str(odr.name), {r.name for r in self.roads.values()} | set(self.actors))
            if not re.fullmatch(r"\d+", road_id):
                self.error(el, f"road id '{road_id}' is not a number: the language imports roads by number")
                raise _Stop
            self.roads[road_id] = RoadPlan(name=name, source="xodr", xodr_file=self.xodr_name,
                                           xodr_text=self.xodr_text, xodr_road_id=road_id)
        return self.roads[road_id].name

    # -- entities

    def entities(self, root) -> None:
        objects = list(root.iterfind("Entities/ScenarioObject"))
        names = [o.get("name", "") for o in objects]
        ego = next((n for n in names if n.lower() in ("ego", "hero")), None)
        if ego is None and names:
            ego = names[0]
            self.approx(objects[0], f"no entity named Ego: '{ego}' becomes the ego (driven by the stack)")
        taken: set[str] = set()
        for obj, name in zip(objects, names):
            addt = "ego" if name == ego else _safe_name(name, taken | {"ego"})
            taken.add(addt)
            self.renames[name] = addt
        for obj in objects:
            self.entity(obj, self.renames[obj.get("name", "")])
        for sel in root.iterfind("Entities/EntitySelection"):
            self.skip(sel, "entity selections are not translated")
        if "ego" not in self.actors:
            self.error(root.find("Entities"), "no entity to be the ego")
            raise _Stop

    def entity(self, obj, name: str) -> None:
        body = _only_child(obj) if obj.find("ObjectController") is None else \
            next((c for c in obj if c.tag != "ObjectController"), None)
        saved = dict(self.params)
        if body is not None and body.tag == "CatalogReference":
            ref = body
            body = self.catalog_entry(ref)
            # The entry's own parameters, as the reference assigns them.
            for decl in body.iterfind("ParameterDeclarations/ParameterDeclaration") if body is not None else ():
                self.params[decl.get("name", "")] = (decl.get("parameterType", "string"), decl.get("value", ""))
            for assign in ref.iterfind("ParameterAssignments/ParameterAssignment"):
                self.params[assign.get("parameterRef", "")] = ("string", assign.get("value", ""))
        try:
            self.entity_body(obj, name, body)
        finally:
            self.params = saved

    def entity_body(self, obj, name: str, body) -> None:
        kind, length, width = "car", None, None
        if body is None:
            self.approx(obj, f"entity '{obj.get('name')}': no vehicle definition; a default car")
        elif body.tag == "Vehicle":
            category = self.raw(body, "vehicleCategory", required=False) or "car"
            kind = CATEGORY_KIND.get(category, "car")
        elif body.tag == "Pedestrian":
            kind = "pedestrian"
        elif body.tag == "MiscObject":
            kind = "obstacle"
        else:
            self.skip(body, f"<{body.tag}> '{obj.get('name')}' is not translated")
            return
        dims = _child(body, "BoundingBox", "Dimensions") if body is not None else None
        height = None
        if dims is not None:
            length, width = self.value(dims, "length"), self.value(dims, "width")
            height = self.value(dims, "height") if dims.get("height") is not None else None
        if self.sidecar and name in self.sidecar.get("actors", {}):
            kind = self.sidecar["actors"][name]["vehicle"]
        if name == "ego" and kind != "car":
            self.approx(obj, f"the ego is a {kind} in the scenario; addt-dsl's stack drives a car")
            kind = "car"
        # The catalog's Performance bounds every speed change (esmini clamps the acceleration
        # of SpeedActions to it): [m/s^2]; None without one.
        perf = body.find("Performance") if body is not None and body.tag == "Vehicle" else None
        limits = {}
        for attr, key in (("maxAcceleration", "max_accel"), ("maxDeceleration", "max_decel")):
            if perf is not None and perf.get(attr) is not None:
                value = self.value(perf, attr, units.ACCELERATION)
                if value > 0 and math.isfinite(value):
                    limits[key] = value
        self.actors[name] = {**limits, "vehicle": kind, "length_m": length if length and length > 0 else None,
                             "width_m": width if width and width > 0 else None,
                             "height_m": height if height and 0.05 <= height <= 10.0 else None, "el": obj,
                             "behaviors": [], "triggers": [], "lane_now": None, "speed_now": 0.0}

    def catalog_entry(self, ref, kinds=("Vehicle", "Pedestrian", "MiscObject")):
        catalog, entry = self.raw(ref, "catalogName"), self.raw(ref, "entryName")
        locations = {loc.tag.removesuffix("Catalog"): loc.find("Directory")
                     for loc in self.doc.iterfind("CatalogLocations/*")}
        for kind in kinds:
            directory = locations.get(kind)
            if directory is None:
                continue
            base = self.raw(directory, "path")
            folder = self.path.parent / base
            if not self.inside(folder):
                continue
            for candidate in sorted(folder.glob("*.xosc"))[:64]:
                if candidate not in self.catalog_docs:  # each catalog file read and parsed once
                    got = self.read(os.path.relpath(candidate, self.path.parent), self.path.parent, ref)
                    self.catalog_docs[candidate] = self.parse(got[1], candidate.name) if got is not None else None
                root = self.catalog_docs[candidate]
                for el in root.iterfind(f"Catalog/{kind}") if root is not None else ():
                    if el.get("name") == entry:
                        return el
        if "Route" in kinds:
            self.skip(ref, f"route '{entry}' of catalog {catalog} not found",
                      "catalogs are read from <CatalogLocations> inside the root directory")
            return None
        self.approx(ref, f"catalog entry '{entry}' of {catalog} not found: a default car "
                         f"({VEHICLES['car'].length_m} x {VEHICLES['car'].width_m} m)",
                    "catalogs are read from <CatalogLocations> inside the root directory")
        return None

    def inside(self, folder) -> bool:
        try:
            return Path(folder).resolve().is_relative_to(self.root) and Path(folder).is_dir()
        except OSError:
            return False

    # -- positions

    def position(self, pos_el, who: str):
        """(road name, lane, s, offset) as expressions, or None after a diagnostic."""
        pos = _only_child(pos_el)
        if pos is None:
            self.error(pos_el, "a <Position> holds one position")
            return None
        if pos.tag == "LanePosition":
            road = self.road(self.raw(pos, "roadId"), pos)
            lane = int(self.value(pos, "laneId"))
            s = self.number(pos, "s", units.LENGTH)
            odr = self.network.road(next(i for i, r in self.roads.items() if r.name == road))
            s_val = float(eval_param_expr(s, self.param_values()))
            if not math.isfinite(s_val) or abs(s_val) > MAX_STATION_M or abs(lane) > MAX_LANE_ID:
                self.error(pos, f"s = {s_val:g} m, lane {lane}: not a place on any road "
                                f"(|s| at most {MAX_STATION_M:g} m, |laneId| at most {MAX_LANE_ID})")
                raise _Stop
            if 0.0 <= s_val <= odr.length + 1e-6 and lane not in _lane_ids(odr, s_val):
                self.error(pos, f"road {odr.id} has no lane {lane} at s = {s_val:g} m",
                           f"lanes there: {', '.join(str(i) for i in _lane_ids(odr, s_val))}")
                raise _Stop
            return road, lane, s, self.mirror(self.number(pos, "offset", units.LENGTH, 0.0))
        if pos.tag in ("RoadPosition", "WorldPosition", "RelativeRoadPosition", "RelativeLanePosition"):
            return self.position_from_road(pos, who)
        if pos.tag == "RoutePosition":
            return self.route_position(pos, who)
        self.skip(pos, f"<{pos.tag}> is not translated: {who} starts at the start of the first road",
                  "lane, road, world and relative road/lane positions are translated")
        return None

    def position_from_road(self, pos, who):
        if pos.tag == "RoadPosition":
            road_id, s, t = self.raw(pos, "roadId"), self.value(pos, "s"), self.mirror(self.value(pos, "t"))
        elif pos.tag == "WorldPosition":
            x, y = self.value(pos, "x"), self.mirror(self.value(pos, "y"))
            h = self.mirror(self.value(pos, "h")) if pos.get("h") is not None else None
            road_id, s, t = self.world_to_road(x, y, h)
        else:
            ref = self.actor_name(pos)
            if ref is None or ref not in self.placed:
                self.error(pos, f"{pos.tag} relative to '{pos.get('entityRef')}', which has no position yet")
                return None
            road_name, lane, s_ref, off_ref = self.placed[ref]
            params = self.param_values()
            road_id = next(i for i, r in self.roads.items() if r.name == road_name)
            if pos.tag == "RelativeLanePosition":
                d_lane = int(self.value(pos, "dLane"))
                new_lane = lane + d_lane
                if lane * new_lane <= 0 and d_lane:  # lane 0 is the reference line
                    new_lane += 1 if d_lane > 0 else -1
                ds = self.number(pos, "ds", units.LENGTH, 0.0)
                return road_name, new_lane, _plus(s_ref, ds), self.mirror(self.number(pos, "offset", units.LENGTH, 0.0))
            road = self.network.road(road_id)
            s = eval_param_expr(s_ref, params) + self.value(pos, "ds")
            t = road.lane_center_t(lane, eval_param_expr(s_ref, params)) + eval_param_expr(off_ref, params) \
                + self.mirror(self.value(pos, "dt"))
        road_name = self.road(str(road_id), pos)
        odr = self.network.road(str(road_id))
        lane = odr.lane_at(s, t)
        if lane is None:
            self.error(pos, f"{who}: no lane at s={s:g} m, t={t:g} m of road {road_id}")
            return None
        offset = t - odr.lane_center_t(lane, s)
        return road_name, lane, E.Num(value=round(s, 9)), E.Num(value=round(offset, 9))

    def world_to_road(self, x: float, y: float, h: float | None) -> tuple[str, float, float]:
        """(road id, s, t) of world point (x, y) [m]: among the roads with a lane there (the
        point alongside the road, not beyond an end), those whose lane is driven the way `h`
        [rad] faces first, then roads outside junctions (a junction's connecting roads overlap
        each other and the roads they join), then the least offset from the lane's centre.
        Without any such road: the road whose reference line is nearest."""
        best, nearest = None, None
        for rid in self.network.roads:
            road = self.network.road(rid)
            s, t = road.project(x, y)
            px, py = (float(v) for v in road.point_at(s, t))
            if nearest is None or abs(t) < abs(nearest[2]):
                nearest = (rid, s, t)
            lane = road.lane_at(s, t) if math.hypot(px - x, py - y) < 0.5 else None
            if lane is None:
                continue
            against = False
            if h is not None:
                lane_h = float(road.reference_pose(s)[2]) + (0.0 if road.travel_direction(lane) > 0 else math.pi)
                against = math.cos(h - lane_h) < 0
            key = (against, road.is_junction_road, abs(t - float(road.lane_center_t(lane, s))))
            if best is None or key < best[0]:
                best = (key, (rid, s, t))
        return best[1] if best is not None else nearest

    def route_element(self, ref_parent):
        """The <Route> of an AssignRouteAction or a RouteRef: inline, or a route catalog's
        entry (its parameters as the reference assigns them are not read); None after a
        diagnostic."""
        inline = ref_parent.find("Route")
        if inline is not None:
            return inline
        ref = ref_parent.find("CatalogReference")
        if ref is None:
            self.error(ref_parent, f"<{ref_parent.tag}> needs a <Route> or a <CatalogReference>")
            return None
        return self.catalog_entry(ref, kinds=("Route",))

    def route_position(self, pos, who: str):
        """A RoutePosition `FromLaneCoordinates`: `pathS` along the route from its first
        waypoint, in `laneId` there. Placed on the route's first road (the language counts
        `at S` along the route from its entry end), in the first-road lane whose route leg
        is `laneId` where the point is; the route becomes the actor's when nothing assigns
        one. (road, lane, s, offset) or None after a diagnostic."""
        route_el = self.route_element(_first(pos.find("RouteRef"), pos))
        lane_coords = pos.find("InRoutePosition/FromLaneCoordinates")
        if route_el is None or lane_coords is None:
            if route_el is not None:
                self.skip(_first(_only_child(pos.find("InRoutePosition")) if pos.find("InRoutePosition") is not None
                                 else None, pos), "a route position is translated from lane coordinates only")
            return None
        path_s, lane_id = self.value(lane_coords, "pathS", units.LENGTH), int(self.value(lane_coords, "laneId"))
        offset = self.mirror(self.number(lane_coords, "laneOffset", units.LENGTH, 0.0))
        first_wp = route_el.find("Waypoint/Position/LanePosition")
        stops = []
        for wp in route_el.iterfind("Waypoint/Position/*"):
            if wp.get("roadId") is None:
                self.skip(wp, "a waypoint that is not a lane or road position: the route position is not translated")
                return None
            if not stops or stops[-1] != self.resolve(wp.get("roadId")):
                stops.append(self.resolve(wp.get("roadId")))
        if first_wp is None or not stops or path_s < 0:
            self.skip(pos, "a route position needs a route that starts at a lane position and pathS >= 0")
            return None
        road_name = self.road(stops[0], first_wp)
        odr = self.network.road(stops[0])
        s_wp = self.value(first_wp, "s", units.LENGTH)
        candidates = sorted(odr.driving_lane_ids(min(max(s_wp, 0.0), odr.length)), key=lambda i: (i != lane_id, abs(i)))
        for lane in candidates:
            try:
                _, legs = resolve_route(self.network, stops, lane, None)
            except RouteError:
                continue
            u = abs(s_wp - legs[0].s_from) + path_s  # from the first road's entry end
            at, done = legs[-1], 0.0
            for leg in legs:
                if u <= done + abs(leg.s_to - leg.s_from) + 1e-9:
                    at = leg
                    break
                done += abs(leg.s_to - leg.s_from)
            if at.lane == lane_id:
                break
        else:
            self.skip(pos, f"no lane of road {stops[0]} leads along the route to lane {lane_id} at pathS "
                           f"{path_s:g} m: not translated")
            return None
        s_road = s_wp + legs[0].direction * path_s  # a station on the first road, or its continuation
        self.actors.get(who, {}).setdefault("route_from_position", route_el)
        return road_name, lane, E.Num(value=round(s_road, 9)), offset

    def against_s(self, pos_el, placed) -> bool:
        """Whether the entity faces against its lane's driving direction (addt-dsl, like
        OpenSCENARIO's default, drives an actor in its lane's direction)."""
        road_name, lane, s, _ = placed
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        odr = self.network.road(road_id)
        orient = _only_child(pos_el).find("Orientation") if _only_child(pos_el) is not None else None
        if orient is None or orient.get("h") is None or lane == 0:
            return False
        try:
            h = self.mirror(self.value(orient, "h"))
            if orient.get("type", "relative") == "absolute":
                s_now = float(eval_param_expr(s, self.param_values()))
                h -= odr.reference_pose(s_now)[2] + (0.0 if odr.travel_direction(lane) > 0 else math.pi)
            elif _only_child(pos_el).tag != "LanePosition":  # relative to the road's +s
                h -= 0.0 if odr.travel_direction(lane) > 0 else math.pi
            return math.cos(h) < 0
        except (ValueError, ArithmeticError, _Stop):
            return False

    # -- init

    def init(self, init) -> None:
        if init is None:  # no <Init>: every entity at its documented default place
            init = Element("Init")
        pairs = []
        for action in init.iterfind("Actions/GlobalAction"):
            env = _child(action, "EnvironmentAction", "Environment")
            if env is not None:
                self.environment_action(env)
            elif _child(action, "InfrastructureAction", "TrafficSignalAction") is not None:
                pairs += [(action, c) for c in self.light_clauses(action)]
            else:
                self.skip(action, "global actions other than the environment (traffic, parameters, "
                                  "signals) are not translated")
        # a light's state in Init: a step at time 0
        self.light_steps += [TriggerPlan(clause=c) for c in self.light_event(pairs)]
        init_trajectories, init_relative = [], []
        for private in init.iterfind("Actions/Private"):
            who = self.actor_name(private)
            if who is None or who not in self.actors:
                continue
            for pa in private.iterfind("PrivateAction"):
                act = _only_child(pa)
                if act is None:
                    continue
                if act.tag == "TeleportAction":
                    got = self.position(act.find("Position"), who)
                    if got is not None:
                        self.placed[who] = got
                        self.actors[who]["lane_now"] = got[1]
                        self.actors[who]["against_s"] = self.against_s(act.find("Position"), got)
                elif act.tag == "RoutingAction" and _child(act, "AssignRouteAction") is not None:
                    route_el = self.route_element(_child(act, "AssignRouteAction"))
                    if route_el is not None:
                        self.actors[who]["route_el"] = route_el
                elif act.tag == "RoutingAction" and _child(act, "FollowTrajectoryAction") is not None \
                        and (who != "ego" or self.scripted_ego):
                    init_trajectories.append((act, who))
                elif act.tag == "LongitudinalAction" and _child(act, "SpeedAction", "SpeedActionTarget",
                                                                "AbsoluteTargetSpeed") is not None:
                    target = _child(act, "SpeedAction", "SpeedActionTarget", "AbsoluteTargetSpeed")
                    dyn = _child(act, "SpeedAction", "SpeedActionDynamics")
                    if dyn is not None and dyn.get("dynamicsShape", "step") != "step" \
                            and (who != "ego" or self.scripted_ego) \
                            and self.value(dyn, "value", default=0.0) > 0:
                        # A speed change with dynamics in Init starts from standstill (OpenSCENARIO:
                        # Init actions run as the simulation starts) and takes its time.
                        clause = self.speed_action(dyn, target, self.actors[who])
                        if clause is not None:
                            self.actors[who]["behaviors"].append(clause)
                        continue
                    self.actors[who]["speed"] = self.number(target, "value", units.SPEED)
                    self.actors[who]["speed_now"] = self.value(target, "value")
                elif act.tag == "LongitudinalAction" and _child(act, "SpeedAction", "SpeedActionTarget",
                                                                "RelativeTargetSpeed") is not None:
                    init_relative.append((act, who))
                elif act.tag in ("ControllerAction", "ActivateControllerAction"):
                    self.approx(act, "a controller: the entity follows its actions, as under the default "
                                     "controller of OpenSCENARIO (the driver models of esmini are not emulated)")
                else:
                    self.skip(act, f"<{act.tag}> in Init is not translated (positions and speeds are)")
        for act, who in init_relative:  # relative to another entity's initial speed
            rel = _child(act, "SpeedAction", "SpeedActionTarget", "RelativeTargetSpeed")
            ref = self.actor_name(rel)
            if ref is None or ref not in self.actors:
                continue
            base = self.actors[ref].get("speed", E.Num(value=0.0))
            value = self.number(rel, "value", units.SPEED if rel.get("speedTargetValueType", "delta") == "delta"
                                else units.DIMENSIONLESS)
            op = "*" if rel.get("speedTargetValueType", "delta") == "factor" else "+"
            self.actors[who]["speed"] = E.Binary(op=op, left=value, right=base) if op == "*" else _plus(base, value)
            self.actors[who]["speed_now"] = eval_param_expr(self.actors[who]["speed"], self.param_values())
            if rel.get("continuous", "false") in ("true", "1") and (who != "ego" or self.scripted_ego):
                clause = self.relative_speed(_child(act, "SpeedAction", "SpeedActionDynamics"), rel, self.actors[who])
                if clause is not None:
                    self.actors[who]["behaviors"].append(clause)
        for act, who in init_trajectories:  # no TeleportAction: start at the first vertex
            first_vertex = act.find("FollowTrajectoryAction//Polyline/Vertex/Position")
            if who not in self.placed and first_vertex is not None:
                got = self.position(first_vertex, who)
                if got is not None:
                    self.placed[who] = got
                    self.actors[who]["lane_now"] = got[1]
        for who, info in self.actors.items():
            if who not in self.placed:
                self.approx(info["el"], f"{who} has no translated initial position: lane -1 at s = 0 m of the "
                                        "first road")
                first = self.road(next(iter(self.network.roads)), info["el"])
                self.placed[who] = (first, -1, E.Num(value=0.0), E.Num(value=0.0))
        for act, who in init_trajectories:  # a trajectory from the start: once every actor is placed
            clause = self.trajectory(_child(act, "FollowTrajectoryAction"), who)
            if clause is not None:
                self.actors[who]["behaviors"].append(clause)

    # -- actions

    def private_action(self, act, who: str):
        """The behaviour clause an action starts, or None after a diagnostic."""
        if who == "ego" and not self.scripted_ego:
            self.approx(act, f"<{act.tag}> on the ego: the stack under test drives the ego",
                        "`addtc import --ego scripted` makes the ego follow the file's actions")
            return None
        info = self.actors[who]
        if act.tag == "LongitudinalAction":
            speed = _child(act, "SpeedAction")
            if _child(act, "SpeedProfileAction") is not None:
                return self.speed_profile(_child(act, "SpeedProfileAction"), info)
            if _child(act, "LongitudinalDistanceAction") is not None:
                return self.keep_gap(_child(act, "LongitudinalDistanceAction"), who)
            relative = _child(speed, "SpeedActionTarget", "RelativeTargetSpeed")
            if relative is not None:
                return self.relative_speed(speed.find("SpeedActionDynamics"), relative, info)
            target = _child(speed, "SpeedActionTarget", "AbsoluteTargetSpeed")
            if speed is None or target is None:
                self.skip(_first(_only_child(act), act), f"<{_first(_only_child(act), act).tag}> is not translated",
                          "absolute and relative speed targets are translated")
                return None
            return self.speed_action(speed.find("SpeedActionDynamics"), target, info)
        if act.tag == "LateralAction":
            change = _child(act, "LaneChangeAction")
            if change is None:
                self.skip(_first(_only_child(act), act), f"<{_first(_only_child(act), act).tag}> is not translated",
                          "the language has lane changes; lane offsets and lateral distances are not translated")
                return None
            return self.lane_change(change, who, info)
        if act.tag == "ActivateControllerAction":
            self.approx(act, "a controller: the entity follows its actions, as under the default controller "
                             "of OpenSCENARIO (the driver models of esmini are not emulated)")
            return None
        if act.tag == "ControllerAction":
            ctrl = act.find(".//Controller")
            if ctrl is not None and (ctrl.get("name") or "").startswith(CONTROLLER_PREFIX):
                keyword = ctrl.get("name")[len(CONTROLLER_PREFIX):]
                if keyword in BEHAVIORS:
                    settings = {}
                    for prop in ctrl.iterfind("Properties/Property"):
                        raw = prop.get("value", "")
                        if raw == "":
                            continue  # an empty setting is the default
                        try:
                            settings[prop.get("name")] = _setting(json.loads(raw))
                        except ValueError:
                            settings[prop.get("name")] = raw
                    return ClausePlan(keyword="behavior", name=keyword, settings=settings)
            self.approx(act, "a controller: the entity follows its actions, as under the default controller "
                             "of OpenSCENARIO (the driver models of esmini are not emulated)")
            return None
        if act.tag == "TeleportAction":
            return self.teleport(act, who)
        if act.tag == "SynchronizeAction":
            return self.synchronize(act, who)
        if act.tag == "RoutingAction" and _child(act, "FollowTrajectoryAction") is not None:
            return self.trajectory(_child(act, "FollowTrajectoryAction"), who)
        self.skip(act, f"<{act.tag}> is not translated",
                  "translated: speed (absolute, relative, profiles), lane changes, longitudinal distance, "
                  "synchronize, polyline trajectories, routes in Init")
        return None

    def speed_profile(self, el, info) -> ClausePlan | None:
        entries = list(el.iterfind("SpeedProfileEntry"))
        if not entries or any(e.get("time") is None for e in entries):
            self.skip(el, "a speed profile without entry times is not translated",
                      "`speed_profile` needs the time of each point")
            return None
        # Entry times are durations from the previous entry: cumulative times from the start.
        times, clock = [], 0.0
        for e in entries:
            clock += max(self.value(e, "time"), 0.0)
            times.append(clock)
        if any(b <= a for a, b in zip(times, times[1:])):
            self.skip(el, "a speed profile whose entries take no time is not translated")
            return None
        if el.get("followingMode") == "follow":
            self.approx(el, "followingMode follow (smoothed within dynamic constraints): `speed_profile` meets "
                            "every point, as followingMode position")
        speeds = [self.value(e, "speed") for e in entries]
        if times[0] > 0.0:  # the language's first point is at its own time: from the current speed
            pass
        info["speed_now"] = speeds[-1]
        return ClausePlan(keyword="behavior", name="speed_profile",
                          settings={"times": [E.Num(value=x) for x in times],
                                    "speeds": [E.Num(value=v) for v in speeds]})

    def relative_speed(self, dyn, rel, info) -> ClausePlan | None:
        ref = self.actor_name(rel)
        if ref is None:
            return None
        value = self.value(rel, "value")
        kind = rel.get("speedTargetValueType", "delta")
        if rel.get("continuous", "false") not in ("true", "1"):
            self.approx(rel, "a relative speed target that is not continuous: followed continuously")
        other = E.Signal(name=f"speed({ref})")
        if kind == "factor":
            speed = E.Binary(op="*", left=E.Num(value=value), right=other)
        elif value:
            speed = E.Binary(op="+", left=other, right=E.Num(value=value))
        else:
            speed = other
        settings = {"speed": speed}
        if dyn is not None:
            settings.update(self.speed_dynamics(dyn))
        return ClausePlan(keyword="behavior", name="cruise", settings=settings)

    def speed_dynamics(self, dyn) -> dict:
        """Shape and rate/duration of a speed change as `cruise` settings (rate: the average)."""
        shape = self.raw(dyn, "dynamicsShape")
        dim = self.raw(dyn, "dynamicsDimension")
        amount = abs(self.value(dyn, "value"))
        if shape not in PEAK_SLOPE or shape == "quintic":
            self.approx(dyn, f"dynamics shape {shape}: linear")
            shape = "linear"
        out = {"shape": shape} if shape != "linear" else {}
        if shape == "step":
            return out
        if dim == "time":
            out["duration"] = E.Num(value=amount)
        elif dim == "rate":
            rate = max(amount * PEAK_SLOPE[shape], 0.01)
            out.update(accel=E.Num(value=rate), decel=E.Num(value=rate))
        else:
            self.approx(dyn, f"a speed change over a {dim}: at the default rate limits")
        return out

    def keep_gap(self, el, who: str) -> ClausePlan | None:
        ref = self.actor_name(el)
        if ref is None:
            return None
        settings = {"target": ref}
        if el.get("distance") is not None:
            settings["distance"] = E.Num(value=self.value(el, "distance"))
        elif el.get("timeGap") is not None:
            settings["time_gap"] = E.Num(value=self.value(el, "timeGap"))
        else:
            self.error(el, "a LongitudinalDistanceAction needs a distance or a timeGap")
            return None
        if el.get("displacement") == "leadingReferencedEntity":
            settings["side"] = "ahead"
        limits = el.find("DynamicConstraints")
        for attr, key in (("maxAcceleration", "accel"), ("maxDeceleration", "decel")):
            src = el if el.get(attr) is not None else limits
            if src is not None and src.get(attr) is not None:
                settings[key] = E.Num(value=max(self.value(src, attr), 0.01))
        if el.get("freespace") in ("false", "0"):
            if "distance" in settings:  # between reference points (the actors' centres here)
                half = 0.5 * (self.size(who)[0] + self.size(ref)[0])
                settings["distance"] = E.Num(value=max(settings["distance"].value - half, 0.0))
            else:
                self.approx(el, "a time gap between reference points: kept as a bumper-to-bumper gap")
        return ClausePlan(keyword="behavior", name="keep_gap", settings=settings)

    def road_point(self, pos_el, who: str):
        """(s, t) of a position on the actor's road, or None after a diagnostic."""
        got = self.position(pos_el, who)
        if got is None:
            return None
        road, lane, s, offset = got
        params = self.param_values()
        road_id = next(i for i, r in self.roads.items() if r.name == road)
        if road != self.placed[who][0]:
            self.approx(pos_el, f"a point on road {road_id}, not {who}'s road: its s and t are used as they are")
        s_val = float(eval_param_expr(s, params))
        odr = self.network.road(road_id)
        if not 0.0 <= s_val <= odr.length:
            self.skip(pos_el, f"a point at s = {s_val:g} m, beyond road {road_id} ({odr.length:.6g} m): not translated")
            return None
        try:
            t_val = odr.lane_center_t(lane, s_val) + float(eval_param_expr(offset, params))
        except ValueError as exc:
            self.skip(pos_el, f"a point the road does not have: {exc}")
            return None
        return s_val, t_val

    def teleport(self, act, who: str) -> ClausePlan | None:
        """A TeleportAction during the run: to a lane or road position of the road the actor
        is on (`teleport s S t T`, road coordinates); to its own position moved only in
        height, nothing (the twin's actors follow the road's height)."""
        pos_el = act.find("Position")
        pos = _only_child(pos_el) if pos_el is not None else None
        if pos is None:
            self.error(act, "a TeleportAction needs one <Position>")
            return None
        if pos.tag == "RelativeObjectPosition" and self.actor_name(pos) == who and \
                self.value(pos, "dx", default=0.0) == 0.0 and self.value(pos, "dy", default=0.0) == 0.0:
            self.approx(act, "a teleport that only raises or lowers the actor: nothing (actors follow the road's height)")
            return None
        if pos.tag in ("LanePosition", "RoadPosition"):
            road = self.road(self.raw(pos, "roadId"), pos)
            if road == self.placed[who][0] and not self.actors[who].get("route_el"):
                got = self.road_point(pos_el, who)
                if got is None:
                    return None
                s_val, t_val = got
                return ClausePlan(keyword="behavior", name="teleport",
                                  settings={"s": E.Num(value=round(s_val, 9)), "t": E.Num(value=round(t_val, 9))})
        self.skip(act, f"a teleport to a <{pos.tag}> is not translated",
                  "a lane or road position on the road the actor drives (without a route) is")
        return None

    def synchronize(self, act, who: str) -> ClausePlan | None:
        master = self.actor_name(act, "masterEntityRef")
        if master is None:
            return None
        master_pos = self.position(_first(act.find("TargetPositionMaster"), act), master)
        own = self.road_point(_first(act.find("TargetPosition"), act), who)
        if master_pos is None or own is None:
            return None
        # Stations as `s(A)` measures them: along each actor's own path (a lane driven
        # against s, a route: from the path's entry end).
        settings = {"master": master, "master_at": self.frame_station(master, master_pos[2])
                    if master_pos[0] == self.placed[master][0] else master_pos[2],
                    "target_s": self.frame_station(who, E.Num(value=round(own[0], 9))),
                    "target_t": E.Num(value=round(own[1], 9))}
        road, lane, s0, off0 = self.placed[who]
        params = self.param_values()
        road_id = next(i for i, r in self.roads.items() if r.name == road)
        s0_val = float(eval_param_expr(s0, params))
        try:
            t0 = self.network.road(road_id).lane_center_t(lane, s0_val) + float(eval_param_expr(off0, params))
        except ValueError:  # placed where the road has no such lane (reported with the position)
            t0 = own[1]
        if abs(own[1] - t0) > 0.5 and self.along_s(who):
            # Across the road: head for the point (the language's synchronize moves along a heading).
            settings["heading"] = E.Num(value=round(math.atan2(own[1] - t0, own[0] - s0_val), 9))
            self.approx(act, f"{who} heads straight for its target point from where it starts")
        final = _child(act, "FinalSpeed", "AbsoluteSpeed")
        if final is not None:
            settings["final_speed"] = E.Num(value=self.value(final, "value"))
        elif act.find("FinalSpeed") is not None:
            self.approx(act.find("FinalSpeed"), "a final speed relative to the master: the speed reached is kept")
        if act.find("TargetPositionMaster/LanePosition") is None and act.find("TargetPositionMaster") is not None:
            self.approx(act.find("TargetPositionMaster"), "the master's target point: its station on its road")
        return ClausePlan(keyword="behavior", name="synchronize", settings=settings)

    def trajectory(self, follow, who: str) -> ClausePlan | None:
        traj = _first(follow.find("TrajectoryRef/Trajectory"), follow.find("Trajectory"))
        if traj is None:
            self.skip(follow, "a trajectory from a catalog is not translated")
            return None
        shape = _only_child(traj.find("Shape")) if traj.find("Shape") is not None else None
        if shape is None:
            self.error(_first(traj.find("Shape"), traj), "a trajectory needs one shape")
            return None
        if shape.tag in ("Clothoid", "Nurbs"):
            got = self.clothoid(shape, who) if shape.tag == "Clothoid" else self.nurbs(shape, who)
            if got is None:
                return None
            points, times = got
            keys = ("x", "y")
            self.approx(shape, f"a {shape.tag.lower()} trajectory: sampled as a polyline of {len(points)} world "
                               "points (the language's trajectories are polylines)")
        elif shape.tag == "Polyline":
            points, times, keys = [], [], ("s", "t")
            for vertex in shape.iterfind("Vertex"):
                got = self.road_point(_first(vertex.find("Position"), vertex), who)
                if got is None:
                    return None
                points.append(got)
                if vertex.get("time") is not None:
                    times.append(self.value(vertex, "time"))
            if len(points) < 1:
                self.error(shape, "a polyline needs vertices")
                return None
        else:
            self.skip(shape, f"<{shape.tag}> trajectories are not translated",
                      "polylines are; clothoids and NURBS are sampled")
            return None
        settings = {keys[0]: [E.Num(value=round(p[0], 9)) for p in points],
                    keys[1]: [E.Num(value=round(p[1], 9)) for p in points]}
        timing = follow.find("TimeReference/Timing")
        if timing is not None and times and len(times) == len(points):
            offset = self.value(timing, "offset", default=0.0)
            scale = self.value(timing, "scale", default=1.0)
            times = [scale * x + offset for x in times]
            if timing.get("domainAbsoluteRelative") == "absolute":
                self.approx(timing, "absolute vertex times: taken from the start of the trajectory")
            if all(b > a for a, b in zip(times, times[1:])) and times[0] >= 0.0:
                settings["times"] = [E.Num(value=round(x, 9)) for x in times]
            else:
                self.approx(timing, "vertex times that do not increase: driven at the default speed")
        return ClausePlan(keyword="behavior", name="trajectory", settings=settings)

    def world_point(self, pos_el, who: str):
        """(x, y, heading) [m, m, rad] of a position, facing its lane's driving direction (or
        its `Orientation`); None after a diagnostic."""
        got = self.position(pos_el, who)
        if got is None:
            return None
        road, lane, s, offset = got
        params = self.param_values()
        odr = self.network.road(next(i for i, r in self.roads.items() if r.name == road))
        s_val = min(max(float(eval_param_expr(s, params)), 0.0), odr.length)
        t_val = odr.lane_center_t(lane, s_val) + float(eval_param_expr(offset, params))
        x, y, h = (float(v) for v in odr.reference_pose(s_val))
        heading = h + (math.pi if lane > 0 and odr.travel_direction(lane) < 0 else 0.0)
        orient = pos_el.find(".//Orientation")
        if orient is not None and orient.get("h") is not None:
            turn = self.mirror(self.value(orient, "h"))
            heading = turn if orient.get("type") == "absolute" else heading + turn
        return x - t_val * math.sin(h), y + t_val * math.cos(h), heading

    def clothoid(self, el, who: str):
        """A clothoid (curvature k0 + k' u over its length) from its start pose, sampled
        about every 2 m; times linear in arc length from startTime to stopTime."""
        start = self.world_point(_first(el.find("Position"), el), who)
        if start is None:
            return None
        k0 = self.mirror(self.value(el, "curvature"))  # a left turn is a right one in CARLA's frame
        rate = el.get("curvaturePrime") if el.get("curvaturePrime") is not None else el.get("curvatureDot")
        k1 = self.mirror(self.value(el, "curvaturePrime" if el.get("curvaturePrime") is not None else "curvatureDot")) \
            if rate is not None else 0.0
        length = self.value(el, "length")
        if not 0.0 < length <= 10000.0:
            self.skip(el, f"a clothoid {length:g} m long is not translated (0 to 10 km)")
            return None
        count = int(min(max(math.ceil(length / 2.0), 8), 200))
        fine = 20 * count  # heading integrated on a grid 20 times finer than the samples
        x, y, h0 = start
        points = [(x, y)]
        du = length / fine
        for i in range(1, fine + 1):
            u_mid = (i - 0.5) * du
            heading = h0 + k0 * u_mid + 0.5 * k1 * u_mid * u_mid
            x, y = x + du * math.cos(heading), y + du * math.sin(heading)
            if i % 20 == 0:
                points.append((x, y))
        times = []
        if el.get("startTime") is not None and el.get("stopTime") is not None:
            t0, t1 = self.value(el, "startTime"), self.value(el, "stopTime")
            times = [t0 + (t1 - t0) * i / count for i in range(count + 1)]
        return points, times

    def nurbs(self, el, who: str):
        """A NURBS curve (Cox-de Boor) through its control points' world positions, sampled
        at evenly spaced parameters; times by the same rational basis when every control
        point has one."""
        order = int(self.value(el, "order"))
        cps = list(el.iterfind("ControlPoint"))
        knots = [self.value(k, "value") for k in el.iterfind("Knot")]
        if order < 2 or len(cps) < order or len(knots) != len(cps) + order or \
                any(b < a for a, b in zip(knots, knots[1:])) or knots[order - 1] >= knots[len(cps)]:
            self.error(el, f"a NURBS of order {order} with {len(cps)} control points needs {len(cps) + order} "
                           f"non-decreasing knots (it has {len(knots)})")
            return None
        pts, weights, stamps = [], [], []
        for cp in cps:
            got = self.world_point(_first(cp.find("Position"), cp), who)
            if got is None:
                return None
            pts.append(got[:2])
            weights.append(self.value(cp, "weight", default=1.0))
            stamps.append(self.value(cp, "time") if cp.get("time") is not None else None)
        lo, hi = knots[order - 1], knots[len(cps)]
        count = int(min(max(10 * len(cps), 20), 200))
        points, times = [], []
        for j in range(count + 1):
            u = lo + (hi - lo) * j / count
            basis = _bspline_basis(knots, order, len(cps), min(u, hi - 1e-9 * (hi - lo)))
            w = [b * wt for b, wt in zip(basis, weights)]
            total = sum(w)
            if total <= 0.0:
                self.error(el, "a NURBS whose weights cancel")
                return None
            points.append((sum(wi * p[0] for wi, p in zip(w, pts)) / total,
                           sum(wi * p[1] for wi, p in zip(w, pts)) / total))
            if None not in stamps:
                times.append(sum(wi * t for wi, t in zip(w, stamps)) / total)
        return points, times

    def route(self, route_el, who: str, lane: int, s):
        """An AssignRouteAction's waypoints as the actor's route (road ids, connecting roads
        included) and its start station along the route; None after a diagnostic."""
        stops = []
        for wp in route_el.iterfind("Waypoint"):
            pos = _only_child(wp.find("Position")) if wp.find("Position") is not None else None
            road_id = pos.get("roadId") if pos is not None else None
            if road_id is None:
                self.skip(wp, "a waypoint that is not a lane or road position: the route is not translated")
                return None
            if not stops or stops[-1] != road_id:
                stops.append(self.resolve(road_id))
        first = self.placed[who][0]
        if self.roads.get(stops[0]) is None or self.roads[stops[0]].name != first:
            self.skip(route_el, f"a route that does not start on {who}'s road: not translated")
            return None
        try:
            roads, _ = resolve_route(self.network, stops, lane, None)
        except RouteError as exc:
            self.skip(route_el, f"the route is not translated: {exc}")
            return None
        return roads, s  # `at` stays the first road's station on a route too

    def straight_on(self, road_name: str, lane: int, s, reach_m: float) -> list[str] | None:
        """A route for an ego the file gives none: from its lane, on along each road's link
        and through each junction straight on, else turning to the kerb side, else the other
        way, never onto a road it already has, until `reach_m` [m] beyond its start or a
        road end with no such way on. None when it never leaves its road."""
        first = next(i for i, r in self.roads.items() if r.name == road_name)
        try:
            s0 = float(eval_param_expr(s, self.param_values()))
            roads, legs = resolve_route(self.network, [first], lane, s0)
        except (RouteError, KeyError, ValueError, ArithmeticError):
            return None
        stops = [first]
        for _ in range(64):
            if sum(abs(g.s_to - g.s_from) for g in legs) >= reach_m:
                break
            last = legs[-1]
            outs = exits(self.network, last.road_id, "end" if last.direction > 0 else "start")
            direct = [e.road_id for e in outs if e.connection is None or e.connection.direct]
            turns = {turn_of(self.network, e.road_id, e.contact) for e in outs}
            # Straight on where a junction allows it, else the turn that crosses no oncoming
            # traffic (right under right-hand traffic), else the other; never onto a road the
            # route already has (the language's routes do not repeat a road).
            kerb, far = ("right", "left") if self.network.road(last.road_id).rule == "RHT" else ("left", "right")
            options = direct[:1] if direct else [t for t in ("straight", kerb, far) if t in turns]
            for step in options:
                try:
                    more, more_legs = resolve_route(self.network, stops + [step], lane, s0)
                except RouteError:
                    continue
                if len(set(more)) == len(more):
                    break
            else:
                break
            stops, roads, legs = list(more), more, more_legs  # (a turn's road after the junction named)
        return roads if len(roads) > 1 else None

    def environment_action(self, env) -> None:
        weather = env.find("Weather")
        if weather is None:
            self.approx(env, "an environment without weather: clear daylight")
            return
        fog, rain, sun = weather.find("Fog"), weather.find("Precipitation"), weather.find("Sun")
        if fog is not None:
            visibility = min(max(self.value(fog, "visualRange"), 10.0), 100000.0)
            self.environment.append(ClausePlan(keyword="environment", name="fog",
                                               settings={"visibility": E.Num(value=visibility)}))
        if rain is not None and rain.get("precipitationType") == "rain":
            intensity = rain.get("precipitationIntensity") or rain.get("intensity")
            if intensity is not None:
                rate = min(float(self.resolve(intensity)), 200.0) * units.lookup("mm/h").factor
                if rate > 0:
                    self.environment.append(ClausePlan(keyword="environment", name="rain",
                                                       settings={"rate": E.Num(value=rate)}))
        elif rain is not None and rain.get("precipitationType") not in (None, "dry"):
            self.approx(rain, f"precipitation {rain.get('precipitationType')}: no model (rain, fog, light are)")
        if sun is not None and sun.get("elevation") is not None:
            elevation = min(max(self.value(sun, "elevation"), -math.pi / 2), math.pi / 2)
            self.environment.append(ClausePlan(keyword="environment", name="light",
                                               settings={"sun": E.Num(value=elevation)}))

    def speed_action(self, dyn, target, info) -> ClausePlan | None:
        v = self.number(target, "value", units.SPEED)
        v_now = float(eval_param_expr(v, self.param_values()))
        shape = self.raw(dyn, "dynamicsShape") if dyn is not None else "step"
        dim = self.raw(dyn, "dynamicsDimension") if dyn is not None else "time"
        amount = abs(self.value(dyn, "value")) if dyn is not None else 0.0
        dv = v_now - info["speed_now"]
        if shape == "step" or amount == 0.0:  # at once, as esmini sets it when the action starts
            info["speed_now"] = v_now
            return ClausePlan(keyword="behavior", name="cruise", settings={"speed": v, "shape": "step"})
        if dim == "rate":
            rate = amount
        elif dim == "time":
            rate = abs(dv) / amount if dv else 1.0
        else:  # distance: v1^2 - v0^2 = 2 a d
            rate = abs(v_now ** 2 - info["speed_now"] ** 2) / (2 * amount) if dv else 1.0
        rate = max(rate, 0.01)
        if shape != "step" and amount > 0.0:
            limit = info.get("max_accel" if dv > 0 else "max_decel")
            rate = min(rate, limit) if limit is not None and dim in ("time", "rate") and shape == "linear" else rate
        info["speed_now"] = v_now
        if shape in ("cubic", "sinusoidal") and dv and dim in ("time", "rate"):
            return ClausePlan(keyword="behavior", name="cruise", settings={"speed": v, **self.speed_dynamics(dyn)})
        if dv < 0:  # constant deceleration to a speed: exactly `brake`
            return ClausePlan(keyword="behavior", name="brake",
                              settings={"decel": E.Num(value=min(rate, 12.0)), "to_speed": v})
        if shape != "step" and shape != "linear" and dv:
            self.approx(dyn, f"a {shape} speed change over a distance: `cruise` at {rate:.3g} m/s^2")
        return ClausePlan(keyword="behavior", name="cruise",
                          settings={"speed": v, "accel": E.Num(value=rate), "decel": E.Num(value=rate)})

    def lane_change(self, change, who, info) -> ClausePlan | None:
        dyn, target = change.find("LaneChangeActionDynamics"), change.find("LaneChangeTarget")
        tgt = _only_child(target)
        if tgt is None or dyn is None:
            self.error(change, "a lane change needs dynamics and a target")
            return None
        extra = {}
        shape = self.raw(dyn, "dynamicsShape", required=False)
        if shape in ("linear", "cubic", "sinusoidal", "step"):
            extra["shape"] = shape
        if tgt.tag == "RelativeTargetLane" and tgt.get("entityRef") not in (None, who) \
                and int(self.value(tgt, "value")) == 0:
            ref = self.actor_name(tgt)
            if ref is None:
                return None
            lane = self.actors[ref]["lane_now"] if ref in self.actors else None
            extra["to_lane_of"] = ref
        elif tgt.tag == "AbsoluteTargetLane":
            lane = int(self.value(tgt, "value"))
        else:
            ref = self.actor_name(tgt)
            if ref is None:
                return None
            base = self.actors[ref]["lane_now"] if ref != who else info["lane_now"]
            if base is None:
                self.skip(tgt, f"lane relative to {ref}, whose lane is not known (no translated position)")
                return None
            if ref != who:
                self.approx(tgt, f"lane relative to {ref}: its lane at the start ({base}), not at the change",
                            "`lane_change to_lane_of X` takes X's lane when the change starts (offset 0)")
            d = int(self.value(tgt, "value"))
            lane = base + d
            if base * lane <= 0 and d:
                lane += 1 if d > 0 else -1
        dim = self.raw(dyn, "dynamicsDimension")
        amount = abs(self.value(dyn, "value"))
        if dim == "time":
            duration = amount
        elif dim == "distance":
            duration = amount / max(info["speed_now"], 1.0)
            self.approx(dyn, f"a lane change over {amount:g} m: {duration:.3g} s at {info['speed_now']:.3g} m/s")
        else:
            duration = 3.5 / max(amount, 0.1)
            self.approx(dyn, f"a lane change at a lateral rate: {duration:.3g} s for a 3.5 m lane")
        info["lane_now"] = lane
        if "to_lane_of" in extra:
            return ClausePlan(keyword="behavior", name="lane_change",
                              settings={"duration": E.Num(value=max(duration, 0.5)), **extra})
        return ClausePlan(keyword="behavior", name="lane_change",
                          settings={"to": E.Num(value=float(lane)), "duration": E.Num(value=max(duration, 0.5)),
                                    **extra})

    # -- stop trigger

    def stop_trigger(self, trigger) -> float:
        """The run's duration: a stop condition group that is a simulation time alone (the
        rest of the stop trigger is `end when ...`, `end_trigger`)."""
        for group in trigger.iterfind("ConditionGroup") if trigger is not None else ():
            conds = list(group.iterfind("Condition"))
            time = conds[0].find("ByValueCondition/SimulationTimeCondition") if len(conds) == 1 else None
            if time is not None and (time.get("rule") or "").startswith("greater"):
                return min(max(self.value(time, "value") + self.value(conds[0], "delay", units.TIME, 0.0), 0.1),
                           MAX_DURATION_S)
        others = trigger is not None and any(True for _ in trigger.iterfind("ConditionGroup/Condition"))
        self.approx(trigger, f"no simulation-time stop trigger: at most {DEFAULT_DURATION_S:g} s"
                    + (" (the run ends when its stop condition holds)" if others else ""))
        return DEFAULT_DURATION_S

    # -- storyboard

    def story(self, story) -> None:
        self.story_name = story.get("name", "")
        for act in story.iterfind("Act"):
            self.act_name = act.get("name", "")
            act_at = None
            groups = list(act.iterfind("StartTrigger/ConditionGroup"))
            for cond in act.iterfind("StartTrigger/ConditionGroup/Condition"):
                time = cond.find("ByValueCondition/SimulationTimeCondition")
                sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
                if len(groups) > 1:
                    self.skip(cond, "an act start trigger of several condition groups is not translated")
                elif time is not None and (time.get("rule") or "").startswith("greater") \
                        and self.value(cond, "delay", units.TIME, 0.0) == 0.0:
                    value = self.value(time, "value")
                    act_at = max(act_at or 0.0, value) if value > 0 else act_at
                elif sesc is not None and self.raw(sesc, "storyboardElementType") == "story" \
                        and self.raw(sesc, "storyboardElementRef") == self.story_name \
                        and self.raw(sesc, "state") in ("startTransition", "runningState") \
                        and self.value(cond, "delay", units.TIME, 0.0) == 0.0:
                    continue  # its own story running: the act starts with it
                else:
                    self.skip(cond, "act start conditions other than the simulation time and the story running "
                                    "are not translated")
            for stop in act.iterfind("StopTrigger/ConditionGroup"):
                if all((c.get("name") or "").startswith("criteria_") for c in stop.iterfind("Condition")):
                    continue  # CARLA ScenarioRunner's pass criteria: oracles (pass_criteria)
                self.skip(stop, "act stop triggers are not translated")
            for group in act.iterfind("ManeuverGroup"):
                self.maneuver_group(group, act_at)
        self.link_sequences()

    def maneuver_group(self, group, act_at) -> None:
        refs = [self.actor_name(r) for r in group.iterfind("Actors/EntityRef")]
        refs = [r for r in refs if r is not None]
        if int(self.value(group, "maximumExecutionCount", default=1.0)) > 1:
            self.skip(group, "a maneuver group that runs more than once is not translated")
        if len(refs) > 1:
            self.skip(group, f"maneuver group with {len(refs)} actors: translated for one actor only")
        who = refs[0] if refs else None  # no actor: its events' global actions (light steps) only
        maneuvers = list(group.iterfind("Maneuver"))
        if group.find("CatalogReference") is not None:
            self.skip(group.find("CatalogReference"), "maneuver catalogs are not translated")
        for maneuver in maneuvers:
            self.maneuvers.setdefault(maneuver.get("name", ""), []).extend(
                e.get("name", "") for e in maneuver.iterfind("Event"))
            for event in maneuver.iterfind("Event"):
                self.event(event, who, act_at)

    def event(self, event, who: str, act_at) -> None:
        name = event.get("name", "")
        if name in (self.sidecar or {}).get("group_events", ()):
            return  # a step of a group: the side file has the group (appended in `plan`)
        actions = list(event.iterfind("Action"))
        clauses, lights = [], []
        for action in actions:
            body = _only_child(action)
            if body is None:
                continue
            if body.tag == "GlobalAction" and _child(body, "InfrastructureAction", "TrafficSignalAction") is not None:
                exact = ((self.sidecar or {}).get("lights") or {}).get("steps", {}).get(name)
                if exact and exact.get("name") not in self.light_ctls:
                    self.error(body, f"the side file's light step {name!r} names controller "
                                     f"{exact.get('name')!r}, which this file does not have")
                    raise _Stop
                lights += [(body, ClausePlan.model_validate(exact))] if exact else \
                    [(body, c) for c in self.light_clauses(body)]
                continue
            if body.tag == "GlobalAction" and body.find("EnvironmentAction") is not None:
                self.skip(body.find("EnvironmentAction"), "an environment change in an event is not translated: "
                          "`environment { }` holds for the whole run (the language has no environment steps)",
                          "an EnvironmentAction in Init is translated")
                continue
            if body.tag != "PrivateAction":
                self.skip(body, f"<{body.tag}> is not translated (private actions are)")
                continue
            if who is None:
                self.skip(body, f"<{_first(_only_child(body), body).tag}> in a maneuver group without actors is "
                                "not translated")
                continue
            inner = _only_child(body)
            if inner is None:
                continue
            if inner.tag == "VisibilityAction" and len(actions) == 1:
                # An exported group's anchor (a no-op): the events it starts form one group.
                step = self.start(event.find("StartTrigger"), who, act_at)
                if step is not None and step[0] == "now":
                    self.anchors[name] = (who, step[1])
                return
            exact = (self.sidecar or {}).get("behaviors", {}).get(name)
            clause = ClausePlan.model_validate(exact["clause"]) if exact else self.private_action(inner, who)
            if clause is not None:
                clauses.append(clause)
        if lights:
            self.light_step(event, self.light_event(lights), who, act_at)
        if not clauses:
            return
        trigger = event.find("StartTrigger")
        step = self.start(trigger, who, act_at, name)
        if step is None:
            return
        kind, fields = step
        clauses = _speed_into_trajectory(clauses)
        if len(clauses) > 1:
            self.approx(event, f"event '{name}' starts {len(clauses)} actions: one step each, same start")
        runs = int(self.value(event, "maximumExecutionCount", default=1.0))
        if runs > 1:
            # It starts again when its actions have ended and its condition counts again.
            if kind != "now" or fields.get("condition") is None or len(clauses) > 1:
                self.skip(event, f"an event that runs up to {runs} times without a start condition of its own, or "
                                 "with several actions, is not translated",
                          "one action started by a condition translates (`when C repeat N`)")
                return
            fields = {**fields, "repeat": min(runs, 1_000_000)}
        for clause in clauses:
            self.events.setdefault(name, (who, kind, fields, clause))
            if kind == "after_event":
                self.pending.append((name, who, fields, clause))
            elif not fields:
                self.actors[who]["behaviors"].append(clause)
            else:
                self.actors[who]["triggers"].append(TriggerPlan(clause=clause, **fields))

    def light_step(self, event, clauses: list[ClausePlan], who, act_at) -> None:
        if not clauses:
            return
        step = self.start(event.find("StartTrigger"), who, act_at, event.get("name", ""))
        if step is None:
            return
        kind, fields = step
        if kind == "after_event":
            self.skip(fields[3], f"light step '{event.get('name')}' starts on another event: not translated",
                      "a lights block's steps start at a time, after a delay or on a condition")
            return
        self.light_steps += [TriggerPlan(clause=c, **fields) for c in clauses]

    def start(self, trigger, who: str, act_at, event: str = ""):
        """('now', fields of a TriggerPlan) or ('after_event', (event, delay, state)); None: dropped."""
        groups = list(trigger.iterfind("ConditionGroup")) if trigger is not None else []
        alternatives, at_s, holds, edges = [], act_at, [], []
        for group in groups:
            conj = []
            for cond in group.iterfind("Condition"):
                sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
                if sesc is not None and self.raw(sesc, "storyboardElementType") in ("act", "story") \
                        and self.raw(sesc, "state") in ("startTransition", "runningState") \
                        and self.raw(sesc, "storyboardElementRef") in (getattr(self, "act_name", None),
                                                                       getattr(self, "story_name", None)) \
                        and self.value(cond, "delay", units.TIME, 0.0) == 0.0:
                    continue  # the event's own act (story) has started: true whenever the event is armed
                if sesc is not None and len(groups) == 1 and len(list(group)) == 1:
                    if self.raw(sesc, "storyboardElementType") in ("event", "action"):
                        return "after_event", (self.raw(sesc, "storyboardElementRef"),
                                               self.value(cond, "delay", units.TIME, 0.0),
                                               self.raw(sesc, "state"), cond)
                time = cond.find("ByValueCondition/SimulationTimeCondition")
                if time is not None and (time.get("rule") or "").startswith("greater") and len(groups) == 1:
                    value = self.value(time, "value")
                    at_s = max(at_s or 0.0, value) if value > 0 else at_s
                    continue
                formula = self.condition(cond, who)
                if formula is None:
                    return None
                conj.append(formula)
                holds.append((self.value(cond, "delay", units.TIME, 0.0), cond))
                edges.append((EDGES.get(cond.get("conditionEdge", "none")), cond))
            if conj:
                alternatives.append(_all(conj))
        fields = {}
        if at_s is not None:
            fields["at_s"] = E.Num(value=at_s)
        if alternatives:
            fields["condition"] = _any(alternatives)
        # One condition (the usual case): its edge and delay exactly. Several: the step's edge
        # and delay act on the whole formula, exact when all conditions agree.
        if any(e for e, _ in edges):
            if len(edges) > 1:
                self.approx(edges[0][1], "several conditions with edges: the edge applies to the whole start "
                                         "condition")
            fields["edge"] = next(e for e, _ in edges if e)
        delays = sorted({d for d, _ in holds})
        if delays and delays[-1] > 0:
            delay = delays[-1]
            if len(delays) > 1:
                self.approx(holds[0][1], f"conditions with different delays: the step fires {delay:g} s after its "
                                         "whole start condition")
            if (self.sidecar or {}).get("holds", {}).get(event) == delay:  # an exported `when C for D`
                fields["hold_s"] = E.Num(value=delay)
                fields.pop("edge", None)
            else:
                fields["delay_s"] = E.Num(value=delay)
        return "now", fields

    def condition(self, cond, who: str):
        """One <Condition> as a formula over signals, or None after a diagnostic."""
        value_cond = _only_child(cond.find("ByValueCondition")) if cond.find("ByValueCondition") is not None else None
        if value_cond is not None:
            if value_cond.tag == "ParameterCondition":
                ref = self.raw(value_cond, "parameterRef")
                exact = (self.sidecar or {}).get("conditions", {}).get(ref)
                if exact:
                    return EXPR.validate_python(exact["formula"])
            if value_cond.tag in ("TrafficSignalCondition", "TrafficSignalControllerCondition"):
                return self.light_condition(value_cond)
            self.skip(value_cond, f"<{value_cond.tag}> is not translated")
            return None
        by_entity = cond.find("ByEntityCondition")
        entity = _only_child(_child(by_entity, "EntityCondition"))
        if by_entity is None or entity is None:
            self.error(cond, "a condition needs a ByValueCondition or a ByEntityCondition")
            return None
        triggering = by_entity.find("TriggeringEntities")
        rule = triggering.get("triggeringEntitiesRule", "any") if triggering is not None else "any"
        actors = [self.actor_name(r) for r in by_entity.iterfind("TriggeringEntities/EntityRef")]
        if not actors or any(a is None for a in actors):
            return None
        parts = [self.entity_condition(entity, a) for a in actors]
        if any(p is None for p in parts):
            return None
        return _all(parts) if rule == "all" else _any(parts)

    def light_condition(self, c):
        """`light(C) == S`: a signal's state (its controller's) or a controller's phase."""
        if c.tag == "TrafficSignalCondition":
            sid = self.raw(c, "name")
            ctl = self.light_controller(sid, c)
            state = self.signal_state(sid, self.raw(c, "state"), c) if ctl else None
        else:
            raw, phase = self.raw(c, "trafficSignalControllerRef"), self.raw(c, "phase")
            ctl = self.ctl_names.get(raw, raw)
            if ctl not in self.light_ctls or self.light_ctls[ctl].get("solo"):
                self.error(c, f"no traffic signal controller '{raw}'")
                return None
            state = self.light_ctls[ctl]["phases"].get(phase)
            if state is None:
                self.error(c, f"controller '{ctl}' has no phase '{phase}'",
                           f"phases: {', '.join(self.light_ctls[ctl]['phases'])}")
        if state is None:
            return None
        return E.Binary(op="==", left=E.Signal(name=f"light({ctl})"), right=E.Num(value=LIGHT_STATES[state]))

    def entity_condition(self, c, a: str):
        op = RULE_OPS.get(c.get("rule", ""), ">")
        sig = lambda fn, *args: E.Signal(name=f"{fn}({','.join(args)})")  # noqa: E731 - canonical names
        if c.tag == "TraveledDistanceCondition":
            # `s(A)` grows in A's driving direction, from its station in its own frame
            # (the road's station along +s; on a path, from the path's entry end).
            travelled = self.number(c, "value", units.LENGTH)
            return E.Binary(op=">=", left=sig("s", a), right=_plus(self.start_station(a), travelled))
        if c.tag == "SpeedCondition":
            return E.Binary(op=op, left=sig("speed", a), right=self.number(c, "value", units.SPEED))
        if c.tag == "CollisionCondition":
            # The twin ends a run at its first collision; as a condition, an overlap of the
            # actor's box with any other (exact with one other actor or a type that is every one).
            others = [n for n in self.actors if n != a]
            target = c.find("EntityRef")
            if target is not None and len(others) > 1:
                self.approx(c, "a collision with one entity: a collision of the actor with any other")
            elif c.find("ByType") is not None and len(others) > 1:
                self.approx(c, "a collision with a type of object: a collision of the actor with any other")
            return E.Binary(op="<=", left=sig("clearance", a), right=E.Num(value=0.0))
        if c.tag == "RelativeSpeedCondition":
            b = self.actor_name(c)
            if b is None:
                return None
            if c.get("direction") not in (None, "longitudinal"):
                self.skip(c, f"a {c.get('direction')} relative speed is not translated (longitudinal is)")
                return None
            if c.get("direction") == "longitudinal":
                self.approx(c, "a longitudinal relative speed: the difference of the speeds (the same when they "
                               "drive the same way)")
            return E.Binary(op=op, left=sig("rel_speed", a, b), right=self.number(c, "value", units.SPEED))
        if c.tag == "AccelerationCondition":
            return E.Binary(op=op, left=sig("accel", a), right=self.number(c, "value", units.ACCELERATION))
        if c.tag in ("RelativeDistanceCondition", "TimeToCollisionCondition", "TimeHeadwayCondition"):
            target = c.find("TimeToCollisionConditionTarget/EntityRef") if c.tag == "TimeToCollisionCondition" else c
            if target is None:
                self.skip(c, "time to collision with a position is not translated (with an entity it is)")
                return None
            b = self.actor_name(target)
            if b is None:
                return None
            # freespace="false": distances between the entities' reference points (the
            # importer places an actor's centre there), i.e. the bumper gap plus half of
            # both lengths along the road.
            free = (c.get("freespace") or "false").lower() == "true"
            half = 0.0 if free else 0.5 * (self.size(a)[0] + self.size(b)[0])
            if c.tag == "TimeToCollisionCondition":
                # As esmini evaluates it: the longitudinal distance along the road over the
                # speed difference; undefined (the condition false, whatever its rule) when
                # they do not close in.
                value = self.number(c, "value", units.TIME)
                closing = E.Binary(op="-", left=sig("speed", a), right=sig("speed", b))
                lhs = _plus(sig("gap", a, b), E.Num(value=half)) if half else sig("gap", a, b)
                return _all([E.Binary(op=">", left=closing, right=E.Num(value=0.0)),
                             E.Binary(op=op, left=lhs, right=E.Binary(op="*", left=value, right=closing))])
            if c.tag == "TimeHeadwayCondition":
                headway = E.Binary(op="*", left=self.number(c, "value", units.TIME), right=sig("speed", a))
                return E.Binary(op=op, left=sig("gap", a, b),
                                right=_plus(headway, E.Num(value=-half)) if half else headway)
            kind = c.get("relativeDistanceType", "cartesianDistance")
            free = (c.get("freespace") or "false").lower() == "true"
            value = self.number(c, "value", units.LENGTH)
            if kind == "longitudinal":
                half = 0.0 if free else 0.5 * (self.size(a)[0] + self.size(b)[0])
                ahead = _ahead(self.placed, a, b, self.param_values())
                left = sig("gap", a, b) if ahead else sig("gap", b, a)
                return E.Binary(op=op, left=left, right=_plus(value, E.Num(value=-half)) if half else value)
            if kind in ("cartesianDistance", "euclidianDistance"):
                if free:
                    self.approx(c, "a free-space distance: the centre distance less half of both lengths")
                    half = 0.5 * (self.size(a)[0] + self.size(b)[0])
                    return E.Binary(op=op, left=sig("distance", a, b), right=_plus(value, E.Num(value=half)))
                return E.Binary(op=op, left=sig("distance", a, b), right=value)
            self.skip(c, f"a {kind} relative distance is not translated (longitudinal and cartesian are)")
            return None
        if c.tag == "ReachPositionCondition" or c.tag == "DistanceCondition":
            # The Euclidean distance of the entity's reference point to the position's point
            # (esmini: `dist < tolerance`; DistanceCondition: its rule against `value`).
            pos = c.find("Position")
            if pos is None:
                self.error(c, f"<{c.tag}> needs a <Position>")
                return None
            point = self.world_point(pos, a)
            if point is None:
                return None
            x, y, _ = point
            if c.tag == "ReachPositionCondition":
                radius, op = self.number(c, "tolerance", units.LENGTH), "<"
            else:
                radius = self.number(c, "value", units.LENGTH)
                if (c.get("freespace") or "false").lower() == "true":
                    self.skip(c, "a free-space distance to a position is not translated (between reference points "
                                 "it is)")
                    return None
                kind = c.get("relativeDistanceType", "cartesianDistance")
                lane_pos = _only_child(pos)
                if kind == "longitudinal" and lane_pos is not None and \
                        lane_pos.tag in ("LanePosition", "RoadPosition") and self.along_s(a) and \
                        self.placed[a][0] == self.road(self.raw(lane_pos, "roadId"), lane_pos):
                    # along the road both are on: the stations' difference
                    gap = E.Call(fn="abs", args=[E.Binary(op="-", left=sig("s", a),
                                                          right=self.number(lane_pos, "s", units.LENGTH))])
                    return E.Binary(op=op, left=gap, right=radius)
                if kind not in ("cartesianDistance", "euclidianDistance"):
                    self.skip(c, f"a {kind} distance to a position is not translated (cartesian is, and "
                                 "longitudinal along the actor's own road)")
                    return None
            dx = E.Binary(op="-", left=sig("x", a), right=E.Num(value=round(x, 9)))
            dy = E.Binary(op="-", left=sig("y", a), right=E.Num(value=round(y, 9)))
            square = E.Binary(op="+", left=E.Binary(op="*", left=dx, right=dx), right=E.Binary(op="*", left=dy, right=dy))
            return E.Binary(op=op, left=square, right=E.Binary(op="*", left=radius, right=radius))
        self.skip(c, f"<{c.tag}> is not translated",
                  "translated: traveled distance, speed, acceleration, relative distance, time headway, TTC, "
                  "reach position")
        return None

    def start_station(self, who: str):
        """The actor's first `s(A)` as an expression: its road station where it drives a road
        along +s; on a path (a lane driven against s, a reversed lane, a route), the
        distance from the path's entry end, as the runtime measures it."""
        return self.frame_station(who, self.placed[who][2])

    def frame_station(self, who: str, s):
        """A station `s` of the actor's first road as `s(A)` measures it (see start_station)."""
        road_name, lane, s_start, _ = self.placed[who]
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        info = self.actors[who]
        reverse = bool(info.get("against_s")) and info["vehicle"] != "obstacle"
        routed = info.get("route_el") is not None or info.get("route_from_position") is not None
        if lane == 0 or (not routed and self.along_s(who)):
            return s
        try:
            _, legs = resolve_route(self.network, [road_id], lane,
                                    float(eval_param_expr(s_start, self.param_values())), reverse=reverse)
        except (RouteError, ValueError, ArithmeticError):
            return s
        first = legs[0]
        entry = E.Num(value=round(float(first.s_from), 9))
        return E.Binary(op="-", left=s, right=entry) if first.direction > 0 else \
            E.Binary(op="-", left=entry, right=s)

    def driving_way(self, who: str) -> int:
        """+1 if the actor starts driving towards +s of its road, -1 against."""
        road_name, lane, _, _ = self.placed[who]
        if lane == 0:
            return 1
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        reverse = bool(self.actors[who].get("against_s")) and self.actors[who]["vehicle"] != "obstacle"
        return self.network.road(road_id).travel_direction(lane) * (-1 if reverse else 1)

    def along_s(self, who: str) -> bool:
        """Whether the actor drives towards +s (its lane's OpenDRIVE direction)."""
        road_name, lane = self.placed[who][0], self.placed[who][1]
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        way = -1 if self.actors[who].get("against_s") and self.actors[who]["vehicle"] != "obstacle" else 1
        return lane == 0 or self.network.road(road_id).travel_direction(lane) * way > 0

    def size(self, who: str) -> tuple[float, float]:
        info = self.actors[who]
        kind = VEHICLES[info["vehicle"]]
        return info["length_m"] or kind.length_m, info["width_m"] or kind.width_m

    # -- sequences: an event started by another event of the same actor

    def link_sequences(self) -> None:
        grouped: dict[str, list] = {}
        for name, who, (ref, delay, state, cond), clause in self.pending:
            if ref in self.anchors and self.anchors[ref][0] == who:
                grouped.setdefault(ref, []).append(TriggerPlan(clause=clause, after_s=E.Num(value=delay)
                                                               if delay else None))
                self.events[name] = (who, "now", {}, clause)
        for ref, steps in grouped.items():
            who, fields = self.anchors[ref]
            self.actors[who]["triggers"].append(TriggerPlan(group=GroupPlan(mode="parallel", steps=steps), **fields))
        other_actor = []  # after the sequences are built: a named step never gets lifted
        for name, who, (ref, delay, state, cond), clause in self.pending:
            if ref in grouped:
                continue
            first = self.events.get(ref)
            if first is not None and first[0] != who and state in STATE_SIGNAL:
                other_actor.append((name, who, (ref, delay, state, cond), clause, first))
                continue
            if first is None or first[0] != who:
                self.skip(cond, f"event '{name}' starts on '{ref}', "
                                + ("not an event of the same actor" if first else "which is not translated"),
                          "a step after another actor's event has no form in the language")
                continue
            after = delay
            if state in ("endTransition", "completeState"):
                after += _duration(first[3])
            info = self.actors[who]
            prev_clause = first[3]
            # Lift the first step into a sequence that also starts this one.
            for i, tr in enumerate(info["triggers"]):
                if tr.clause == prev_clause or (tr.group and tr.group.steps and tr.group.steps[0].clause ==
                                                prev_clause):
                    steps = list(tr.group.steps) if tr.group else [TriggerPlan(clause=prev_clause)]
                    steps.append(TriggerPlan(clause=clause, after_s=E.Num(value=after) if after else None))
                    # The step's start (its hold and name too) now starts the sequence.
                    info["triggers"][i] = tr.model_copy(update={"clause": None,
                                                                "group": GroupPlan(mode="sequence", steps=steps)})
                    break
            else:
                if prev_clause in info["behaviors"]:
                    info["triggers"].append(TriggerPlan(after_s=E.Num(value=after), clause=clause)
                                            if after else TriggerPlan(at_s=E.Num(value=0.0), clause=clause))
                else:
                    self.skip(cond, f"event '{name}' follows '{ref}' in a way the language cannot say")
                    continue
            self.events[name] = (who, "now", {}, clause)
        for name, who, (ref, delay, state, cond), clause, first in other_actor:
            if not self.after_other_actor(who, ref, delay, state, cond, clause, first):
                self.skip(cond, f"event '{name}' starts on '{ref}' of '{first[0]}', which is not a step",
                          "only an event that starts a step can be named for `started`/`ended`")
                continue
            self.events[name] = (who, "now", {}, clause)

    def after_other_actor(self, who, ref, delay, state, cond, clause, first) -> bool:
        """An event on another actor's event: that event's step gets a name and this one
        starts on its state (`when ended(lead.brake) delayed D then ...`)."""
        state_of = self.event_state(ref, state)
        if state_of is None:
            return False
        self.actors[who]["triggers"].append(TriggerPlan(condition=state_of, clause=clause,
                                                        delay_s=E.Num(value=delay) if delay else None))
        return True

    def event_state(self, ref: str, state: str):
        """`started(A.x) > 0` / `ended(A.x) > 0` for an event, naming its step (an event
        at time 0 becomes a named step `after 0 s`); None if the event has no step."""
        first = self.events.get(ref)
        if first is None or state not in STATE_SIGNAL:
            return None
        other = first[0]
        info = self.actors[other]
        taken = {tr.label for a in self.actors.values() for t in a["triggers"] for tr in _steps_of(t) if tr.label}
        if not any(tr.clause == first[3] for t in info["triggers"] for tr in _steps_of(t)):
            j = next((j for j, c in enumerate(info["behaviors"]) if c == first[3]), None)
            if j is None:
                return None
            clause = info["behaviors"].pop(j)
            info["triggers"].append(TriggerPlan(after_s=E.Num(value=0.0), clause=clause))
        found: list[str] = []
        info["triggers"] = [_labelled(t, first[3], _safe_name(ref, taken), found) for t in info["triggers"]]
        label = found[0]
        # A step state is a formula: the signal above 0, as the compiler lowers it.
        return E.Binary(op=">", left=E.Signal(name=f"{STATE_SIGNAL[state]}({other}.{label})"), right=E.Num(value=0.0))

    def end_trigger(self, trigger) -> None:
        """The storyboard's stop trigger beyond its simulation time (the run's duration):
        `end when ...`. Element states of events and maneuvers, and entity conditions."""
        if trigger is None:
            return
        alternatives, delays, edges, at_s = [], [], [], None
        groups = list(trigger.iterfind("ConditionGroup"))
        for group in groups:
            conj, timed = [], None
            for cond in group.iterfind("Condition"):
                if (cond.get("name") or "").startswith("criteria_"):
                    continue  # CARLA ScenarioRunner's pass criteria: oracles (pass_criteria)
                time = cond.find("ByValueCondition/SimulationTimeCondition")
                if time is not None and (time.get("rule") or "").startswith("greater"):
                    timed = self.value(time, "value")  # alone: the duration
                    continue
                sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
                if sesc is not None:
                    kind, ref, state = (self.raw(sesc, "storyboardElementType"), self.raw(sesc, "storyboardElementRef"),
                                        self.raw(sesc, "state"))
                    events = [ref] if kind in ("event", "action") else self.maneuvers.get(ref) \
                        if kind == "maneuver" and state in ("endTransition", "completeState") else None
                    parts = [self.event_state(e, state) for e in events] if events else [None]
                    if not parts or any(p is None for p in parts):
                        self.skip(cond, f"a stop trigger on the {kind} '{ref}' ({state}) is not translated",
                                  "events and maneuvers that translate to steps are")
                        return
                    conj.append(_all(parts))
                else:
                    formula = self.condition(cond, "ego")
                    if formula is None:
                        return
                    conj.append(formula)
                delays.append((self.value(cond, "delay", units.TIME, 0.0), cond))
                edges.append((EDGES.get(cond.get("conditionEdge", "none")), cond))
            if conj and timed is not None:
                if len([g for g in groups if list(g)]) > 1:
                    self.skip(group, "a stop condition group that mixes the simulation time with other conditions, "
                                     "beside other groups, is not translated")
                    return
                at_s = timed  # `end at T when C`
            if conj:
                alternatives.append(_all(conj))
        if not alternatives:
            return
        fields = {"condition": _any(alternatives)}
        if at_s is not None and at_s > 0:
            fields["at_s"] = E.Num(value=at_s)
        if any(e for e, _ in edges):
            if len(edges) > 1:
                self.approx(edges[0][1], "several stop conditions with edges: the edge applies to the whole condition")
            fields["edge"] = next(e for e, _ in edges if e)
        if delays and max(d for d, _ in delays) > 0:
            if len({d for d, _ in delays}) > 1:
                self.approx(delays[0][1], "stop conditions with different delays: the run ends the longest after")
            fields["delay_s"] = E.Num(value=max(d for d, _ in delays))
        self.end = TriggerPlan(**fields)

    def speed_limit_at(self, road_name: str, s) -> float | None:
        """The map's speed limit [m/s] where an actor is placed (None: the map gives none)."""
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        odr = self.network.road(road_id)
        try:
            return odr.speed_limit(min(max(float(eval_param_expr(s, self.param_values())), 0.0), odr.length))
        except (KeyError, ValueError, ArithmeticError):
            return None

    # -- pass criteria

    def pass_criteria(self, ego: ActorPlan) -> list[OraclePlan]:
        """CARLA ScenarioRunner's test criteria as oracles on the ego: the stop triggers'
        conditions named `criteria_<Test>` (a ParameterCondition whose value, if any, is the
        test's argument), as ScenarioRunner reads them. Those the language cannot judge are
        W0801; none at all: [] (the caller's default)."""
        found: dict[str, OraclePlan] = {}
        for cond in self.doc.iterfind("Storyboard//StopTrigger//Condition"):
            name = cond.get("name") or ""
            if not name.startswith("criteria_"):
                continue
            test = name[len("criteria_"):]
            param = cond.find("ByValueCondition/ParameterCondition")
            raw = param.get("value", "") if param is not None else ""
            try:
                arg = float(self.resolve(raw)) if raw.strip() else None
            except (KeyError, SyntaxError, ValueError, ArithmeticError):
                arg = None
            oracle = self.criterion(test, arg, ego, cond)
            if oracle is not None:
                found.setdefault(oracle.name, oracle)
        self.criteria = bool(found)
        return list(found.values())

    def criterion(self, test: str, arg: float | None, ego: ActorPlan, cond) -> OraclePlan | None:
        always, signal = (lambda f: E.Temporal(op="always", lo_s=0.0, hi_s=None, arg=f)), E.Signal
        if test == "CollisionTest":
            return OraclePlan(name="no_collision", formula=NO_CLAUSES["collision"]("ego", None), text="no collision")
        if test == "RunningRedLightTest":
            return OraclePlan(name="no_red_light", formula=NO_CLAUSES["red_light"]("ego", None), text="no red_light")
        if test == "KeepLaneTest":
            road_id = next(i for i, r in self.roads.items() if r.name == ego.road)
            odr = self.network.road(road_id)
            s0 = min(max(float(eval_param_expr(ego.s, self.param_values())), 0.0), odr.length)
            formula = stay_in_lane_formula(float(odr.lane_width(int(ego.lane.value), s0)), ego.width_m)
            if formula is None:
                self.skip(cond, f"criteria_{test}: the ego is wider than its lane: not translated")
                return None
            self.approx(cond, f"criteria_{test} is translated as `stay in lane` (the body inside the lane); "
                              "ScenarioRunner fails it on any lane marking crossed")
            return OraclePlan(name="keep_lane", formula=formula, text="stay in lane")
        if test == "DrivenDistanceTest" and arg is not None and arg > 0:
            return OraclePlan(name="driven_distance", formula=E.Temporal(
                op="eventually", lo_s=0.0, hi_s=None,
                arg=E.Binary(op=">=", left=signal(name="travelled(ego)"), right=E.Num(value=arg))),
                text=f"eventually travelled(ego) >= {arg:g} m")
        if test == "MaxVelocityTest" and arg is not None and arg > 0:
            return OraclePlan(name="max_velocity", formula=always(E.Binary(
                op="<=", left=signal(name="speed(ego)"), right=E.Num(value=arg))),
                text=f"always speed(ego) <= {arg:g} m/s")
        why = {"RunningStopTest": "the twin has no stop signs",
               "WrongLaneTest": "no signal gives the driving direction of the lane the ego is in",
               "OnSidewalkTest": "no signal gives the type of the lane the ego is in"}.get(test, "no such oracle")
        self.skip(cond, f"criteria_{test} is not translated: {why}",
                  "translated: CollisionTest, RunningRedLightTest, KeepLaneTest, DrivenDistanceTest, MaxVelocityTest")
        return None

    # -- the plan

    def plan(self, header, duration: float) -> ScenarioPlan:
        sc = self.sidecar or {}
        actors = []
        for who, info in self.actors.items():
            road, lane, s, offset = self.placed[who]
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
                got = self.route(_first(info.get("route_el"), info.get("route_from_position")), who, lane, s)
                if got is not None:
                    fields["route"], fields["s"] = got
            if extra.get("yaw") is not None:
                fields["yaw"] = E.Num(value=float(extra["yaw"]))
            if extra.get("reverse") is not None:
                fields["reverse"] = bool(extra["reverse"])
            elif info.get("against_s") and info["vehicle"] != "obstacle" and not fields.get("route"):
                fields["reverse"] = True  # it faces against its lane: it drives that way
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
                    fields["stack"] = ClausePlan(keyword="stack", name="bev", settings={"cruise_speed": fields["speed"]})
                elif not sc:
                    limit = self.speed_limit_at(road, s)
                    if limit is not None:
                        # A standing ego is someone else's to drive (CARLA's examples leave it to an
                        # external agent): the stack drives at the map's limit, not its own default.
                        fields["stack"] = ClausePlan(keyword="stack", name="bev",
                                                     settings={"cruise_speed": E.Num(value=round(limit, 6))})
                        self.approx(info["el"], f"the ego starts standing: the stack cruises at its road's speed "
                                                f"limit, {limit * 3.6:.4g} km/h")
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
                        self.approx(info["el"], f"the ego has no route in the file: it drives on through junctions, "
                                                f"straight where it can, else to the kerb side, else the other way (roads "
                                                f"{' -> '.join(route)})")
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
        name = sc.get("scenario") or _safe_name(self.path.stem, set())
        if self.light_ctls and not sc and agents:
            self.approx(_first(self.signals_el, self.doc), "OpenSCENARIO's actors follow their actions, not the "
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
                            environment=self.environment, controllers=controllers, light_steps=self.light_steps,
                            end=self.end)
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
                raise _Stop
            params.append(ParamPlan(name=p, dimension=units.dim_name(dim), default=float(values[p])))
        return plan.model_copy(update={"params": params})


def _sidecar_problem(data: dict) -> str:
    """What is wrong with a side file's contents ("" if nothing): each part is validated
    before the import uses it, so a damaged file is a diagnostic, not an exception."""
    try:
        for key, kind in (("actors", dict), ("behaviors", dict), ("conditions", dict), ("groups", dict),
                          ("faults", list), ("oracles", list), ("params", dict), ("param_dims", dict),
                          ("group_events", list), ("holds", dict)):
            if not isinstance(data.get(key, kind()), kind):
                return f"'{key}' is not a {kind.__name__}"
        for key in ("scenario", "description", "source_file", "run_id"):
            if not isinstance(data.get(key, ""), str):
                return f"'{key}' is not a string"
        for info in data.get("actors", {}).values():
            if info.get("vehicle") not in VEHICLES:
                return f"unknown vehicle {info.get('vehicle')!r}"
            for key in ("length_m", "width_m", "height_m", "mass_kg", "wheelbase_m", "goal_s", "mu", "yaw"):
                if info.get(key) is not None:
                    float(info[key])
            if not isinstance(info.get("reverse", False), bool):
                return "an actor's 'reverse' is not true or false"
            if (info.get("mass_kg") is None) != (info.get("wheelbase_m") is None):
                return "an actor's 'mass_kg' and 'wheelbase_m' come together"
            route = info.get("route", [])
            if not isinstance(route, list) or not all(type(r) in (str, int) for r in route):
                return "an actor's 'route' is not a list of road ids"
            if info.get("stack"):
                ClausePlan.model_validate(info["stack"])
            for x in info.get("sensors", []):
                ClausePlan.model_validate(x)
        for b in data.get("behaviors", {}).values():
            ClausePlan.model_validate(b["clause"])
        for c in data.get("conditions", {}).values():
            EXPR.validate_python(c["formula"])
        for steps in data.get("groups", {}).values():
            for step in steps:
                TriggerPlan.model_validate(step)
        lights = data.get("lights", {})
        if not isinstance(lights, dict):
            return "'lights' is not a dict"
        for c in lights.get("controllers", {}).values():
            for key in ("green_s", "yellow_s", "red_s", "offset_s"):
                float(c[key])
        for clause in lights.get("steps", {}).values():
            step = ClausePlan.model_validate(clause)
            if step.keyword != "light" or step.settings.get("state") not in (*LIGHT_STATES, LIGHT_PROGRAM):
                return "a light step that is not a `light` clause with a state"
        for f in data.get("faults", []):
            ConcreteFault.model_validate(f)
        for o in data.get("oracles", []):
            OraclePlan.model_validate(o)
        for k, v in data.get("params", {}).items():
            float(v)
        for d in data.get("param_dims", {}).values():
            units.dim_from_name(d)
        float(data.get("step_s", 0.01))
        # int(1.5) is 1: a seed must be a whole number as written (run_seed may be absent: null).
        for key, value in (("seed", data.get("seed", 0)), ("run_seed", data.get("run_seed"))):
            if type(value) is not int and not (key == "run_seed" and value is None):
                return f"'{key}' is {value!r}, not an integer"
    except (ValueError, TypeError, KeyError, AttributeError) as exc:  # pydantic's ValidationError is a ValueError
        return (str(exc).splitlines() or [type(exc).__name__])[0][:200]
    return ""


def _bspline_basis(knots: list[float], order: int, n: int, u: float) -> list[float]:
    """The n B-spline basis functions of `order` (degree order - 1) at `u` (Cox-de Boor)."""
    basis = [1.0 if knots[i] <= u < knots[i + 1] else 0.0 for i in range(len(knots) - 1)]
    for k in range(2, order + 1):
        nxt = []
        for i in range(len(knots) - k):
            left = right = 0.0
            if knots[i + k - 1] > knots[i]:
                left = (u - knots[i]) / (knots[i + k - 1] - knots[i]) * basis[i]
            if knots[i + k] > knots[i + 1]:
                right = (knots[i + k] - u) / (knots[i + k] - knots[i + 1]) * basis[i + 1]
            nxt.append(left + right)
        basis = nxt
    return basis[:n]


def _setting(value):
    if isinstance(value, str):
        return value
    if isinstance(value, dict):  # a live expression (`speed 2 * speed(ego) - 1 m/s`), as the export writes it
        return EXPR.validate_python(value)
    if isinstance(value, list):
        return [E.Num(value=float(v)) for v in value]
    return E.Num(value=float(value))


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def _steps_of(step: TriggerPlan):
    """A step and every step of its groups, depth first."""
    yield step
    for sub in step.group.steps if step.group is not None else ():
        yield from _steps_of(sub)


def _labelled(step: TriggerPlan, clause: ClausePlan, label: str, found: list) -> TriggerPlan:
    """The step tree with the first step that starts `clause` named (its name if it has
    one, else `label`); the name used is appended to `found`."""
    if not found and step.clause == clause:
        found.append(step.label or label)
        return step if step.label else step.model_copy(update={"label": label})
    if step.group is None:
        return step
    steps = [_labelled(s, clause, label, found) for s in step.group.steps]
    return step.model_copy(update={"group": step.group.model_copy(update={"steps": steps})})


def _speed_into_trajectory(clauses: list[ClausePlan]) -> list[ClausePlan]:
    """A speed action and an untimed trajectory in one event: OpenSCENARIO moves the entity
    along the trajectory at the speed the speed action sets; the language's trajectory holds
    the longitudinal channel itself, so it takes that speed (and its rate limits)."""
    cruise = next((c for c in clauses if c.name == "cruise" and c.settings.get("speed") is not None
                   and not any(isinstance(n, E.Signal) for n in E.walk(c.settings["speed"]))), None)
    traj = next((c for c in clauses if c.name == "trajectory" and "times" not in c.settings
                 and "speed" not in c.settings), None)
    if cruise is None or traj is None:
        return clauses
    extra = {k: cruise.settings[k] for k in ("accel", "decel") if k in cruise.settings}
    merged = traj.model_copy(update={"settings": {**traj.settings, "speed": cruise.settings["speed"], **extra}})
    return [merged if c is traj else c for c in clauses if c is not cruise]


def _plus(a, b):
    if isinstance(a, E.Num) and isinstance(b, E.Num):
        return E.Num(value=a.value + b.value)
    if isinstance(b, E.Num) and b.value == 0.0:
        return a
    return E.Binary(op="+", left=a, right=b)


def _all(parts):
    out = parts[0]
    for p in parts[1:]:
        out = E.Binary(op="and", left=out, right=p)
    return out


def _any(parts):
    out = parts[0]
    for p in parts[1:]:
        out = E.Binary(op="or", left=out, right=p)
    return out


def _ahead(placed, a, b, params) -> bool:
    """Whether b starts ahead of a (so `gap(a, b)` is the positive one)."""
    return eval_param_expr(placed[b][2], params) >= eval_param_expr(placed[a][2], params)


def _duration(clause: ClausePlan) -> float:
    """How long a behaviour runs [s], where its settings say: `duration`, or a timed
    trajectory's last vertex time; else 0."""
    d = clause.settings.get("duration")
    times = clause.settings.get("times")
    if not isinstance(d, E.Num) and isinstance(times, list) and times and isinstance(times[-1], E.Num):
        d = times[-1]
    return float(d.value) if isinstance(d, E.Num) else 0.0


# ---------------------------------------------------------------- entry point

# Documents other than a scenario, translated elsewhere: (recognise(path) -> bool,
# translate(path, root, maps, lenient=, ego=) -> Imported). openscenario/distribution.py
# registers the ParameterValueDistribution (a logical scenario: a distribution and the
# template it names); the interop package loads it.
DOCUMENT_KINDS: list[tuple] = []
# The reading machinery that module reuses for a distribution and its template.
Importer, Translate, Stop, arith = _Importer, _Translate, _Stop, _arith


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
    imp = (translator or _Translate)(path, Path(root) if root is not None else path.parent,
                                     tuple(Path(m) for m in maps), lenient=lenient, ego=ego)
    if not path.resolve().is_relative_to(imp.root):
        imp.sink.error("E0402", f"{path} is outside the root directory", None)
        return Imported(None, None, imp.sink.items, imp.sources)
    try:
        plan = imp.run()
    except _Stop:
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
