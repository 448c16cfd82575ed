"""Source text → AST. Syntax errors become diagnostics, never tracebacks.

lark (LALR, contextual lexer) builds a parse tree with positions; `_ToAst` turns it
into the frozen dataclasses of `compiler.ast`.

Error recovery is panic mode, as in yacc's `error` token: after a syntax error the
parser skips tokens to the end of the statement (a newline or a closing brace outside
any brace opened on the way), then pops parser states until that token fits, feeds it
and goes on. One run therefore reports every broken statement, not just the first.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

from lark import Lark, Token, Transformer, Tree, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from addt_dsl.compiler import ast
from addt_dsl.diagnostics import DiagnosticSink, Span

GRAMMAR_PATH = Path(__file__).resolve().parent.parent / "grammar" / "addt.lark"
MAX_SOURCE_BYTES = 1_000_000  # real scenarios are a few kB; lark parses ~200 kB/s
MAX_NESTING = 64
MAX_SYNTAX_ERRORS = 25
MAX_EXPR_DEPTH = 200  # operators chained or nested in one expression


@functools.lru_cache(maxsize=1)
def grammar() -> Lark:
    """The parser, built once per process (a check of many files reuses it)."""
    return Lark.open(str(GRAMMAR_PATH), parser="lalr", lexer="contextual",
                     propagate_positions=True, maybe_placeholders=False, cache=False)


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


def _depth_at(text: str, line_no: int) -> int:
    """Brace depth at the start of a line (strings and comments skipped)."""
    depth, line, in_string, in_comment, escaped = 0, 1, False, False, False
    for ch in text:
        if ch == "\n":
            line += 1
            in_string = in_comment = False
            if line >= line_no:
                return depth
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
            depth += 1
        elif ch == "}":
            depth = max(0, depth - 1)
    return depth


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
    bad = next((i for i, ch in enumerate(text)
                if (ord(ch) < 32 and ch not in "\t\r\n\f") or ch == "\x7f" or 0xD800 <= ord(ch) <= 0xDFFF),
               None)
    if bad is not None:
        line = text.count("\n", 0, bad) + 1
        col = bad - (text.rfind("\n", 0, bad) + 1) + 1
        sink.error("E0003", "source contains control characters or binary data",
                   Span.point(path, line, col), f"character {text[bad]!r} at offset {bad}")
        return None
    depth = 0
    for i, ch in enumerate(text):
        if ch in "([{":
            depth += 1
            if depth > MAX_NESTING:
                line = text.count("\n", 0, i) + 1
                col = i - (text.rfind("\n", 0, i) + 1) + 1
                sink.error("E0004", f"brackets nested deeper than {MAX_NESTING} levels",
                           Span.point(path, line, col))
                return None
        elif ch in ")]}":
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
        self.report(exc)
        if len(self.lines_reported) >= MAX_SYNTAX_ERRORS:
            return False
        ip = getattr(exc, "interactive_parser", None)
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
    try:
        tree = grammar().parse(text, on_error=recovery.on_error)
    except UnexpectedInput as exc:
        if not recovery.failed:
            _report_syntax_error(exc, path, sink, text)
        return None
    except RecursionError:
        sink.error("E0004", "source nested too deeply", Span.point(path, 1, 1))
        return None
    if recovery.failed:
        return None
    try:
        tree_ast = _ToAst(path).transform(tree)
    except RecursionError:
        sink.error("E0004", "source nested too deeply", Span.point(path, 1, 1))
        return None
    too_deep = _first_too_deep(tree_ast)
    if too_deep is not None:
        sink.error("E0004", f"expression is too long or nested too deeply (limit {MAX_EXPR_DEPTH} operators)",
                   too_deep.span, "split it with parameters or simplify it")
        return None
    return tree_ast


def _first_too_deep(root) -> ast.Node | None:
    """The first expression whose operator tree is deeper than MAX_EXPR_DEPTH (iterative:
    later stages recurse over expressions and must not hit Python's recursion limit)."""
    stack = [(root, 0)]
    while stack:
        node, depth = stack.pop()
        if depth > MAX_EXPR_DEPTH:
            return node
        if isinstance(node, (tuple, list)):
            stack.extend((child, depth) for child in node)
            continue
        if not isinstance(node, ast.Node):
            continue
        is_expr = isinstance(node, ast.Expression)
        for name in node.__slots__:
            child = getattr(node, name, None)
            if isinstance(child, (ast.Node, tuple, list)):
                stack.append((child, depth + 1 if is_expr else depth))
    return None


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


# ---------------------------------------------------------------- tree → AST

class _ToAst(Transformer):
    def __init__(self, path: str):
        super().__init__(visit_tokens=False)
        self.path = path

    def _span(self, meta) -> Span:
        if getattr(meta, "empty", True):
            return Span.point(self.path, 1, 1)
        return Span(self.path, meta.line, meta.column, meta.end_line, meta.end_column)

    def _tspan(self, tok: Token) -> Span:
        return Span(self.path, tok.line, tok.column, tok.end_line or tok.line,
                    tok.end_column or tok.column + len(tok))

    # ---- top level
    @v_args(meta=True)
    def start(self, meta, items):
        includes = tuple(i for i in items if isinstance(i, ast.Include))
        scenarios = tuple(i for i in items if isinstance(i, ast.Scenario))
        defs = tuple(i for i in items if not isinstance(i, (ast.Include, ast.Scenario)))
        return ast.SourceFile(self._span(meta), self.path, includes, scenarios, defs)

    @v_args(meta=True)
    def include(self, meta, items):
        return ast.Include(self._span(meta), _unquote(items[0]))

    @v_args(meta=True)
    def scenario(self, meta, items):
        name = str(items[0])
        rest = items[1:]
        settings = tuple(i for i in rest if isinstance(i, ast.Setting))
        includes = tuple(i for i in rest if isinstance(i, ast.Include))
        defs = tuple(i for i in rest if not isinstance(i, (ast.Setting, ast.Include)))
        return ast.Scenario(self._span(meta), name, settings, defs, includes)

    @v_args(meta=True)
    def setting(self, meta, items):
        key, value = items
        return ast.Setting(self._span(meta), str(key), self._tspan(key), value)

    def settings(self, items):
        return tuple(items)

    @v_args(meta=True)
    def setting_line(self, meta, items):
        key, value = items
        return ast.Setting(self._span(meta), str(key), self._tspan(key), value)

    # ---- road
    @v_args(meta=True)
    def road(self, meta, items):
        name, body = items
        if isinstance(body, tuple) and body and body[0] == "import":
            _, path, settings = body
            return ast.RoadDecl(self._span(meta), str(name), (), path, settings)
        return ast.RoadDecl(self._span(meta), str(name), tuple(body))

    def road_block(self, items):
        return list(items)

    @v_args(meta=True)
    def road_item(self, meta, items):
        kind, settings = items
        return ast.RoadItem(self._span(meta), str(kind), settings)

    def road_import(self, items):
        return ("import", _unquote(items[0]), items[1])

    # ---- parameters
    @v_args(meta=True)
    def param(self, meta, items):
        name = str(items[0])
        default = items[1]
        domain = items[2] if len(items) == 4 else None
        settings = items[-1]
        return ast.ParamDecl(self._span(meta), name, default, domain, settings)

    @v_args(meta=True)
    def assume(self, meta, items):
        label = None
        if items and isinstance(items[0], tuple) and items[0][0] == "label":
            label = items[0][1]
        return ast.AssumeDecl(self._span(meta), items[-1], label)

    # ---- actors
    @v_args(meta=True)
    def actor(self, meta, items):
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
        return ast.ActorDecl(self._span(meta), name, is_ego, str(vehicle), self._tspan(vehicle),
                             settings, clauses, steps, block_settings, placements)

    def actor_block(self, items):
        return list(items)

    def actor_ref(self, items):
        return items[0]

    @v_args(meta=True)
    def ahead_of(self, meta, items):
        return ast.Placement(self._span(meta), "ahead", str(items[0]), self._tspan(items[0]), items[1])

    @v_args(meta=True)
    def behind(self, meta, items):
        return ast.Placement(self._span(meta), "behind", str(items[0]), self._tspan(items[0]), items[1])

    @v_args(meta=True)
    def lane_value(self, meta, items):
        span = self._span(meta)
        key_span = Span(self.path, span.line, span.col, span.line, span.col + 4)
        return ast.Setting(span, "lane", key_span, items[0])

    @v_args(meta=True)
    def at_value(self, meta, items):
        span = self._span(meta)
        key_span = Span(self.path, span.line, span.col, span.line, span.col + 2)
        return ast.Setting(span, "at", key_span, items[0])

    @v_args(meta=True)
    def lane_of(self, meta, items):
        return ast.Placement(self._span(meta), "lane_of", str(items[0]), self._tspan(items[0]))

    @v_args(meta=True)
    def lane_left_of(self, meta, items):
        return ast.Placement(self._span(meta), "lane_left", str(items[0]), self._tspan(items[0]))

    @v_args(meta=True)
    def lane_right_of(self, meta, items):
        return ast.Placement(self._span(meta), "lane_right", str(items[0]), self._tspan(items[0]))

    @v_args(meta=True)
    def clause(self, meta, items):
        kw, name, settings = items[0], items[1], items[2]
        block = tuple(items[3]) if len(items) > 3 else ()
        keyword = "behavior" if kw == "behaviour" else kw
        return ast.Clause(self._span(meta), keyword, str(name), self._tspan(name), settings, block)

    def add_op(self, items):
        return str(items[0])

    def clause_kw(self, items):
        return str(items[0])

    def clause_block(self, items):
        return list(items)

    @v_args(meta=True)
    def step(self, meta, items):
        starts = tuple(i for i in items if isinstance(i, ast.StepStart))
        return ast.Step(self._span(meta), starts, items[-1])

    @v_args(meta=True)
    def start_at(self, meta, items):
        return ast.StepStart(self._span(meta), "at", items[0])

    @v_args(meta=True)
    def start_after(self, meta, items):
        return ast.StepStart(self._span(meta), "after", items[0])

    @v_args(meta=True)
    def start_when(self, meta, items):
        return ast.StepStart(self._span(meta), "when", items[0])

    @v_args(meta=True)
    def group(self, meta, items):
        return ast.Group(self._span(meta), str(items[0]), tuple(items[1:]))

    # ---- faults
    @v_args(meta=True)
    def faults(self, meta, items):
        return ast.Block(self._span(meta), "faults", tuple(items))

    @v_args(meta=True)
    def fault(self, meta, items):
        timing = items[0] if isinstance(items[0], ast.Timing) else None
        rest = items[1:] if timing else items
        kind, (target, target_span), settings = rest
        return ast.FaultDecl(self._span(meta), str(kind), self._tspan(kind), target, target_span,
                             timing, settings)

    @v_args(meta=True)
    def target(self, meta, items):
        return tuple(str(t) for t in items), self._span(meta)

    @v_args(meta=True)
    def at_time(self, meta, items):
        return ast.Timing(self._span(meta), "at", items[0], None, items[1] if len(items) > 1 else None)

    @v_args(meta=True)
    def during(self, meta, items):
        lo, hi = items[0]
        return ast.Timing(self._span(meta), "during", lo, hi)

    @v_args(meta=True)
    def from_time(self, meta, items):
        return ast.Timing(self._span(meta), "from", items[0])

    def interval(self, items):
        return items[0], items[1]

    # ---- oracles
    @v_args(meta=True)
    def expect(self, meta, items):
        return ast.Block(self._span(meta), "expect", tuple(items))

    @v_args(meta=True)
    def oracle(self, meta, items):
        severity, label = "hard", None
        rest = list(items)
        if rest and isinstance(rest[0], tuple) and rest[0][0] == "severity":
            severity = rest.pop(0)[1]
        if rest and isinstance(rest[0], tuple) and rest[0][0] == "label":
            label = rest.pop(0)[1]
        body = rest[0]
        if isinstance(body, ast.Builtin):
            return ast.OracleDecl(self._span(meta), severity, label, None, body)
        return ast.OracleDecl(self._span(meta), severity, label, body)

    def severity(self, items):
        return ("severity", str(items[0]))

    def label(self, items):
        return ("label", str(items[0]))

    @v_args(meta=True)
    def no_clause(self, meta, items):
        actor = items[1] if len(items) > 1 else None
        return ast.Builtin(self._span(meta), "no", str(items[0]), self._tspan(items[0]),
                           str(actor) if actor is not None else None,
                           self._tspan(actor) if actor is not None else None)

    @v_args(meta=True)
    def stay_in_lane(self, meta, items):
        return ast.Builtin(self._span(meta), "stay_in_lane", settings=items[0] if items else ())

    @v_args(meta=True)
    def reach_goal(self, meta, items):
        return ast.Builtin(self._span(meta), "reach_goal", value=items[0] if items else None)

    @v_args(meta=True)
    def bound(self, meta, items):
        kind, signal = items[0], items[1]
        actor = items[2] if len(items) == 4 else None
        return ast.Builtin(self._span(meta), str(kind), str(signal), self._tspan(signal),
                           str(actor) if actor is not None else None,
                           self._tspan(actor) if actor is not None else None, items[-1])

    # ---- sweeps
    @v_args(meta=True)
    def sweep(self, meta, items):
        return ast.Block(self._span(meta), "sweep", tuple(items))

    @v_args(meta=True)
    def grid(self, meta, items):
        return ast.SweepItem(self._span(meta), "grid", str(items[0]), items[1])

    @v_args(meta=True)
    def sample(self, meta, items):
        return ast.SweepItem(self._span(meta), items[0], None, items[1], items[2])

    def sampler(self, items):
        return str(items[0])

    @v_args(meta=True)
    def repeat(self, meta, items):
        return ast.SweepItem(self._span(meta), "repeat", None, items[0])

    @v_args(meta=True)
    def sweep_seed(self, meta, items):
        return ast.SweepItem(self._span(meta), "seed", None, items[0])

    @v_args(meta=True)
    def max_rejections(self, meta, items):
        return ast.SweepItem(self._span(meta), "max_rejections", None, items[0])

    # ---- expressions
    @v_args(meta=True)
    def always(self, meta, items):
        return self._temporal(meta, "always", items)

    @v_args(meta=True)
    def eventually(self, meta, items):
        return self._temporal(meta, "eventually", items)

    def _temporal(self, meta, op, items):
        items = [i for i in items if not isinstance(i, Token)]
        window = items[0] if len(items) == 2 else None
        return ast.TemporalExpr(self._span(meta), op, window, items[-1])

    @v_args(meta=True)
    def within(self, meta, items):
        return ast.Window(self._span(meta), None, items[0])

    @v_args(meta=True)
    def during_window(self, meta, items):
        lo, hi = items[0]
        return ast.Window(self._span(meta), lo, hi)

    @v_args(meta=True)
    def after(self, meta, items):
        return ast.Window(self._span(meta), items[0], None)

    @v_args(meta=True)
    def until(self, meta, items):
        items = [i for i in items if not isinstance(i, Token)]
        window = items[1] if len(items) == 3 else None
        return ast.UntilExpr(self._span(meta), window, items[0], items[-1])

    @v_args(meta=True)
    def implies(self, meta, items):
        return ast.BinaryExpr(self._span(meta), "implies", items[0], items[2])

    @v_args(meta=True)
    def or_(self, meta, items):
        return self._chain(meta, items)

    @v_args(meta=True)
    def and_(self, meta, items):
        return self._chain(meta, items)

    @v_args(meta=True)
    def sum(self, meta, items):
        return self._chain(meta, items)

    @v_args(meta=True)
    def product(self, meta, items):
        return self._chain(meta, items)

    def _chain(self, meta, items):
        # Left-associative chain `a op b op c`; each node spans its operands.
        node = items[0]
        for op, right in zip(items[1::2], items[2::2]):
            span = Span(self.path, node.span.line, node.span.col, right.span.end_line, right.span.end_col)
            node = ast.BinaryExpr(span, str(op), node, right)
        return node

    @v_args(meta=True)
    def comparison(self, meta, items):
        return ast.BinaryExpr(self._span(meta), str(items[1]), items[0], items[2])

    @v_args(meta=True)
    def not_(self, meta, items):
        return ast.UnaryExpr(self._span(meta), "not", items[-1])

    @v_args(meta=True)
    def neg(self, meta, items):
        arg = items[-1]
        if isinstance(arg, ast.Number):
            return ast.Number(self._span(meta), -arg.value, arg.unit)
        return ast.UnaryExpr(self._span(meta), "neg", arg)

    @v_args(meta=True)
    def quantity(self, meta, items):
        value = float(items[0])
        unit = str(items[1]) if len(items) > 1 else None
        return ast.Number(self._span(meta), value, unit)

    @v_args(meta=True)
    def ref(self, meta, items):
        return ast.Ref(self._span(meta), tuple(str(t) for t in items))

    @v_args(meta=True)
    def call(self, meta, items):
        return ast.CallExpr(self._span(meta), str(items[0]), tuple(items[1:]))

    @v_args(meta=True)
    def list_(self, meta, items):
        unit = None
        if items and isinstance(items[-1], Token) and items[-1].type == "UNIT":
            unit = str(items[-1])
            items = items[:-1]
        return ast.ListExpr(self._span(meta), tuple(items), unit)

    def __default_token__(self, token):
        return token

    def __default__(self, data, children, meta):
        # Bare tokens that reach here as atoms (STRING, TRUE, FALSE).
        return Tree(data, children, meta)

    def _atom_token(self, tok: Token):
        span = self._tspan(tok)
        if tok.type == "STRING":
            return ast.Str(span, _unquote(tok))
        if tok.type in ("TRUE", "FALSE"):
            return ast.Bool(span, tok.type == "TRUE")
        return tok

    def transform(self, tree):
        return super().transform(_wrap_atom_tokens(tree, self))


def _wrap_atom_tokens(tree, conv: _ToAst):
    """Turn STRING/TRUE/FALSE tokens into AST atoms before the bottom-up transform."""
    if isinstance(tree, Tree):
        tree.children = [conv._atom_token(c) if isinstance(c, Token) and c.type in ("STRING", "TRUE", "FALSE")
                         else _wrap_atom_tokens(c, conv) for c in tree.children]
    return tree


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
