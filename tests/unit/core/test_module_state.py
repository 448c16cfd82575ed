"""No module-level mutable cache outside `LruCache`: a dict, list or set at module (or class)
level that a function fills grows for the life of the process (a sweep worker, the pytest
plugin). The ones left are a registry filled at import, a lock table and a table evicted with an
LruCache, each named here."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[3] / "addt_dsl"
MUTATORS = {"update", "setdefault", "append", "add", "extend", "insert", "__setitem__"}
CONTAINERS = {"dict", "list", "set", "OrderedDict", "defaultdict", "deque"}
ALLOWED = {
    "distributions.py:DISTRIBUTIONS",  # the registry of distributions (filled by `register` at import)
    "runtime/store.py:_LOCKS",  # locks held now (an entry leaves when its lock is released)
    "compiler/xodr_check.py:_INFOS",  # per cached map; dropped by _MAPS's on_evict, so bounded by it
    "kernel.py:_bound",  # the compiled kernels: one entry per module-level kernel, at its first compile
}


def _mutable(value) -> bool:
    if isinstance(value, (ast.Dict, ast.List, ast.Set, ast.DictComp, ast.ListComp, ast.SetComp)):
        return True
    func = value.func if isinstance(value, ast.Call) else None
    return getattr(func, "id", getattr(func, "attr", None)) in CONTAINERS


def _filled(tree: ast.Module, name: str) -> bool:
    for node in ast.walk(tree):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for inner in ast.walk(node):
            target = None
            if isinstance(inner, ast.Subscript) and isinstance(inner.ctx, ast.Store):
                target = inner.value
            elif isinstance(inner, ast.Call) and isinstance(inner.func, ast.Attribute) and inner.func.attr in MUTATORS:
                target = inner.func.value
            if target is not None and getattr(target, "id", getattr(target, "attr", None)) == name:
                return True
    return False


def test_module_level_containers_that_functions_fill_are_registries_only():
    found = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        bodies = [tree.body] + [n.body for n in tree.body if isinstance(n, ast.ClassDef)]
        for body in bodies:
            for node in body:
                if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None and _mutable(node.value):
                    targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                    for t in targets:
                        if isinstance(t, ast.Name) and _filled(tree, t.id):
                            found.add(f"{path.relative_to(PACKAGE).as_posix()}:{t.id}")
    assert found == ALLOWED


def test_golden_fingerprints_in_memory_are_bounded(tmp_path, monkeypatch):
    from addt_dsl.runtime import outcome

    monkeypatch.setattr(outcome, "GOLDEN_MEMORY_SIZE", 3)
    cache = outcome.GoldenCache(tmp_path / "golden.sqlite")
    for k in range(10):
        cache.put(f"k{k}", outcome.Fingerprint({}, "ok", True))
    assert len(cache.memory) == 3
    assert cache.get("k0") == outcome.Fingerprint({}, "ok", True)  # read back from the store
