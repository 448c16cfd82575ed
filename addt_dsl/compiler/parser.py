"""Source text → AST. Syntax errors become diagnostics, never tracebacks.

lark (LALR, contextual lexer) calls the `_Builder` methods as it reduces, so the frozen
dataclasses of `compiler.ast` are built directly, with spans computed from the tokens
(no intermediate parse tree, no position propagation: about half the parse time).

Error recovery is panic mode, as in yacc's `error` token: after a syntax error the
parser skips tokens to the end of the statement (a newline or a closing brace outside
any brace opened on the way), then pops parser states until that token fits, feeds it
and goes on. One run therefore reports every broken statement, not just the first.
Two repairs avoid cascades: a block's `{` on the line after its header is read as if on
the header's line, and a definition (`param`, `agent`, `expect {`) inside another block
closes that block with a virtual `}` (its `}` is missing) and is read again.
"""

from __future__ import annotations

import functools
import re
import threading
from pathlib import Path

from lark import Lark, Token, Tree
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from addt_dsl.compiler import ast
from addt_dsl.diagnostics import DiagnosticSink, Span

GRAMMAR_PATH = Path(__file__).resolve().parent.parent / "grammar" / "addt.lark"
MAX_SOURCE_BYTES = 1_000_000  # real scenarios are a few kB; lark parses ~200 kB/s
MAX_NESTING = 64
MAX_SYNTAX_ERRORS = 25
MAX_EXPR_DEPTH = 200  # operators chained or nested in one expression


@functools.lru_cache(maxsize=1)
def _parser() -> tuple[Lark, _Builder]:
    """The parser, built once per process (a check of many files reuses it), with the
    AST builders called as it reduces: no parse tree is built or walked."""
    builder = _Builder()
    lark = Lark.open(str(GRAMMAR_PATH), parser="lalr", lexer="contextual",
                     transformer=_Callbacks(builder.callbacks()), maybe_placeholders=False)
    return lark, builder


def grammar() -> Lark:
    return _parser()[0]


class _Callbacks:
    """What lark's `transformer=` option reads: one attribute per rule name."""

    def __init__(self, table: dict):
        self.__dict__.update(table)

    def __default__(self, data, children, meta):
        if data.startswith("_"):  # an inlined rule: lark splices its children into the parent
            return Tree(data, children)
        raise RuntimeError(f"no AST builder for grammar rule '{data}'")


_PARSE_LOCK = threading.Lock()  # the builder holds the current file name


@functools.lru_cache(maxsize=1)
def _terminal_words() -> dict[str, str]:
    """Readable names of the grammar's terminals, for "expected ..." notes."""
    words = {"NAME": "a name", "NUMBER": "a number", "STRING": "a string", "UNIT": "a unit",
             "_NL": "end of line", "$END": "end of file", "COMP": "a comparison",
             "MUL_OP": "'*' or '/'"}
    for term in grammar().terminals:
        if term.name not in words and term.pattern.type == "str":
            words[term.name] = f"'{term.pattern.value}'"
    return words


def _expected_words(expected) -> list[str]:
    table = _terminal_words()
    return sorted({table[name] for name in expected if name in table})


# Words that start a definition; seen where they cannot stand, a '}' is usually missing.
_DEFINITION_WORDS = {"agent", "ego", "param", "road", "faults", "expect", "sweep", "assume", "keep",
                     "include", "scenario"}

# Characters from other languages, with what to write instead.
_CHAR_HINTS = {
    "&": "write `and` for a conjunction",
    "|": "write `or` for a disjunction",
    "!": "write `not` for a negation, `!=` for 'not equal'",
    ";": "statements end at a newline; no ';' is needed",
    "'": "strings are written in double quotes: \"...\"",
    "\u2018": "use straight double quotes \"...\"", "\u2019": "use straight double quotes \"...\"",
    "\u201c": "use straight double quotes \"...\"", "\u201d": "use straight double quotes \"...\"",
    "$": "parameters are referred to by their bare name: `gap`, not `$gap`",
    "@": "there are no decorators; write `hard` or `warn` before an oracle",
    "?": "there is no conditional expression; use `implies` in formulas",
    "`": "code quotes are not part of the language",
    "=": "settings are written `key value`, without '='",
}


_FOREIGN_WORDS = ("if", "else", "elif", "while", "for", "def", "return", "lambda", "function", "var", "let")
# Words people write after a number believing they are units, with the unit they meant.
UNIT_TYPOS = {
    "kph": "km/h", "kmh": "km/h", "kmph": "km/h", "mps": "m/s", "sec": "s", "secs": "s", "second": "s",
    "seconds": "s", "msec": "ms", "millis": "ms", "meter": "m", "meters": "m", "metre": "m", "metres": "m",
    "mins": "min", "minute": "min", "minutes": "min", "hz": "Hz", "HZ": "Hz", "hertz": "Hz", "degree": "deg",
    "degrees": "deg", "radian": "rad", "radians": "rad", "percent": "%", "pct": "%", "M": "m", "S": "s",
    "KM": "km", "Km": "km", "kilometers": "km", "kilograms": "kg",
}
_UNIT_TYPO_RE = re.compile(r"(\d[\d.eE+-]*)\s*(" + "|".join(sorted(UNIT_TYPOS, key=len, reverse=True)) + r")\b")


