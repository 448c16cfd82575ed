"""Diagnostics are data; renderers are separate (rustc / ruff style).

A `Diagnostic` carries a stable code, a severity, a message, a primary `Span` and notes.
`render_text` prints it with the source line and a caret; `render_json` for tools.
The catalogue of codes lives in `CODES` and is mirrored in docs/diagnostics.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import Enum


class Severity(str, Enum):
    ERROR = "error"
    WARNING = "warning"


@dataclass(frozen=True, slots=True)
class Span:
    """A source range. Lines and columns are 1-based; `end_col` is exclusive."""

    file: str
    line: int
    col: int
    end_line: int
    end_col: int

    @staticmethod
    def point(file: str, line: int, col: int) -> Span:
        return Span(file, line, col, line, col + 1)

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"


@dataclass(frozen=True, slots=True)
class Diagnostic:
    code: str
    severity: Severity
    message: str
    span: Span | None
    notes: tuple[str, ...] = ()
    label: str = ""  # short text printed next to the caret

    @property
    def is_error(self) -> bool:
        return self.severity is Severity.ERROR

    def to_dict(self) -> dict:
        span = self.span
        return {
            "code": self.code,
            "severity": self.severity.value,
            "message": self.message,
            "file": span.file if span else None,
            "line": span.line if span else None,
            "col": span.col if span else None,
            "end_line": span.end_line if span else None,
            "end_col": span.end_col if span else None,
            "label": self.label,
            "notes": list(self.notes),
        }


# Stable codes. Never renumber; retire codes instead. docs/diagnostics.md lists them.
CODES: dict[str, str] = {
    "E0001": "syntax error",
    "E0002": "unexpected end of file",
    "E0003": "unreadable source (encoding, binary data or size)",
    "E0004": "nesting too deep",
    "E0005": "unknown block keyword",
    "E0101": "unknown name",
    "E0102": "duplicate definition",
    "E0103": "missing required element",
    "E0104": "unknown setting",
    "E0105": "missing required setting",
    "E0106": "unknown kind (not in the registry)",
    "E0107": "invalid reference target",
    "E0108": "cyclic definition",
    "E0109": "fault needs sites the remote stack does not declare",
    "E0201": "dimension mismatch",
    "E0202": "unknown unit",
    "E0203": "expected a boolean formula",
    "E0204": "invalid value",
    "E0301": "value out of range",
    "E0302": "time outside the scenario duration",
    "E0303": "empty or inverted interval",
    "E0401": "include or import failed",
    "E0402": "path escapes the scenario directory",
    "E0403": "road file error",
    "E0404": "no such route in the road network",
    "E0405": "no such traffic signal or controller",
    "E0501": "unsatisfiable constraints",
    "E0601": "feature needs a package that is not installed",
    "E0701": "beyond a documented limit (input size or sweep cost)",
    "E0801": "unreadable OpenSCENARIO file (malformed XML, a DTD or entity, too large)",
    "E0802": "invalid OpenSCENARIO content (missing element, attribute or reference)",
    "E0803": "OpenSCENARIO element not translated (`addtc import --lenient` imports the rest without it)",
    "E0900": "internal compiler error",
    "W0001": "unused parameter",
    "W0002": "setting has no effect",
    "W0003": "sensor unlike the one the stack is made for",
    "W0004": "agent under every ray of the ego's lidar",
    "W0801": "OpenSCENARIO element not translated",
    "W0802": "OpenSCENARIO value approximated or defaulted",
    "W0803": "OpenSCENARIO file read with CARLA ScenarioRunner's conventions",
}


@dataclass
class DiagnosticSink:
    """Collects diagnostics so a pass can report every error, not only the first."""

    items: list[Diagnostic] = field(default_factory=list)

    def error(self, code: str, message: str, span: Span | None, *notes: str,
              label: str = "") -> None:
        self.items.append(Diagnostic(code, Severity.ERROR, message, span, notes, label))

    def warning(self, code: str, message: str, span: Span | None, *notes: str,
                label: str = "") -> None:
        self.items.append(Diagnostic(code, Severity.WARNING, message, span, notes, label))

    @property
    def has_errors(self) -> bool:
        return any(d.is_error for d in self.items)


def sorted_diagnostics(diags: list[Diagnostic]) -> list[Diagnostic]:
    def key(d: Diagnostic):
        s = d.span
        return (s.file if s else "", s.line if s else 0, s.col if s else 0, d.code)
    return sorted(diags, key=key)


# Notes that tell the user what to write are rendered as `= help:` (as rustc does).
_HELP_PREFIXES = ("did you mean", "write ", "add ", "use ", "give ", "put ", "narrow ", "shorten ",
                  "widen ", "split ", "configure ", "order ", "save ", "e.g.", "a label goes", "a block's")


def render_text(diags: list[Diagnostic], sources: dict[str, str]) -> str:
    """rustc-style text: `error[E0201]: message`, location, source line and caret."""
    out: list[str] = []
    line_cache: dict[str, list[str]] = {}
    for d in sorted_diagnostics(diags):
        out.append(f"{d.severity.value}[{d.code}]: {d.message}")
        span = d.span
        if span is not None:
            out.append(f"  --> {span}")
            if span.file not in line_cache:
                text = sources.get(span.file)
                line_cache[span.file] = text.splitlines() if text is not None else []
            lines = line_cache[span.file]
            if 1 <= span.line <= len(lines):
                src = lines[span.line - 1].expandtabs(1)
                gutter = str(span.line)
                pad = " " * len(gutter)
                width = (span.end_col - span.col) if span.end_line == span.line else len(src) - span.col + 1
                width = max(1, min(width, max(1, len(src) - span.col + 1)))
                caret = " " * (span.col - 1) + "^" * width
                out.append(f"{pad} |")
                out.append(f"{gutter} | {src}")
                out.append(f"{pad} | {caret}" + (f" {d.label}" if d.label else ""))
        for note in d.notes:
            kind = "help" if note.startswith(_HELP_PREFIXES) else "note"
            out.append(f"  = {kind}: {note}")
        out.append("")
    errors = sum(d.is_error for d in diags)
    warnings = len(diags) - errors
    if diags:
        out.append(f"{errors} error(s), {warnings} warning(s)")
    return "\n".join(out)


def render_json(diags: list[Diagnostic]) -> str:
    return json.dumps([d.to_dict() for d in sorted_diagnostics(diags)], indent=2)
