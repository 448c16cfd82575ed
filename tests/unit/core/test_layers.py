"""Layer boundaries (docs/architecture.md, "Rules that keep it simple").

Every module of the package is imported, and every import statement in it (module level
and inside functions) and every load by a literal name (`importlib.import_module("...")`,
`__import__`) is checked against the layer order:

    app (cli, console, suite, studies, pytest_plugin, search.commands, interop.commands)
      > search > reporting > stack > runtime > core (units, expr, diagnostics, registry, fingerprint,
        vehicles, plan, sweep, distributions, confine, errors, extras, limits, cost, lru, xmlread, atomic, road/,
        specs/)
      printer > compiler > core;   search > printer
      interop (OpenSCENARIO export/import) > printer, compiler, runtime;   search > interop
    the compiler and the runtime never import each other (nor the stack).

Besides, the compiler never loads pybullet/torch and the runtime never loads the parser
(fresh interpreters check `sys.modules`), no module imports another's private names, and
no modules import each other (at any level).
"""

from __future__ import annotations

import ast
import functools
import importlib.util
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.conftest import EXAMPLES

PACKAGE = Path(__file__).resolve().parents[3] / "addt_dsl"

CORE = {"addt_dsl", "addt_dsl.units", "addt_dsl.expr", "addt_dsl.diagnostics", "addt_dsl.registry",
        "addt_dsl.fingerprint", "addt_dsl.vehicles", "addt_dsl.plan", "addt_dsl.sweep", "addt_dsl.distributions",
        "addt_dsl.confine",
        "addt_dsl.errors", "addt_dsl.extras", "addt_dsl.limits", "addt_dsl.cost", "addt_dsl.stats",
        "addt_dsl.lru", "addt_dsl.xmlread", "addt_dsl.atomic", "addt_dsl.kernel"}
APP = {"addt_dsl.cli", "addt_dsl.console", "addt_dsl.suite", "addt_dsl.studies", "addt_dsl.pytest_plugin",
       "addt_dsl.search.commands", "addt_dsl.interop.commands"}
# layer -> the layers its modules may import (besides their own)
ALLOWED = {
    "core": set(),
    "compiler": {"core"},
    "runtime": {"core"},
    "stack": {"core", "runtime"},
    "printer": {"core", "compiler"},
    "reporting": {"core", "runtime", "stack"},
    "interop": {"core", "compiler", "runtime", "printer"},
    "search": {"core", "runtime", "stack", "reporting", "printer", "interop"},
    "app": {"core", "compiler", "runtime", "stack", "reporting", "printer", "search", "interop"},
}
# Edges that break the order: none (add one only with the reason beside it).
KNOWN: set[tuple[str, str]] = set()


def layer(module: str) -> str:
    if module in APP:
        return "app"
    if module in CORE or module.split(".")[:2] in (["addt_dsl", "road"], ["addt_dsl", "specs"]):
        return "core"
    if module == "addt_dsl.printer" or module.startswith("addt_dsl.printer."):
        return "printer"
    top = module.split(".")[1]
    if top in ("compiler", "runtime", "stack", "reporting", "search", "interop"):
        return top
    raise AssertionError(f"{module} is in no layer: add it to test_layers.py and docs/architecture.md")


def modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = modules()


@functools.cache
def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), str(path))


def _dynamic_load(node: ast.AST) -> ast.expr | None:
    """The module argument of `importlib.import_module(...)`, `import_module(...)` or
    `__import__(...)`, None for any other node."""
    if not isinstance(node, ast.Call) or not node.args:
        return None
    fn = node.func
    name = fn.attr if isinstance(fn, ast.Attribute) else fn.id if isinstance(fn, ast.Name) else None
    return node.args[0] if name in ("import_module", "__import__") else None


def imports(module: str, path: Path):
    """(imported module, names, line) of every import statement of a module, and of every
    load by name (`importlib.import_module("addt_dsl.x")`, `__import__`) with a literal name."""
    is_package = path.name == "__init__.py"
    for node in ast.walk(_tree(path)):
        target = _dynamic_load(node)
        if isinstance(target, ast.Constant) and isinstance(target.value, str):
            yield target.value, (), node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, (), node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = module.split(".")[: len(module.split(".")) - node.level + is_package]
                base = ".".join(parent + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                # `from addt_dsl import expr` is an edge to addt_dsl.expr.
                yield (sub, (), node.lineno) if sub in MODULES else (base, (alias.name,), node.lineno)


def edges():
    for module, path in MODULES.items():
        for target, names, line in imports(module, path):
            if target.split(".")[0] == "addt_dsl":
                yield module, target, names, f"{path.relative_to(PACKAGE.parent)}:{line}"


def _imports_torch(module: str) -> bool:
    """Modules of the `learned` extra import torch at module level."""
    return any(target.split(".")[0] == "torch" for target, _, _ in imports(module, MODULES[module]))


def test_every_module_is_in_a_layer_and_imports():
    # Without torch (the core install) the `learned` extra's modules cannot import: every
    # other module must, and none of them may import torch at module level.
    has_torch = importlib.util.find_spec("torch") is not None
    importable = [m for m in MODULES if has_torch or not _imports_torch(m)]
    code = "import importlib\n" + "".join(f"importlib.import_module({m!r})\n" for m in importable)
    subprocess.run([sys.executable, "-c", code], check=True)
    for m in MODULES:
        layer(m)


def test_every_import_points_down():
    bad = []
    for module, target, _, where in edges():
        if target not in MODULES:
            bad.append(f"{where}: {module} imports {target}, which is no module")
            continue
        a, b = layer(module), layer(target)
        if a != b and b not in ALLOWED[a] and (module, ".".join(target.split(".")[:3])) not in KNOWN:
            bad.append(f"{where}: {module} ({a}) imports {target} ({b})")
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def test_known_exceptions_still_exist():
    found = {(m, ".".join(t.split(".")[:3])) for m, t, _, _ in edges()}
    assert KNOWN <= found, f"fixed, delete from KNOWN: {KNOWN - found}"


# Import circles allowed (a function-level import or a load by name does not hide one):
KNOWN_CYCLES: list[set[str]] = [
    # `stack external protocol osi`: bridge loads its OSI client (a subclass of ExternalStack,
    # needing the `osi` extra) by name, only when a scenario asks for it.
    {"addt_dsl.stack.bridge", "addt_dsl.stack.osi_stack", "addt_dsl.stack.osi_transport"},
]


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_circles():
    graph: dict[str, set[str]] = {}
    for module, target, _, _ in edges():
        if target in MODULES and target != module:
            graph.setdefault(module, set()).add(target)
    assert sorted(map(sorted, cycles(graph))) == sorted(map(sorted, KNOWN_CYCLES))
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]


