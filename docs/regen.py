"""Regenerate the command outputs printed in the docs.

    python docs/regen.py [DOC.md ...]          rewrite the outputs in place
    python docs/regen.py --check [DOC.md ...]  exit 1 if a doc differs from what its commands print now

A fenced block is regenerated when its info string carries `regen`:

- ```` ```console regen ````: `$ COMMAND` lines, each followed by what COMMAND prints, as a
  terminal shows it (stdout and stderr, unbuffered);
- any other block with `regen="COMMAND"` holds what COMMAND prints (e.g. the counterexample
  a previous command wrote);
- between `<!-- regen="COMMAND" -->` and `<!-- /regen -->` (outside a fence): Markdown that
  COMMAND prints, shown as Markdown (a table generated from a registry).

The commands of one doc run in doc order, with bash, in one fresh directory holding a
copy of `examples/` and the doc's blocks marked `file="NAME"` written as `NAME`; this
checkout's `addtc` and `pytest` come first. The directory's path is printed as `.`,
and trailing blanks are dropped.
`--check` compares up to wall times and versions (`MASKS`), so it passes on any machine.

Only the standard library: the tests import this module for `doc_blocks` and `MASKS`.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC_FILES = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]

_FENCE = re.compile(r"^(?P<indent> *)```(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)
_HEADING = re.compile(r"^#+ (.*)$", re.M)
_SECTION = re.compile(r'^<!-- regen="(?P<command>[^"]+)" -->\n(?P<body>.*?)^<!-- /regen -->$', re.M | re.S)

# What differs between two honest runs of the same commands: wall times, tool versions, widths
# of pytest's rules around a wall time.
MASKS = [
    (re.compile(r"(runs in|rounds,) \d+(\.\d+)? s"), r"\1 <wall> s"),
    (re.compile(r"(accepted) +\d+\.\d+ s$", re.M), r"\1 <wall> s"),
    (re.compile(r"^=+ (.*) in \d+\.\d+s( \([^)]*\))? =+$", re.M), r"== \1 in <wall> =="),
    (re.compile(r"^(platform|plugins:) .*$", re.M), r"\1 <versions>"),
]


@dataclass(frozen=True)
class Block:
    """One fenced block of a doc: its language, the attributes of its info string
    (`expect="3 passed"` → {"expect": "3 passed"}, a bare word → ""), its text."""

    doc: str  # relative to the repository: "docs/language.md"
    line: int  # 1-based line of the opening fence
    lang: str
    attrs: dict[str, str]
    text: str
    heading: str  # the nearest heading above it
    span: tuple[int, int] = field(repr=False)  # the body's character range in the doc
    indent: str = field(default="", repr=False)

    @property
    def name(self) -> str:
        """A stable id for test ids and messages: doc:line and the scenario's name."""
        m = re.search(r"^scenario (\w+)", self.text, re.M)
        return f"{self.doc}:{self.line}" + (f"-{m.group(1)}" if m else "")


def doc_blocks(path: Path) -> list[Block]:
    text = path.read_text(encoding="utf-8")
    headings = [(m.start(), m.group(1)) for m in _HEADING.finditer(text)]
    out = []
    for m in _FENCE.finditer(text):
        words = shlex.split(m.group("info"))
        lang = words[0] if words else ""
        attrs = dict((w.split("=", 1) + [""])[:2] for w in words[1:])
        indent = m.group("indent")
        body = "".join(ln[len(indent):] if ln.startswith(indent) else ln
                       for ln in m.group("body").splitlines(keepends=True))
        heading = next((h for pos, h in reversed(headings) if pos < m.start()), "")
        out.append(Block(str(path.relative_to(ROOT)), text.count("\n", 0, m.start()) + 1, lang, attrs,
                         body, heading, m.span("body"), indent))
    return out


def mask(text: str) -> str:
    for pattern, repl in MASKS:
        text = pattern.sub(repl, text)
    return text


def _run(command: str, cwd: Path, env: dict) -> str:
    proc = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    if "Traceback (most recent call last)" in proc.stdout or proc.returncode > 2:
        raise RuntimeError(f"`{command}` crashed (exit {proc.returncode}):\n{proc.stdout[-3000:]}")
    out = proc.stdout.replace(str(cwd) + "/", "").replace(str(cwd), ".")
    out = "".join(line.rstrip() + "\n" for line in out.splitlines())
    return _XML_RULE.sub(lambda m: _rule(m.group(1)), out)


_XML_RULE = re.compile(r"^-+ (generated xml file: .*?) -+$", re.M)


def _rule(msg: str, width: int = 80) -> str:
    """pytest's `---- msg ----` rule, re-centred after the directory's path was shortened."""
    n = max((width - len(msg) - 2) // 2, 1)
    line = f"{'-' * n} {msg} {'-' * n}"
    return line + "-" if len(line) + 1 <= width else line


def regenerate(path: Path) -> str:
    """The doc's text with every `regen` block replaced by what its commands print now."""
    text = path.read_text(encoding="utf-8")
    blocks = doc_blocks(path)
    todo = [b for b in blocks if "regen" in b.attrs]
    sections = list(_SECTION.finditer(text))
    if not todo and not sections:
        return text
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
               PYTHONPATH=str(ROOT), COLUMNS="80", PYTHONHASHSEED="0", PYTHONUNBUFFERED="1")
    # The outputs shown are a developer's terminal: on GitHub the pytest plugin adds `::error`
    # lines, and pytest stops cutting its short summary to the width when `CI` or `BUILD_NUMBER` is set.
    for name in ("GITHUB_ACTIONS", "CI", "BUILD_NUMBER"):
        env.pop(name, None)
    new = {}
    with tempfile.TemporaryDirectory(prefix="addt-docs-") as tmp:
        work = Path(tmp)
        shutil.copytree(ROOT / "examples", work / "examples")
        for block in blocks:
            if "file" in block.attrs:
                (work / block.attrs["file"]).parent.mkdir(parents=True, exist_ok=True)
                (work / block.attrs["file"]).write_text(block.text, encoding="utf-8")
        for block in todo:
            if block.lang == "console":
                commands = [ln[2:] for ln in block.text.splitlines() if ln.startswith("$ ")]
                assert commands, f"{block.doc}:{block.line}: a console regen block needs `$ COMMAND` lines"
                body = "".join(f"$ {c}\n{_run(c, work, env)}" for c in commands)
            else:
                body = _run(block.attrs["regen"], work, env)
            new[block.span] = "".join(block.indent + ln if ln.strip() else ln
                                      for ln in body.splitlines(keepends=True))
        for m in sections:
            new[m.span("body")] = _run(m.group("command"), work, env)
    for (start, end), body in sorted(new.items(), reverse=True):
        text = text[:start] + body + text[end:]
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("docs", nargs="*", type=Path, help="docs to regenerate (default: every doc)")
    parser.add_argument("--check", action="store_true", help="only report docs that are out of date")
    args = parser.parse_args(argv)
    stale = []
    for path in [p.resolve() for p in args.docs] or DOC_FILES:
        old = path.read_text(encoding="utf-8")
        new = regenerate(path)
        if mask(new) != mask(old):
            stale.append(path.relative_to(ROOT))
            if not args.check:
                path.write_text(new, encoding="utf-8")
    verb = "out of date" if args.check else "rewritten"
    for rel in stale:
        print(f"{rel}: {verb}")
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