def _curated_hint(token: Token, expected: set[str], text: str) -> list[str]:
    """Messages for mistakes people actually make, from the token, what the parser
    expected and the line around it."""
    value, kind = str(token), token.type
    lines = text.splitlines()
    line_no = getattr(token, "line", None) or 1
    line = lines[line_no - 1] if 0 < line_no <= len(lines) else ""
    words = line.split()
    first = words[0].rstrip(":") if words else ""
    before = text[:token.start_pos].rstrip(" \t") if token.start_pos is not None else ""
    hints = []
    if value == ":" and "NAME" not in expected:
        hints.append("a label goes first, before the formula: `name: always ...`")
    if kind == "NAME" and "UNIT" in expected:
        hints.append(f"'{value}' is not a known unit; units are m, km, cm, mm, m/s, km/h, mph, s, ms, "
                     "min, Hz, deg, rad, deg/s, rad/s, %, m/s^2, m/s^3, g, 1/m, kg")
    typo = _UNIT_TYPO_RE.search(line)
    if typo:
        number, word = typo.groups()
        hints.append(f"'{word}' is not a unit: write `{number} {UNIT_TYPOS[word]}`")
    if value == "=" and first == "param":
        hints.append("a parameter is declared `param NAME = VALUE`")
    elif value == "=":
        hints.append("settings are written `key value`, without '='; use '==' to compare")
    if kind == "_NL" and "LBRACE" in expected:
        hints.append("a block's '{' must be on the same line as its header")
    if kind in ("NUMBER", "NAME") and "COMMA" in expected and before[-1:].isalnum() | (before[-1:] in "%)"):
        hints.append("is a ',' missing between the list items?")
    if first in _DEFINITION_WORDS and _depth_at(text, line_no) > 1:
        hints.append(f"`{first} ...` is a definition, which cannot stand inside this block; "
                     "is a '}' missing above?")
    if first in _FOREIGN_WORDS or value in _FOREIGN_WORDS:
        word = first if first in _FOREIGN_WORDS else value
        hints.append(f"'{word}' is not part of the language; a behaviour starts with "
                     "`when <condition> then ...`, `at <time> ...` or `after <time> ...`")
    if "THEN" in expected and first == "when":
        hints.append("write `when <condition> then <behaviour>`")
    return hints


_DEFINITION_LINE = re.compile(r"\s*(agent\s+\w+\s+\w+|ego\s+(car|truck)\b|param\s+\w+\s*=|road\s+\w+\s+(\{|import)|"
                              r"(faults|expect|sweep)\s*\{|(assume|keep)\s|include\s+\")")
_DEFINITION_OPENER = re.compile(r"\s*(road|agent|ego|faults|expect|sweep)\b")


def _line_offset(text: str, line_no: int) -> int:
    pos = 0
    for _ in range(line_no - 1):
        pos = text.find("\n", pos) + 1
        if pos == 0:
            return len(text)
    return pos


def _open_braces(text: str, line_no: int) -> list[tuple[int, int]]:
    """(line, col) of every '{' still open where `line_no` starts, outermost first
    (strings and comments skipped)."""
    stack: list[tuple[int, int]] = []
    line, col, in_string, in_comment, escaped = 1, 0, False, False, False
    for ch in text:
        col += 1
        if ch == "\n":
            line, col = line + 1, 0
            in_string = in_comment = False
            if line >= line_no:
                break
            continue
        if in_comment:
            continue
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
            continue
        if ch == "#":
            in_comment = True
        elif ch == '"':
            in_string = True
        elif ch == "{":
            stack.append((line, col))
        elif ch == "}" and stack:
            stack.pop()
    return stack


def _open_brace_at(text: str, line_no: int) -> tuple[int, int, str] | None:
    """(line, col, text of that line) of the innermost '{' still open where line_no starts."""
    stack = _open_braces(text, line_no)
    if not stack:
        return None
    open_line, open_col = stack[-1]
    lines = text.split("\n", open_line)
    return open_line, open_col, lines[open_line - 1] if open_line - 1 < len(lines) else ""


def _depth_at(text: str, line_no: int) -> int:
    """Brace depth at the start of a line (strings and comments skipped)."""
    return len(_open_braces(text, line_no))


_BAD_CHARS = re.compile("[\x00-\x08\x0b\x0e-\x1f\x7f\ud800-\udfff]")
_NOT_BRACKETS = re.compile(r"[^()\[\]{}]+")


def _nth_bracket(text: str, n: int) -> int:
    """Offset in `text` of its n-th bracket (0-based)."""
    for m in re.finditer(r"[()\[\]{}]", text):
        if n == 0:
            return m.start()
        n -= 1
    return 0