# Private names imported across modules: none.
KNOWN_PRIVATE: set[tuple[str, str, str]] = set()


def test_no_private_names_across_modules():
    private = {(m, t, n) for m, t, names, _ in edges() for n in names if n.startswith("_") and t != m}
    assert private == KNOWN_PRIVATE


# Loads by a computed name, which the checks above cannot follow: each module that makes one,
# and what it loads.
DYNAMIC_LOADS = {
    "addt_dsl.registry": "a table's spec module (core) and, from `implementation()`, its implementation modules",
    "addt_dsl.search.samplers": "the sampler implementations of its own table (search)",
}
# Layers that may ask the registry for an implementation (which imports the runtime or the stack).
IMPLEMENTATION_CALLERS = {"runtime", "stack", "reporting", "interop", "search", "app"}


def test_loads_by_computed_name_are_the_known_ones():
    found = set()
    for module, path in MODULES.items():
        for node in ast.walk(_tree(path)):
            target = _dynamic_load(node)
            if target is not None and not (isinstance(target, ast.Constant) and isinstance(target.value, str)):
                found.add(module)
    assert found == set(DYNAMIC_LOADS)


def test_only_the_runtime_side_asks_for_implementations():
    # The compiler, the printer and core read specs: `Registry.implementation` would load the runtime.
    bad = []
    for module, path in MODULES.items():
        for node in ast.walk(_tree(path)):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "implementation" and layer(module) not in IMPLEMENTATION_CALLERS
                    and module != "addt_dsl.registry"):
                bad.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: {module} ({layer(module)})")
    assert not bad, "implementations asked for outside the runtime side:\n" + "\n".join(bad)


def test_the_registry_loads_specs_from_core_and_implementations_from_the_runtime_side():
    from addt_dsl import registry

    for table in (registry.BEHAVIORS, registry.SENSORS, registry.FAULTS, registry.STACKS, registry.SIGNALS,
                  registry.GEOMETRIES, registry.ENVIRONMENTS):
        assert layer(table._specs_module) == "core", table.what
        assert all(layer(m) in ("runtime", "stack") for m in table._implementation_modules), table.what


def test_the_checker_sees_function_level_imports(tmp_path):
    # A sanity check of `imports` itself: a function-level import is an edge too.
    path = tmp_path / "m.py"
    path.write_text("def f():\n    from addt_dsl.search import shrink\n    import addt_dsl.cli\n"
                    "    importlib.import_module('addt_dsl.stack.bev')\n    __import__('addt_dsl.printer')\n")
    assert sorted(t for t, _, _ in imports("addt_dsl.runtime.x", path)) == [
        "addt_dsl.cli", "addt_dsl.printer", "addt_dsl.search.shrink", "addt_dsl.stack.bev"]
    assert importlib.util.find_spec("addt_dsl.search.shrink") is not None


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                         check=True)
    return out.stdout.strip()


def test_compiler_imports_neither_pybullet_nor_torch():
    loaded = _run(f"""
        import sys
        from addt_dsl.compiler import compile_file
        assert compile_file({str(EXAMPLES / 'overtake.addt')!r}).ok
        from addt_dsl.registry import FAULTS, SENSORS, STACKS, BEHAVIORS
        FAULTS.names(); SENSORS.names(); STACKS.names(); BEHAVIORS.names()
        print(sorted(m for m in ("pybullet", "torch", "cv2") if m in sys.modules))
    """)
    assert loaded == "[]"


@pytest.mark.parametrize("entry", ["from addt_dsl.runtime.execute import execute",
                                   "from addt_dsl.runtime.executor import run_sweep"])
def test_runtime_never_imports_the_parser(tmp_path, entry):
    from addt_dsl.compiler import compile_file
    from addt_dsl.sweep import expand

    spec = expand(compile_file(EXAMPLES / "overtake.addt").plan).specs[0]
    spec = spec.model_copy(update={"plan": spec.plan.model_copy(update={"duration_s": 2.0})})
    path = tmp_path / "spec.json"
    path.write_text(spec.model_dump_json())
    loaded = _run(f"""
        import sys
        from addt_dsl.plan import RunSpec
        {entry}
        from addt_dsl.runtime.execute import execute
        execute(RunSpec.model_validate_json(open({str(path)!r}).read()))
        print(sorted(m for m in sys.modules if m == "lark" or m.startswith("addt_dsl.compiler")))
    """)
    assert loaded == "[]"
