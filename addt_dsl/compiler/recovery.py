"""Syntax errors as diagnostics, and panic-mode error recovery.

Recovery is panic mode, as in yacc's `error` token: after a syntax error the parser
skips tokens to the end of the statement (a newline or a closing brace outside any brace
opened on the way), then pops parser states until that token fits, feeds it and goes on.
One run therefore reports every broken statement, not just the first. Two repairs avoid
cascades: a block's `{` on the line after its header is read as if on the header's line,
and a definition (`param`, `agent`, `expect {`) inside another block closes that block
with a virtual `}` (its `}` is missing) and is read again. Each error names what the
grammar expected there (`_acceptable`) and, for common slips, a curated hint.

`check_source` rejects what is not source text before lark sees it (binary data, bad
UTF-8, a huge file, brackets nested too deeply).
"""

from __future__ import annotations

import difflib
import functools
import re

from lark import Lark, Token
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from addt_dsl.diagnostics import DiagnosticSink, Span

MAX_SOURCE_BYTES = 1_000_000  # real scenarios are a few kB; lark parses ~200 kB/s
MAX_NESTING = 64
MAX_SYNTAX_ERRORS = 25


@functools.lru_cache(maxsize=4)
def _terminal_words(lark: Lark) -> dict[str, str]:
    """Readable names of the grammar's terminals, for "expected ..." notes."""
    words = {"NAME": "a name", "NUMBER": "a number", "STRING": "a string", "UNIT": "a unit",
             "_NL": "end of line", "$END": "end of file", "COMP": "a comparison",
             "MUL_OP": "'*' or '/'"}
    for term in lark.terminals:
        if term.name not in words and term.pattern.type == "str":
            words[term.name] = f"'{term.pattern.value}'"
    return words


def _expected_words(lark: Lark, expected) -> list[str]:
    table = _terminal_words(lark)
    return sorted({table[name] for name in expected if name in table})


# Words that start a definition; seen where they cannot stand, a '}' is usually missing.
_DEFINITION_WORDS = {"agent", "ego", "param", "road", "faults", "expect", "sweep", "assume", "keep",
                     "include", "scenario", "lights", "environment"}

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
    "mins": "min", "minute": "min", "minutes": "min", "hr": "h", "hour": "h", "hours": "h",
    "hz": "Hz", "HZ": "Hz", "hertz": "Hz", "degree": "deg",
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
    call = _WINDOW_CALL_RE.search(line)
    if call and kind == "_NL" and call.group(2) not in ("min", "max", "abs", "sqrt"):
        hints.append(f"`{call.group(2)} (` reads as a call: put a window bound over parameters in parentheses, "
                     f"`{call.group(1)} ({call.group(2)}) (...)`")
    return hints


# `always within t_end (x > 1 m)`: the bound and the parenthesis read as a call `t_end(...)`.
_WINDOW_CALL_RE = re.compile(r"\b(within|after)\s+([A-Za-z_]\w*)\s*\(")


_DEFINITION_LINE = re.compile(r"\s*(agent\s+\w+\s+\w+|ego\s+(car|truck)\b|param\s+\w+\s*=|road\s+\w+\s+(\{|import)|"
                              r"(faults|expect|sweep|environment)\s*\{|(assume|keep)\s|include\s+\")")
_DEFINITION_OPENER = re.compile(r"\s*(road|agent|ego|faults|expect|sweep|environment)\b")


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


def check_source(data: bytes | str, path: str, sink: DiagnosticSink, max_bytes: int = MAX_SOURCE_BYTES) -> str | None:
    if isinstance(data, bytes):
        if len(data) > max_bytes:
            sink.error("E0003", f"source is too large ({len(data)} bytes; limit source_bytes = {max_bytes})",
                       Span.point(path, 1, 1), "raise it with `--max source_bytes=N` (docs/limits.md)")
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
        if len(text) > max_bytes:
            sink.error("E0003", f"source is too large ({len(text)} characters; limit source_bytes = {max_bytes})",
                       Span.point(path, 1, 1), "raise it with `--max source_bytes=N` (docs/limits.md)")
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


