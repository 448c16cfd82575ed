"""The reading machinery of an import: diagnostics (with the element's line), files read under the
root directory, entity names. `distribution.py` reuses it for a distribution file."""

from pathlib import Path

from addt_dsl import units
from addt_dsl.confine import Refused, confine
from addt_dsl.diagnostics import DiagnosticSink, Span
from addt_dsl.interop.openscenario.carla import CarlaFrame
from addt_dsl.interop.openscenario.params import Parameters
from addt_dsl.interop.openscenario.xml import MAX_XML_BYTES
from addt_dsl.plan import ClausePlan, RoadPlan, TriggerPlan
from addt_dsl.xmlread import XmlReadError, read_xml


class Importer(Parameters, CarlaFrame):
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
        self.events: dict = {}  # event (and action) name -> storyboard.EventStep
        self.instant: dict = {}  # event (and action) name -> storyboard.InstantEvent: no step, only a start
        self.maneuvers: dict[str, list[str]] = {}  # maneuver name -> its events' names
        self.act_events: dict[str, list[str]] = {}  # act name -> its events' names (those with steps)
        self.event_order: list[str] = []  # events that became steps, in file order
        self.skipping: list = []  # (event, the events of its maneuver that may run): priority skip, at the end
        self.end: TriggerPlan | None = None  # the storyboard's stop trigger beyond its time
        self.act_stop = None  # CARLA: a story's only act's stop trigger (a formula), `end when` it
        self.act_stop_s: float | None = None  # ... and the time it ends the run at
        self.relative_paths: list = []  # (clause, shape element, entity): a trajectory relative to an entity
        self.pending: list = []  # storyboard.PendingEvent: events started by another event, linked at the end
        self.anchors: dict = {}  # no-op events that start a group: name -> storyboard.Anchor
        self.stand_still: list = []  # (duration [s], element) of each StandStillCondition read
        self.placed: dict = {}  # actor -> positions.Placement
        self.environment: list[ClausePlan] = []  # weather and light from an EnvironmentAction
        self.environment_steps: list[TriggerPlan] = []  # ... and their changes in events
        # Scenario variables: parameters (and 1.2 variables) that a SetAction in an event sets,
        # with their first values, and the steps that set them.
        self.variables: dict[str, float] = {}
        self.variable_steps: list[TriggerPlan] = []
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
        try:
            doc = read_xml(text)
        except XmlReadError as exc:
            if exc.kind == "unsafe":
                self.sink.error("E0801", f"{display}: refused: {exc.exception} (DTDs and entities are not read)",
                                Span.point(display, 1, 1))
            else:
                self.sink.error("E0801", f"{display}: not well-formed XML: {exc.detail}",
                                Span.point(display, exc.line, 1))
            return None
        root = doc.root
        self.lines.update(doc.lines)
        return root

    def actor_name(self, el, attr: str = "entityRef") -> str | None:
        name = self.raw(el, attr)
        if name not in self.renames:
            self.error(el, f"no entity '{name}'", f"entities: {', '.join(self.renames) or 'none'}")
            return None
        return self.renames[name]
