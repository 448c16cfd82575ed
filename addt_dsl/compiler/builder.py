"""The AST builder: lark calls its methods as it reduces (`Lark(..., transformer=...)`),
so the frozen dataclasses of `compiler.ast` are built directly, with spans computed from
the tokens (no intermediate parse tree, no position propagation: about half the parse
time). Syntax errors are not its business (`compiler.recovery`).
"""

from __future__ import annotations

import dataclasses

from lark import Token

from addt_dsl.compiler import ast
from addt_dsl.diagnostics import Span

MAX_EXPR_DEPTH = 200  # operators chained or nested in one expression


# Named keyword tokens the grammar keeps only for their position: dropped before a rule's
# builder sees its children.
_POSITION_ONLY = frozenset({
    "INCLUDE", "SCENARIO", "ROAD", "IMPORT", "PARAM", "ASSUME", "KEEP", "AGENT", "AHEAD", "BEHIND",
    "LANE", "AT", "AFTER", "WHEN", "SET", "FAULTS", "DURING", "FROM", "EXPECT", "NO", "STAY", "REACH",
    "SWEEP", "GRID", "CASES", "REPEAT", "SEED", "MAX_REJECTIONS", "WITHIN", "LSQB", "LIGHTS", "END", "VARIABLES",
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


class Builder:
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
                # `_bounds` of the first and last positioned child, with its two common
                # cases (a token, an AST node) inlined: this runs for every reduction.
                first = None
                for c in children:
                    if c.__class__ is Token:
                        if c.line is not None:
                            first = (c.line, c.column)
                            break
                    else:
                        s = getattr(c, "span", None)
                        if s is not None:
                            first = (s.line, s.col)
                            break
                        b = _bounds(c)
                        if b is not None:
                            first = b[0]
                            break
                if first is None:
                    span = Span.point(self.path, 1, 1)
                else:
                    for c in reversed(children):
                        if c.__class__ is Token:
                            if c.line is not None:
                                last = (c.end_line or c.line, c.end_column or c.column + len(c))
                                break
                        else:
                            s = getattr(c, "span", None)
                            if s is not None:
                                last = (s.end_line, s.end_col)
                                break
                            b = _bounds(c)
                            if b is not None:
                                last = b[1]
                                break
                    span = Span(self.path, first[0], first[1], last[0], last[1])
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

    def literal(self, tok: Token) -> ast.Bool:
        """`true` / `false` standing alone (an expression that is one token, no rule)."""
        return ast.Bool(self._tspan(tok), tok.type == "TRUE")

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
        routes = [h for h in head if isinstance(h, ast.Route)]
        clauses = tuple(b for b in block if isinstance(b, ast.Clause))
        steps = tuple(b for b in block if isinstance(b, (ast.Step, ast.Group)))
        block_settings = tuple(b for b in block if isinstance(b, ast.Setting))
        return ast.ActorDecl(span, name, is_ego, str(vehicle), self._tspan(vehicle),
                             settings, clauses, steps, block_settings, placements,
                             routes[-1] if routes else None)

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

    def b_route(self, span, items):
        stops = [i for i in items if isinstance(i, _Marked)]
        return ast.Route(span, tuple(st.value for st in stops), tuple(st.span for st in stops))

    def b_route_stop(self, span, items):
        tok = items[0]
        return _Marked(span, "route_stop", _unquote(tok) if isinstance(tok, ast.Str) else str(tok))

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
        edge = None
        if isinstance(items[0], Token) and items[0].type in ("RISING", "FALLING", "CHANGING"):
            edge, items = str(items[0]), items[1:]
        repeat = delay = None
        if isinstance(items[-1], _Marked) and items[-1].kind == "repeat":
            repeat, items = items[-1].value, items[:-1]
        if len(items) >= 3 and isinstance(items[-2], Token) and items[-2].type == "DELAY":
            delay, items = items[-1], items[:-2]
        return ast.StepStart(span, "when", items[0], items[1] if len(items) > 1 else None, edge, delay, repeat)

    def b_group(self, span, items):
        return ast.Group(span, str(items[0]), tuple(items[1:]))

    def b_labelled(self, span, items):
        label, item = items
        return dataclasses.replace(item, span=span, label=label.value, label_span=label.span)

    def b_step_repeat(self, span, items):
        return _Marked(span, "repeat", items[-1])

    def b_end_when(self, span, items):
        return ast.EndWhen(span, tuple(i for i in items if isinstance(i, ast.StepStart)))

    # ---- traffic lights
    def b_lights(self, span, items):
        return ast.Block(span, "lights", tuple(items))

    def b_light_def(self, span, items):
        kind, name, settings = items
        return ast.LightDef(span, str(kind), self._tspan(kind), str(name), self._tspan(name), settings)

    # ---- environment
    def b_environment(self, span, items):
        return ast.Block(span, "environment", tuple(i for i in items if isinstance(i, (ast.EnvItem, ast.EnvStep))))

    def b_env_item(self, span, items):
        name, settings = items
        return ast.EnvItem(span, str(name), self._tspan(name), settings)

    def b_env_name(self, span, items):
        return items[0]

    def b_env_step(self, span, items):
        return ast.EnvStep(span, tuple(i for i in items if isinstance(i, ast.StepStart)), items[-1])

    # ---- variables
    def b_variables(self, span, items):
        return ast.Block(span, "variables", tuple(i for i in items if isinstance(i, (ast.VarDef, ast.VarStep))))

    def b_var_def(self, span, items):
        name, value = items
        return ast.VarDef(span, str(name), self._tspan(name), value)

    def b_var_step(self, span, items):
        starts = tuple(i for i in items if isinstance(i, ast.StepStart))
        name, value = items[-2], items[-1]
        return ast.VarStep(span, starts, str(name), self._tspan(name), value)

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

    def b_when_time(self, span, items):
        edge = delay = length = None
        if isinstance(items[0], Token) and items[0].type in ("RISING", "FALLING", "CHANGING"):
            edge, items = str(items[0]), items[1:]
        condition, rest = items[0], list(items[1:])
        if rest and isinstance(rest[0], Token) and rest[0].type == "DELAY":
            delay, rest = rest[1], rest[2:]
        if rest:
            length = rest[0]
        return ast.Timing(span, "when", condition, None, length, edge, delay)

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

    def b_cases(self, span, items):
        columns = tuple(items)
        return ast.SweepItem(span, "cases", None, columns[0].value, columns)

    def b_case_column(self, span, items):
        return self.b_setting(span, items)

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
