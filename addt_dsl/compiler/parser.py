"""Source text → AST. Syntax errors become diagnostics, never tracebacks.

lark (LALR, contextual lexer) builds a parse tree with positions; `_ToAst` turns it
into the frozen dataclasses of `compiler.ast`. After a syntax error the parser skips to
the next line and goes on, so one run reports every broken statement.
"""

from __future__ import annotations

import functools
from pathlib import Path

from lark import Lark, Token, Transformer, Tree, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken

from addt_dsl.compiler import ast
from addt_dsl.diagnostics import DiagnosticSink, Span

GRAMMAR_PATH = Path(__file__).resolve().parent.parent / "grammar" / "addt.lark"
MAX_SOURCE_BYTES = 2_000_000
MAX_NESTING = 64
MAX_SYNTAX_ERRORS = 25


@functools.lru_cache(maxsize=1)
def grammar() -> Lark:
    return Lark.open(str(GRAMMAR_PATH), parser="lalr", lexer="contextual",
                     propagate_positions=True, maybe_placeholders=False, cache=False)


# Friendlier words for lark's terminal names in "expected ..." lists.
_TERMINAL_WORDS = {
    "NAME": "a name", "NUMBER": "a number", "STRING": "a string", "UNIT": "a unit",
    "_NL": "end of line", "LBRACE": "'{'", "RBRACE": "'}'", "LSQB": "'['", "RSQB": "']'",
    "LPAR": "'('", "RPAR": "')'", "COMMA": "','", "EQUAL": "'='", "COLON": "':'",
    "DOT": "'.'", "COMP": "a comparison", "ADD_OP": "'+' or '-'", "MUL_OP": "'*' or '/'",
    "MINUS": "'-'", "$END": "end of file",
}


def _expected_words(expected: set[str]) -> list[str]:
    words = []
    for name in sorted(expected):
        if name in _TERMINAL_WORDS:
            words.append(_TERMINAL_WORDS[name])
        elif name.startswith("__ANON") or name.startswith("_"):
            continue
        else:
            words.append(f"'{name.lower()}'")
    return sorted(set(words))


def _curated_hint(token: Token | None, expected: set[str]) -> str | None:
    """Messages for mistakes people actually make."""
    if token is None:
        return None
    value = str(token)
    if value == ":" and "NAME" not in expected:
        return "labels go before the formula: `name: always ...`"
    if token.type == "NAME" and "UNIT" in expected:
        return f"'{value}' is not a known unit; units are m, km, m/s, km/h, mph, s, ms, Hz, deg, rad, %, m/s^2, 1/m, kg"
    if value == "=" :
        return "settings are written `key value`, without '='; use '==' to compare"
    if value == "{" and "_NL" in expected:
        return "a block's '{' must be on the same line as its header"
    return None


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
            sink.error("E0003", "source is too large", Span.point(path, 1, 1))
            return None
    bad = next((i for i, ch in enumerate(text) if ch == "\x00" or (ord(ch) < 32 and ch not in "\t\r\n\f")), None)
    if bad is not None:
        line = text.count("\n", 0, bad) + 1
        col = bad - (text.rfind("\n", 0, bad) + 1) + 1
        sink.error("E0003", "source contains control characters or binary data",
                   Span.point(path, line, col))
        return None
    depth = max_depth = 0
    for i, ch in enumerate(text):
        if ch in "([{":
            depth += 1
            if depth > max_depth:
                max_depth = depth
                if depth > MAX_NESTING:
                    line = text.count("\n", 0, i) + 1
                    col = i - (text.rfind("\n", 0, i) + 1) + 1
                    sink.error("E0004", f"brackets nested deeper than {MAX_NESTING} levels",
                               Span.point(path, line, col))
                    return None
        elif ch in ")]}":
            depth = max(0, depth - 1)
    return text