def _check_source(data: bytes | str, path: str, sink: DiagnosticSink) -> str | None:
    if isinstance(data, bytes):
        if len(data) > MAX_SOURCE_BYTES:
            sink.error("E0003", f"source is too large ({len(data)} bytes; limit {MAX_SOURCE_BYTES})",
                       Span.point(path, 1, 1))
            return None
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            line = data[: exc.start].count(b"\n") + 1
            col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
            sink.error("E0003", "source is not valid UTF-8", Span.point(path, line, col),
                       "save the file as UTF-8 text")
            return None
    else:
        text = data
        if len(text) > MAX_SOURCE_BYTES:
            sink.error("E0003", f"source is too large ({len(text)} characters; limit {MAX_SOURCE_BYTES})",
                       Span.point(path, 1, 1))
            return None
        if text.startswith("\ufeff"):
            text = text[1:]
    bad_match = _BAD_CHARS.search(text)
    if bad_match is not None:
        bad = bad_match.start()
        line = text.count("\n", 0, bad) + 1
        col = bad - (text.rfind("\n", 0, bad) + 1) + 1
        sink.error("E0003", "source contains control characters or binary data",
                   Span.point(path, line, col), f"character {text[bad]!r} at offset {bad}")
        return None
    brackets = _NOT_BRACKETS.sub("", text)
    if len(brackets) > MAX_NESTING:  # else it cannot nest too deeply: skip the scan
        depth = 0
        for k, ch in enumerate(brackets):
            if ch in "([{":
                depth += 1
                if depth > MAX_NESTING:
                    i = _nth_bracket(text, k)
                    line = text.count("\n", 0, i) + 1
                    col = i - (text.rfind("\n", 0, i) + 1) + 1
                    sink.error("E0004", f"brackets nested deeper than {MAX_NESTING} levels",
                               Span.point(path, line, col))
                    return None
            else:
                depth = max(0, depth - 1)
    return text


