"""The declared interfaces (`runtime/views.py`) are the only way into the twin: behaviours,
sensors, perception, stacks and faults use only their members, never the run's state
(`.run.` of a context), and every implementation offers every member."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from addt_dsl.runtime import views

PKG = Path(__file__).resolve().parents[3] / "addt_dsl"
STACK_SERVERS = ("bridge_server.py", "osi_server.py")  # they implement a context, they do not consume one
# Modules that host code inside the twin: none may read the run's state.
HOSTED = sorted([*(PKG / "stack").glob("*.py"), PKG / "runtime" / "behaviors.py", PKG / "runtime" / "sensors.py",
                 *(PKG / "runtime" / "faults").glob("*.py")])


def members(protocol) -> set[str]:
    """A Protocol's declared attributes and methods, its Protocol bases' included."""
    out: set[str] = set()
    for cls in protocol.__mro__:
        if cls in (object, views.Protocol) or cls.__module__ != views.__name__:
            continue
        out |= set(getattr(cls, "__annotations__", {}))
        out |= {k for k, v in vars(cls).items() if callable(v) and not k.startswith("_")}
    return out


def uses(tree: ast.AST, names: tuple[str, ...]) -> list[tuple[str, int]]:
    """(attribute, line) of every `N.attr` or `self.N.attr` for N in `names`."""
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        base = node.value
        if isinstance(base, ast.Name) and base.id in names or \
                isinstance(base, ast.Attribute) and base.attr in names and \
                isinstance(base.value, ast.Name) and base.value.id == "self":
            out.append((node.attr, node.lineno))
    return out


def reads_run(tree: ast.AST) -> list[int]:
    """Lines that read `.run` as a value (`ctx.run`, `x.run.y`); calls of a `run` method are fine."""
    called = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    return [n.lineno for n in ast.walk(tree)
            if isinstance(n, ast.Attribute) and n.attr == "run" and id(n) not in called]


def parse(path: Path) -> ast.AST:
    return ast.parse(path.read_text(), str(path))


@pytest.mark.parametrize("path", HOSTED, ids=lambda p: p.name)
def test_no_hosted_module_reads_the_runs_state(path):
    assert reads_run(parse(path)) == [], f"{path.name} reads `.run` of a context (use runtime.views)"


CONSUMERS = [
    ("runtime/behaviors.py", ("world",), views.BehaviorWorld),
    ("runtime/behaviors.py", ("agent",), views.AgentView),
    ("runtime/sensors.py", ("world",), views.SensorWorld),
    ("stack/nodes.py", ("frame",), views.SensorFrame),
    ("stack/bev.py", ("ctx",), views.StackContext),
    ("stack/bridge.py", ("ctx",), views.HostContext),
    ("stack/osi_stack.py", ("ctx",), views.HostContext),
    # every fault module that reads a sensor or a frame
    *((f"runtime/faults/{p.name}", (name,), protocol)
      for name, protocol in (("sensor", views.FaultSensor), ("frame", views.SensorFrame))
      for p in sorted((PKG / "runtime" / "faults").glob("*.py")) if uses(parse(p), (name,))),
    ("runtime/faults/base.py", ("stack",), views.FaultStack),
]


@pytest.mark.parametrize("rel, names, protocol", CONSUMERS, ids=[f"{c[0]}-{c[2].__name__}" for c in CONSUMERS])
def test_consumers_use_only_declared_members(rel, names, protocol):
    found = uses(parse(PKG / rel), names)
    assert found, f"{rel}: no use of {names} found (the check would pass vacuously)"
    undeclared = sorted({f"{attr} (line {line})" for attr, line in found if attr not in members(protocol)})
    assert undeclared == [], f"{rel} uses members {protocol.__name__} does not declare: {undeclared}"


def offered(path: Path, class_name: str) -> set[str]:
    """Methods, class attributes (properties made by a call) and `self.x = ...` attributes of
    a class (and of its in-module bases)."""
    tree = parse(path)
    classes = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef)}
    out: set[str] = set()
    todo = [class_name]
    while todo:
        cls = classes.get(todo.pop())
        if cls is None:
            continue
        todo += [b.id for b in cls.bases if isinstance(b, ast.Name)]
        out |= {t.id for node in cls.body if isinstance(node, ast.Assign) for t in node.targets
                if isinstance(t, ast.Name)}
        for node in ast.walk(cls):
            if isinstance(node, ast.FunctionDef):
                out.add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                    for t in ast.walk(target):
                        if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id == "self":
                            out.add(t.attr)
    return out


IMPLEMENTATIONS = [
    ("runtime/state.py", "Context", views.HostContext),
    ("runtime/state.py", "RunState", views.BehaviorWorld),
    ("runtime/state.py", "RunState", views.SensorWorld),
    ("stack/bridge_server.py", "RemoteContext", views.StackContext),
    ("runtime/agent_arrays.py", "AgentState", views.AgentView),
]


@pytest.mark.parametrize("rel, cls, protocol", IMPLEMENTATIONS,
                         ids=[f"{c[1]}-{c[2].__name__}" for c in IMPLEMENTATIONS])
def test_implementations_offer_every_member(rel, cls, protocol):
    missing = members(protocol) - offered(PKG / rel, cls)
    assert missing == set(), f"{cls} lacks {sorted(missing)} of {protocol.__name__}"


def test_the_checks_see_a_violation():
    """The AST checks flag what they are meant to (the tests above cannot pass vacuously)."""
    tree = ast.parse("def f(self, ctx):\n    self.ctx.run.ego_s\n    ctx.run.events\n    self.perception.run(1)\n")
    assert reads_run(tree) == [2, 3]
    assert ("ego_s", 2) not in uses(tree, ("ctx",)) and ("run", 3) in uses(tree, ("ctx",))
    assert "run" not in members(views.StackContext)