def parse_source(data: bytes | str, path: str, sink: DiagnosticSink) -> ast.SourceFile | None:
    """Parse one file's contents; syntax errors go to `sink`; None if nothing usable."""
    text = _check_source(data, path, sink)
    if text is None:
        return None
    if not text.endswith("\n"):
        text += "\n"
    errors_seen: set[int] = set()

    def on_error(exc: UnexpectedInput) -> bool:
        line = getattr(exc, "line", 1) or 1
        if line not in errors_seen and len(errors_seen) < MAX_SYNTAX_ERRORS:
            errors_seen.add(line)
            _report_syntax_error(exc, path, sink)
        if len(errors_seen) >= MAX_SYNTAX_ERRORS:
            return False
        if isinstance(exc, UnexpectedToken):
            # Skip to the end of the line, then let the parser resync on it.
            ip = exc.interactive_parser
            try:
                if exc.token.type == "_NL":
                    return False
                for tok in ip.lexer_thread.lex(ip.parser_state):
                    if tok.type == "_NL":
                        ip.feed_token(tok)
                        break
                return True
            except UnexpectedInput:
                return False
            except Exception:  # noqa: BLE001 - recovery is best effort
                return False
        return isinstance(exc, UnexpectedCharacters)

    try:
        tree = grammar().parse(text, on_error=on_error)
    except UnexpectedInput as exc:
        if not sink.has_errors:
            _report_syntax_error(exc, path, sink)
        return None
    except RecursionError:
        sink.error("E0004", "source nested too deeply", Span.point(path, 1, 1))
        return None
    if errors_seen:
        return None
    try:
        return _ToAst(path).transform(tree)
    except RecursionError:
        sink.error("E0004", "source nested too deeply", Span.point(path, 1, 1))
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


def _report_syntax_error(exc: UnexpectedInput, path: str, sink: DiagnosticSink) -> None:
    line = getattr(exc, "line", 1) or 1
    col = getattr(exc, "column", 1) or 1
    if isinstance(exc, UnexpectedEOF) or (isinstance(exc, UnexpectedToken) and exc.token.type == "$END"):
        words = _expected_words(set(getattr(exc, "expected", ()) or ()))
        sink.error("E0002", "unexpected end of file", Span.point(path, line, col),
                   *([f"expected {', '.join(words)}"] if words else []),
                   "is a closing '}' missing?")
        return
    if isinstance(exc, UnexpectedCharacters):
        ch = exc.char
        sink.error("E0001", f"unexpected character {ch!r}", Span.point(path, line, col),
                   label="not part of the language")
        return
    assert isinstance(exc, UnexpectedToken)
    token = exc.token
    expected = set(exc.expected or ())
    shown = "end of line" if token.type == "_NL" else repr(str(token))
    notes = []
    hint = _curated_hint(token, expected)
    if hint:
        notes.append(hint)
    words = _expected_words(expected)
    if words:
        notes.append("expected " + ", ".join(words[:12]) + (" ..." if len(words) > 12 else ""))
    width = max(1, len(str(token))) if token.type != "_NL" else 1
    sink.error("E0001", f"unexpected {shown}",
               Span(path, line, col, line, col + width), *notes)


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
        return ast.AssumeDecl(self._span(meta), items[0])

    # ---- actors
    @v_args(meta=True)
    def actor(self, meta, items):
        if isinstance(items[0], Token) and items[0].type == "EGO":
            is_ego, name, rest = True, "ego", items[1:]
        else:
            is_ego, name, rest = False, str(items[0]), items[1:]
        vehicle = rest[0]
        settings = rest[1]
        block = rest[2] if len(rest) > 2 else []
        clauses = tuple(b for b in block if isinstance(b, ast.Clause))
        triggers = tuple(b for b in block if isinstance(b, ast.Trigger))
        block_settings = tuple(b for b in block if isinstance(b, ast.Setting))
        return ast.ActorDecl(self._span(meta), name, is_ego, str(vehicle), self._tspan(vehicle),
                             settings, clauses, triggers, block_settings)

    def actor_block(self, items):
        return list(items)

    @v_args(meta=True)
    def clause(self, meta, items):
        kw, name, settings = items[0], items[1], items[2]
        block = tuple(items[3]) if len(items) > 3 else ()
        keyword = "behavior" if kw == "behaviour" else kw
        return ast.Clause(self._span(meta), keyword, str(name), self._tspan(name), settings, block)

    def clause_kw(self, items):
        return str(items[0])

    def clause_block(self, items):
        return list(items)

    @v_args(meta=True)
    def trigger(self, meta, items):
        return ast.Trigger(self._span(meta), items[0], items[1])

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
        return ast.Timing(self._span(meta), "at", items[0])

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
        if isinstance(body, tuple) and body[0] == "no":
            return ast.OracleDecl(self._span(meta), severity, label, None, body[1], body[2])
        return ast.OracleDecl(self._span(meta), severity, label, body)

    def severity(self, items):
        return ("severity", str(items[0]))

    def label(self, items):
        return ("label", str(items[0]))

    def no_clause(self, items):
        return ("no", str(items[0]), str(items[1]) if len(items) > 1 else None)

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


def _unquote(tok) -> str:
    if isinstance(tok, ast.Str):
        return tok.value
    text = str(tok)[1:-1]
    return text.encode("utf-8").decode("unicode_escape") if "\\" in text else text