class _Recovery:
    """The `on_error` callback of lark: report, skip to a statement end, resynchronise."""

    def __init__(self, text: str, path: str, sink: DiagnosticSink):
        self.text = text
        self.path = path
        self.sink = sink
        self.lines_reported: set[int] = set()

    @property
    def failed(self) -> bool:
        return bool(self.lines_reported)

    def on_error(self, exc: UnexpectedInput) -> bool:
        ip = getattr(exc, "interactive_parser", None)
        if ip is not None and self._close_unclosed_block(exc, ip):
            return True  # reported; read the line again after a virtual '}'
        self.report(exc)
        if len(self.lines_reported) >= MAX_SYNTAX_ERRORS:
            return False
        if ip is None:
            return False
        if self._brace_on_next_line(exc):
            return True  # reported; read on as if the '{' were on the header's line
        try:
            sync = self._skip(exc, ip)
            return self._resync(ip, sync)
        except (UnexpectedInput, IndexError, KeyError):
            return False

    def report(self, exc: UnexpectedInput) -> None:
        line = getattr(exc, "line", None) or 1
        if line in self.lines_reported or len(self.lines_reported) >= MAX_SYNTAX_ERRORS:
            return
        self.lines_reported.add(line)
        if len(self.lines_reported) == MAX_SYNTAX_ERRORS:
            self.sink.error("E0001", f"too many syntax errors; stopped after {MAX_SYNTAX_ERRORS}",
                            Span.point(self.path, line, getattr(exc, "column", 1) or 1))
            return
        _report_syntax_error(exc, self.path, self.sink, self.text)

    def _close_unclosed_block(self, exc: UnexpectedInput, ip) -> bool:
        """A definition (`param`, `agent`, `expect { ...`) inside another block means that
        block's '}' is missing. Report that once, close the block with a virtual '}' and
        read the line again at the scenario level, so the rest of the file is not blamed."""
        line_no = getattr(exc, "line", None) or 1
        if line_no in self.lines_reported or len(self.lines_reported) >= MAX_SYNTAX_ERRORS - 1:
            return False
        line_start = _line_offset(self.text, line_no)
        line = self.text[line_start:self.text.find("\n", line_start)]
        if not _DEFINITION_LINE.match(line):
            return False
        opened = _open_brace_at(self.text, line_no)
        if opened is None or _DEFINITION_OPENER.match(opened[2]) is None:
            return False
        state = ip.parser_state
        rbrace = Token("RBRACE", "}", line_start, line_no, 1, line_no, 1, line_start)
        newline = Token("_NL", "\n", line_start, line_no, 1, line_no, 1, line_start)
        trial = state.copy(deepcopy_values=False)
        while True:  # drop this line's partial statement until a '}' fits
            probe = trial.copy(deepcopy_values=False)
            try:
                probe.feed_token(rbrace)
                probe.feed_token(newline)
                break
            except UnexpectedInput:
                if len(trial.state_stack) <= 1:
                    return False
                trial.state_stack.pop()
                trial.value_stack.pop()
        indent = len(line) - len(line.lstrip())
        self.lines_reported.add(line_no)
        word = line.split()[0]
        self.sink.error("E0001", f"`{word}` cannot stand inside the block opened at line {opened[0]}",
                        Span(self.path, line_no, indent + 1, line_no, indent + 1 + len(word)),
                        f"is the '}}' of the block at {self.path}:{opened[0]}:{opened[1]} missing?")
        state.state_stack[:] = probe.state_stack
        state.value_stack[:] = probe.value_stack
        counter = ip.lexer_thread.state.line_ctr
        counter.char_pos, counter.line, counter.column, counter.line_start_pos = line_start, line_no, 1, line_start
        return True

    def _brace_on_next_line(self, exc: UnexpectedInput) -> bool:
        if not (isinstance(exc, UnexpectedToken) and exc.token.type == "_NL" and "LBRACE" in (exc.expected or ())):
            return False
        end = getattr(exc.token, "end_pos", None)
        return end is not None and self.text[end:].lstrip(" \t").startswith("{")

    def _skip(self, exc: UnexpectedInput, ip) -> Token:
        """Consume tokens up to the end of the broken statement; return the sync token."""
        depth = 0
        if isinstance(exc, UnexpectedToken):
            tok = exc.token
            if tok.type in ("_NL", "RBRACE", "$END"):
                return tok
            depth = 1 if tok.type == "LBRACE" else 0
        else:
            self._advance_one_char(ip)
        while True:
            try:
                for tok in ip.lexer_thread.lex(ip.parser_state):
                    found, depth = self._sync_step(tok, depth)
                    if found:
                        return tok
                return self._end_token(ip)
            except UnexpectedToken as skipped:  # a token not valid here: skip it too
                found, depth = self._sync_step(skipped.token, depth)
                if found:
                    return skipped.token
            except UnexpectedCharacters:
                self._advance_one_char(ip)

    @staticmethod
    def _sync_step(tok: Token, depth: int) -> tuple[bool, int]:
        if tok.type == "LBRACE":
            return False, depth + 1
        if tok.type == "RBRACE":
            return depth == 0, max(0, depth - 1)
        if tok.type in ("_NL", "$END"):
            return depth == 0 or tok.type == "$END", depth
        return False, depth

    def _advance_one_char(self, ip) -> None:
        state = ip.lexer_thread.state
        pos = state.line_ctr.char_pos
        if pos < len(self.text):
            state.line_ctr.feed(self.text[pos:pos + 1])

    def _end_token(self, ip) -> Token:
        last = ip.lexer_thread.state.last_token
        return Token.new_borrow_pos("$END", "", last) if last is not None else Token("$END", "", 0, 1, 1)

    @staticmethod
    def _resync(ip, sync: Token) -> bool:
        """Pop parser states until `sync` fits; feed it (the end of file is fed by lark)."""
        state = ip.parser_state
        is_end = sync.type == "$END"
        while True:
            trial = state.copy(deepcopy_values=False)
            try:
                trial.feed_token(sync, is_end)
            except UnexpectedToken:
                if len(state.state_stack) <= 1:
                    return False
                state.state_stack.pop()
                state.value_stack.pop()
                continue
            if not is_end:
                state.state_stack[:] = trial.state_stack
                state.value_stack[:] = trial.value_stack
            return True


def parse_source(data: bytes | str, path: str, sink: DiagnosticSink) -> ast.SourceFile | None:
    """Parse one file's contents; syntax errors go to `sink`; None if nothing usable."""
    text = _check_source(data, path, sink)
    if text is None:
        return None
    if not text.endswith("\n"):
        text += "\n"
    recovery = _Recovery(text, path, sink)
    lark, builder = _parser()
    with _PARSE_LOCK:
        builder.path = path
        builder.reset()
        try:
            tree_ast = lark.parse(text, on_error=recovery.on_error)
        except UnexpectedInput as exc:
            if not recovery.failed:
                _report_syntax_error(exc, path, sink, text)
            return None
        except RecursionError:
            sink.error("E0004", "source nested too deeply", Span.point(path, 1, 1))
            return None
        too_deep = builder.too_deep
        builder.reset()
    if recovery.failed:
        return None
    if too_deep is not None:
        sink.error("E0004", f"expression is too long or nested too deeply (limit {MAX_EXPR_DEPTH} operators)",
                   too_deep.span, "split it with parameters or simplify it")
        return None
    return tree_ast


