"""Layer boundaries: the compiler never loads pybullet/torch; the runtime never loads the parser."""

import subprocess
import sys
import textwrap

from tests.conftest import EXAMPLES


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


def test_runtime_never_imports_the_parser(tmp_path):
    from addt_dsl.compiler import compile_file
    from addt_dsl.sweep import expand

    spec = expand(compile_file(EXAMPLES / "overtake.addt").plan).specs[0]
    spec = spec.model_copy(update={"plan": spec.plan.model_copy(update={"duration_s": 2.0})})
    path = tmp_path / "spec.json"
    path.write_text(spec.model_dump_json())
    loaded = _run(f"""
        import sys
        from addt_dsl.plan import RunSpec
        from addt_dsl.runtime.execute import execute
        execute(RunSpec.model_validate_json(open({str(path)!r}).read()))
        print(sorted(m for m in sys.modules if m == "lark" or m.startswith("addt_dsl.compiler")))
    """)
    assert loaded == "[]"