class Recovery:
    """The `on_error` callback of lark: report, skip to a statement end, resynchronise."""

    def __init__(self, lark: Lark, text: str, path: str, sink: DiagnosticSink):
        self.lark = lark
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
        report_syntax_error(self.lark, exc, self.path, self.sink, self.text)

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


# Words that open a block (`expect {`); a line `WORD {` with another word is a misspelt one.
_BLOCK_WORDS = ("faults", "expect", "sweep", "lights", "environment", "sequence", "parallel")
_BLOCK_LINE = re.compile(r"\s*([A-Za-z_]\w*)\s*\{\s*(#.*)?")


def _misspelt_block(token: Token, text: str, path: str, sink: DiagnosticSink) -> bool:
    """`expcet {`: the parser reads the word as a name and fails at '{', listing tokens; say
    which block was meant instead (E0005)."""
    if str(token) != "{" or token.line is None:
        return False
    lines = text.splitlines()
    line = lines[token.line - 1] if 0 < token.line <= len(lines) else ""
    m = _BLOCK_LINE.fullmatch(line)
    if m is None or m.group(1) in _BLOCK_WORDS:
        return False
    word = m.group(1)
    close = difflib.get_close_matches(word.lower(), _BLOCK_WORDS, n=1, cutoff=0.6)
    notes = [f"did you mean `{close[0]}`?"] if close else []
    notes.append("blocks: " + ", ".join(f"`{w} {{`" for w in _BLOCK_WORDS))
    start = m.start(1) + 1
    sink.error("E0005", f"`{word}` does not open a block", Span(path, token.line, start, token.line,
                                                                    start + len(word)),
               *notes, label="not a block keyword")
    return True


def _named_light_step(token: Token, text: str, path: str, sink: DiagnosticSink) -> bool:
    """`to_red: at 3 s light west state red` inside `lights { }`: only an actor's steps have
    names (what `started(A.step)`/`ended(A.step)` read)."""
    if str(token) != ":" or token.line is None:
        return False
    opened = _open_brace_at(text, token.line)
    if opened is None or not re.match(r"\s*lights\s*\{", opened[2]):
        return False
    lines = text.splitlines()
    line = lines[token.line - 1] if 0 < token.line <= len(lines) else ""
    label = line[:token.column - 1].strip()
    rest = line[token.column:].strip()
    sink.error("E0001", f"a step in `lights` cannot be named (`{label}:`)",
               Span(path, token.line, token.column - len(label), token.line, token.column + 1),
               f"write `{rest}`" if rest else "write the step without its name",
               "only an actor's steps have names, which `started(A.step)` and `ended(A.step)` read; "
               "`light(C)` reads a controller's state", label="a name here")
    return True


def report_syntax_error(lark: Lark, exc: UnexpectedInput, path: str, sink: DiagnosticSink, text: str = "") -> None:
    """One syntax error as a diagnostic: what was found, what the grammar expected there,
    and a curated hint for common slips (a unit typo, `=` for `==`, a missing '}')."""
    line = getattr(exc, "line", 1) or 1
    col = getattr(exc, "column", 1) or 1
    ip = getattr(exc, "interactive_parser", None)
    try:
        expected = _acceptable(ip.parser_state) if ip is not None else set(getattr(exc, "expected", ()) or ())
    except Exception:  # noqa: BLE001 - expected words are a courtesy
        expected = set(getattr(exc, "expected", ()) or ())
    words = _expected_words(lark, expected)
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
    if _misspelt_block(token, text, path, sink) or _named_light_step(token, text, path, sink):
        return
    shown = "end of line" if token.type == "_NL" else repr(str(token))
    notes = _curated_hint(token, expected, text)
    if words:
        notes.append("expected " + ", ".join(words[:14]) + (" ..." if len(words) > 14 else ""))
    width = max(1, len(str(token))) if token.type != "_NL" else 1
    sink.error("E0001", f"unexpected {shown}", Span(path, line, col, line, col + width), *notes)