def parse_file(path: Path, sink: DiagnosticSink, display: str | None = None) -> tuple[ast.SourceFile | None, str]:
    name = display or str(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        sink.error("E0401", f"cannot read {name}: {exc.strerror or exc}", None)
        return None, ""
    text = data.decode("utf-8", errors="replace")
    return parse_source(data, name, sink), text


def _acceptable(parser_state) -> set[str]:
    """Terminals the parser can take next (lark's `accepts`, without deep copies)."""
    out = set()
    for term in parser_state.parse_conf.states[parser_state.position]:
        if not term.isupper() and term != "$END":
            continue
        trial = parser_state.copy(deepcopy_values=False)
        try:
            trial.feed_token(Token(term, "", 0, 1, 1, 1, 1, 0), term == "$END")
        except UnexpectedInput:
            continue
        except Exception:  # noqa: BLE001 - a callback on a fake token; just not acceptable
            continue
        out.add(term)
    return out


def _unclosed_brace(text: str) -> tuple[int, int] | None:
    """(line, col) of the '{' most likely left open: the first whose closing '}' is
    indented differently from its line, else the innermost one never closed."""
    stack: list[tuple[int, int, int]] = []  # (line, col, indent)
    suspicious = None
    line, col, indent, at_line_start = 1, 0, 0, True
    in_string = in_comment = False
    prev = ""
    for ch in text:
        col += 1
        if ch == "\n":
            line, col, indent, at_line_start = line + 1, 0, 0, True
            in_string = in_comment = False
            prev = ch
            continue
        if at_line_start and ch in " \t":
            indent += 1
            prev = ch
            continue
        at_line_start = False
        if in_comment:
            continue
        if in_string:
            if ch == '"' and prev != "\\":
                in_string = False
            prev = "" if prev == "\\" and ch == "\\" else ch
            continue
        if ch == "#":
            in_comment = True
        elif ch == '"':
            in_string = True
        elif ch == "{":
            stack.append((line, col, indent))
        elif ch == "}" and stack:
            open_line, open_col, open_indent = stack.pop()
            if open_indent != indent and open_line != line and suspicious is None:
                suspicious = (open_line, open_col)
        prev = ch
    if not stack:
        return None
    return suspicious or stack[-1][:2]


def _report_syntax_error(exc: UnexpectedInput, path: str, sink: DiagnosticSink, text: str = "") -> None:
    line = getattr(exc, "line", 1) or 1
    col = getattr(exc, "column", 1) or 1
    ip = getattr(exc, "interactive_parser", None)
    try:
        expected = _acceptable(ip.parser_state) if ip is not None else set(getattr(exc, "expected", ()) or ())
    except Exception:  # noqa: BLE001 - expected words are a courtesy
        expected = set(getattr(exc, "expected", ()) or ())
    words = _expected_words(expected)
    if isinstance(exc, UnexpectedToken) and exc.token.type == "$END":
        notes = [f"expected {', '.join(words)}"] if words else []
        where = _unclosed_brace(text)
        if where is not None:
            notes.append(f"the block opened at {path}:{where[0]}:{where[1]} is not closed: is a '}}' missing?")
        sink.error("E0002", "unexpected end of file", Span.point(path, line, col), *notes)
        return
    if isinstance(exc, UnexpectedCharacters):
        ch = exc.char
        notes = [_CHAR_HINTS[ch]] if ch in _CHAR_HINTS else []
        if ch == "/" and text:
            notes.append("comments start with '#'")
        sink.error("E0001", f"unexpected character {ch!r}", Span.point(path, line, col),
                   *notes, label="not part of the language")
        return
    assert isinstance(exc, UnexpectedToken)
    token = exc.token
    shown = "end of line" if token.type == "_NL" else repr(str(token))
    notes = _curated_hint(token, expected, text)
    if words:
        notes.append("expected " + ", ".join(words[:14]) + (" ..." if len(words) > 14 else ""))
    width = max(1, len(str(token))) if token.type != "_NL" else 1
    sink.error("E0001", f"unexpected {shown}", Span(path, line, col, line, col + width), *notes)


# ---------------------------------------------------------------- parse → AST

# Named keyword tokens the grammar keeps only for their position: dropped before a rule's
# builder sees its children.
_POSITION_ONLY = frozenset({
    "INCLUDE", "SCENARIO", "ROAD", "IMPORT", "PARAM", "ASSUME", "KEEP", "AGENT", "AHEAD", "BEHIND",
    "LANE", "AT", "AFTER", "WHEN", "SET", "FAULTS", "DURING", "FROM", "EXPECT", "NO", "STAY", "REACH",
    "SWEEP", "GRID", "REPEAT", "SEED", "MAX_REJECTIONS", "WITHIN", "LSQB",
})


class _Marked:
    """A helper value with a span (labels, severities, road imports)."""

    __slots__ = ("span", "kind", "value")

    def __init__(self, span: Span, kind: str, value):
        self.span, self.kind, self.value = span, kind, value


def _bounds(child):
    """((line, col), (end_line, end_col)) of a child, or None."""
    if isinstance(child, Token):
        if child.line is None:
            return None
        return (child.line, child.column), (child.end_line or child.line,
                                            child.end_column or child.column + len(child))
    span = getattr(child, "span", None)
    if span is not None:
        return (span.line, span.col), (span.end_line, span.end_col)
    if isinstance(child, (list, tuple)) and child:
        first, last = _bounds(child[0]), _bounds(child[-1])
        if first and last:
            return first[0], last[1]
    return None


class _Builder:
    """AST builders, called by lark as it reduces (no intermediate parse tree).

    Each builder gets the rule's span (from the first to the last positioned child, so
    the grammar keeps the keywords that start a construct as named tokens) and its
    children without those keywords. `path` is set per parse (see `parse_source`)."""

    def __init__(self):
        self.path = "<input>"
        self.reset()

    def reset(self) -> None:
        # Operator depth of each expression node built (by id), and the first node deeper
        # than MAX_EXPR_DEPTH: later stages recurse over expressions.
        self.depth: dict[int, int] = {}
        self.too_deep: ast.Node | None = None

    def _deep(self, node, *children):
        depth = self.depth
        d = 1 + max((depth.get(id(c), 0) for c in children), default=0)
        depth[id(node)] = d
        if d > MAX_EXPR_DEPTH and self.too_deep is None:
            self.too_deep = node
        return node

    def callbacks(self) -> dict:
        """name → callback(children) for every rule and alias of the grammar."""
        out = {}
        for name in dir(self):
            if name.startswith("b_"):
                out[name[2:]] = self._wrap(getattr(self, name))
        return out

    # Builders that return containers or words: no span needed, skip computing one.
    _NO_SPAN = frozenset({"settings", "clause_settings", "road_block", "actor_block", "clause_block", "interval",
                          "add_op", "actor_ref", "clause_key"})
    # Builders that see the keyword tokens other builders drop (a keyword used as a key).
    _RAW = frozenset({"clause_key"})

    def _wrap(self, build):
        position_only = frozenset() if build.__name__[2:] in self._RAW else _POSITION_ONLY
        needs_span = build.__name__[2:] not in self._NO_SPAN
        no_span = Span.point("<none>", 1, 1)

        def callback(children):
            span = no_span
            if needs_span:
                first = last = None
                for c in children:
                    first = _bounds(c)
                    if first is not None:
                        break
                if first is None:
                    span = Span.point(self.path, 1, 1)
                else:
                    for c in reversed(children):
                        last = _bounds(c)
                        if last is not None:
                            break
                    span = Span(self.path, first[0][0], first[0][1], last[1][0], last[1][1])
            items = []
            for c in children:
                if c.__class__ is Token:
                    kind = c.type
                    if kind in position_only:
                        continue
                    if kind == "STRING":
                        c = ast.Str(self._tspan(c), _unquote(c))
                    elif kind == "TRUE" or kind == "FALSE":
                        c = ast.Bool(self._tspan(c), kind == "TRUE")
                items.append(c)
            return build(span, items)

        return callback

    def _tspan(self, tok: Token) -> Span:
        return Span(self.path, tok.line, tok.column, tok.end_line or tok.line,
                    tok.end_column or tok.column + len(tok))

    # ---- top level
    def b_start(self, span, items):
        includes = tuple(i for i in items if isinstance(i, ast.Include))
        scenarios = tuple(i for i in items if isinstance(i, ast.Scenario))
        defs = tuple(i for i in items if not isinstance(i, (ast.Include, ast.Scenario)))
        return ast.SourceFile(span, self.path, includes, scenarios, defs)

    def b_include(self, span, items):
        return ast.Include(span, _unquote(items[0]))

    def b_scenario(self, span, items):
        name, rest = str(items[0]), items[1:]
        settings = tuple(i for i in rest if isinstance(i, ast.Setting))
        includes = tuple(i for i in rest if isinstance(i, ast.Include))
        defs = tuple(i for i in rest if not isinstance(i, (ast.Setting, ast.Include)))
        return ast.Scenario(span, name, settings, defs, includes)

    def b_setting(self, span, items):
        key, value = items
        return ast.Setting(span, str(key), self._tspan(key), value)

    def b_settings(self, span, items):
        return tuple(items)

    b_clause_settings = b_settings

    def b_clause_setting(self, span, items):
        key, value = items
        return ast.Setting(span, str(key), key.span, value)

    def b_clause_key(self, span, items):
        return _keyword(items[0], self.path)

    b_setting_line = b_setting

    # ---- road
    def b_road(self, span, items):
        name, body = items
        if isinstance(body, _Marked):
            path, settings = body.value
            return ast.RoadDecl(span, str(name), (), path, settings)
        return ast.RoadDecl(span, str(name), tuple(body))

    def b_road_block(self, span, items):
        return list(items)

    def b_road_item(self, span, items):
        kind, settings = items
        return ast.RoadItem(span, str(kind), settings)

    def b_road_import(self, span, items):
        return _Marked(span, "import", (_unquote(items[0]), items[1]))

    # ---- parameters
    def b_param(self, span, items):
        name, default = str(items[0]), items[1]
        domain = items[2] if len(items) == 4 else None
        return ast.ParamDecl(span, name, default, domain, items[-1])

    def b_assume(self, span, items):
        label = items[0].value if isinstance(items[0], _Marked) else None
        return ast.AssumeDecl(span, items[-1], label)

    # ---- actors
    def b_actor(self, span, items):
        if isinstance(items[0], Token) and items[0].type == "EGO":
            is_ego, name, rest = True, "ego", items[1:]
        else:
            is_ego, name, rest = False, str(items[0]), items[1:]
        vehicle, rest = rest[0], rest[1:]
        block = rest[-1] if rest and isinstance(rest[-1], list) else []
        head = [r for r in rest if not isinstance(r, list)]
        settings = tuple(h for h in head if isinstance(h, ast.Setting))
        placements = tuple(h for h in head if isinstance(h, ast.Placement))
        clauses = tuple(b for b in block if isinstance(b, ast.Clause))
        steps = tuple(b for b in block if isinstance(b, (ast.Step, ast.Group)))
        block_settings = tuple(b for b in block if isinstance(b, ast.Setting))
        return ast.ActorDecl(span, name, is_ego, str(vehicle), self._tspan(vehicle),
                             settings, clauses, steps, block_settings, placements)

    def b_actor_block(self, span, items):
        return list(items)

    def b_actor_ref(self, span, items):
        return items[0]

    def b_ahead_of(self, span, items):
        return ast.Placement(span, "ahead", str(items[0]), self._tspan(items[0]), items[1])

    def b_behind(self, span, items):
        return ast.Placement(span, "behind", str(items[0]), self._tspan(items[0]), items[1])

    def _keyword_setting(self, span, key, value):
        key_span = Span(self.path, span.line, span.col, span.line, span.col + len(key))
        return ast.Setting(span, key, key_span, value)

    def b_lane_value(self, span, items):
        return self._keyword_setting(span, "lane", items[0])

    def b_at_value(self, span, items):
        return self._keyword_setting(span, "at", items[0])

    def b_lane_of(self, span, items):
        return ast.Placement(span, "lane_of", str(items[0]), self._tspan(items[0]))

    def b_lane_left_of(self, span, items):
        return ast.Placement(span, "lane_left", str(items[0]), self._tspan(items[0]))

    def b_lane_right_of(self, span, items):
        return ast.Placement(span, "lane_right", str(items[0]), self._tspan(items[0]))

    def b_clause(self, span, items):
        kw, name, settings = items[0], items[1], items[2]
        block = tuple(items[3]) if len(items) > 3 else ()
        keyword = "behavior" if kw == "behaviour" else kw
        return ast.Clause(span, keyword, str(name), self._tspan(name), settings, block)

    def b_clause_kw(self, span, items):
        return _keyword(items[0], self.path)

    def b_clause_block(self, span, items):
        return list(items)

    def b_step(self, span, items):
        starts = tuple(i for i in items if isinstance(i, ast.StepStart))
        return ast.Step(span, starts, items[-1])

    def b_start_at(self, span, items):
        return ast.StepStart(span, "at", items[0])

    def b_start_after(self, span, items):
        return ast.StepStart(span, "after", items[0])

    def b_start_when(self, span, items):
        return ast.StepStart(span, "when", items[0])

    def b_group(self, span, items):
        return ast.Group(span, str(items[0]), tuple(items[1:]))

    # ---- faults
    def b_faults(self, span, items):
        return ast.Block(span, "faults", tuple(items))

    def b_fault(self, span, items):
        timing = items[0] if isinstance(items[0], ast.Timing) else None
        rest = items[1:] if timing else items
        kind, target, settings = rest
        return ast.FaultDecl(span, str(kind), self._tspan(kind), target.value, target.span, timing, settings)

    def b_target(self, span, items):
        return _Marked(span, "target", tuple(str(t) for t in items))

    def b_at_time(self, span, items):
        return ast.Timing(span, "at", items[0], None, items[1] if len(items) > 1 else None)

    def b_during(self, span, items):
        lo, hi = items[0]
        return ast.Timing(span, "during", lo, hi)

    def b_from_time(self, span, items):
        return ast.Timing(span, "from", items[0])

    def b_interval(self, span, items):
        return items[0], items[1]

    # ---- oracles
    def b_expect(self, span, items):
        return ast.Block(span, "expect", tuple(items))

    def b_oracle(self, span, items):
        severity, label = "hard", None
        rest = list(items)
        if rest and isinstance(rest[0], _Marked) and rest[0].kind == "severity":
            severity = rest.pop(0).value
        if rest and isinstance(rest[0], _Marked) and rest[0].kind == "label":
            label = rest.pop(0).value
        body = rest[0]
        if isinstance(body, ast.Builtin):
            return ast.OracleDecl(span, severity, label, None, body)
        return ast.OracleDecl(span, severity, label, body)

    def b_severity(self, span, items):
        return _Marked(span, "severity", str(items[0]))

    def b_label(self, span, items):
        return _Marked(span, "label", str(items[0]))

    def b_no_clause(self, span, items):
        actor = items[1] if len(items) > 1 else None
        return ast.Builtin(span, "no", str(items[0]), self._tspan(items[0]),
                           str(actor) if actor is not None else None,
                           self._tspan(actor) if actor is not None else None)

    def b_stay_in_lane(self, span, items):
        return ast.Builtin(span, "stay_in_lane", settings=items[0] if items else ())

    def b_reach_goal(self, span, items):
        return ast.Builtin(span, "reach_goal", value=items[0] if items else None)

    def b_bound(self, span, items):
        kind, signal = items[0], items[1]
        actor = items[2] if len(items) == 4 else None
        return ast.Builtin(span, str(kind), str(signal), self._tspan(signal),
                           str(actor) if actor is not None else None,
                           self._tspan(actor) if actor is not None else None, items[-1])

    # ---- sweeps
    def b_sweep(self, span, items):
        return ast.Block(span, "sweep", tuple(items))

    def b_grid(self, span, items):
        return ast.SweepItem(span, "grid", str(items[0]), items[1])

    def b_sample(self, span, items):
        return ast.SweepItem(span, str(items[0]), None, items[1], items[2])

    def b_sampler(self, span, items):
        return _keyword(items[0], self.path)

    def b_repeat(self, span, items):
        return ast.SweepItem(span, "repeat", None, items[0])

    def b_sweep_seed(self, span, items):
        return ast.SweepItem(span, "seed", None, items[0])

    def b_max_rejections(self, span, items):
        return ast.SweepItem(span, "max_rejections", None, items[0])

    # ---- expressions
    def b_always(self, span, items):
        return self._temporal(span, "always", items)

    def b_eventually(self, span, items):
        return self._temporal(span, "eventually", items)

    def _temporal(self, span, op, items):
        items = [i for i in items if not isinstance(i, Token)]
        window = items[0] if len(items) == 2 else None
        return self._deep(ast.TemporalExpr(span, op, window, items[-1]), items[-1])

    def b_within(self, span, items):
        return ast.Window(span, None, items[0])

    def b_during_window(self, span, items):
        lo, hi = items[0]
        return ast.Window(span, lo, hi)

    def b_after(self, span, items):
        return ast.Window(span, items[0], None)

    def b_until(self, span, items):
        items = [i for i in items if not isinstance(i, Token)]
        window = items[1] if len(items) == 3 else None
        return self._deep(ast.UntilExpr(span, window, items[0], items[-1]), items[0], items[-1])

    def b_implies(self, span, items):
        return self._deep(ast.BinaryExpr(span, "implies", items[0], items[2]), items[0], items[2])

    def _chain(self, span, items):
        # Left-associative chain `a op b op c`; each node spans its operands.
        node = items[0]
        for op, right in zip(items[1::2], items[2::2]):
            node = self._deep(ast.BinaryExpr(Span(self.path, node.span.line, node.span.col, right.span.end_line,
                                                  right.span.end_col), str(op), node, right), node, right)
        return node

    b_or_ = b_and_ = b_sum = b_product = _chain

    def b_add_op(self, span, items):
        return str(items[0])

    def b_comparison(self, span, items):
        return self._deep(ast.BinaryExpr(span, str(items[1]), items[0], items[2]), items[0], items[2])

    def b_not_(self, span, items):
        return self._deep(ast.UnaryExpr(span, "not", items[-1]), items[-1])

    def b_neg(self, span, items):
        arg = items[-1]
        if isinstance(arg, ast.Number):
            return self._deep(ast.Number(span, -arg.value, arg.unit), arg)
        return self._deep(ast.UnaryExpr(span, "neg", arg), arg)

    def b_quantity(self, span, items):
        unit = str(items[1]) if len(items) > 1 else None
        return ast.Number(span, float(items[0]), unit)

    def b_ref(self, span, items):
        return ast.Ref(span, tuple(str(t) for t in items))

    def b_call(self, span, items):
        return self._deep(ast.CallExpr(span, str(items[0]), tuple(items[1:])), *items[1:])

    def b_list_(self, span, items):
        unit = None
        if items and isinstance(items[-1], Token) and items[-1].type == "UNIT":
            unit = str(items[-1])
            items = items[:-1]
        return self._deep(ast.ListExpr(span, tuple(items), unit), *items)


class _Keyword(str):
    """A keyword kept as text (a clause keyword, a sampler), with its position."""

    span: Span


def _keyword(tok: Token, path: str) -> _Keyword:
    word = _Keyword(str(tok))
    word.span = Span(path, tok.line, tok.column, tok.end_line or tok.line, tok.end_column or tok.column + len(tok))
    return word


_ESCAPES = {"n": "\n", "t": "\t", '"': '"', "\\": "\\"}


def _unquote(tok) -> str:
    """String literal → text. Escapes: \\n \\t \\" \\\\; any other `\\x` stays as written."""
    if isinstance(tok, ast.Str):
        return tok.value
    text = str(tok)[1:-1]
    if "\\" not in text:
        return text
    out, i = [], 0
    while i < len(text):
        ch = text[i]
        if ch == "\\" and i + 1 < len(text) and text[i + 1] in _ESCAPES:
            out.append(_ESCAPES[text[i + 1]])
            i += 2
        else:
            out.append(ch)
            i += 1
    return "".join(out)
