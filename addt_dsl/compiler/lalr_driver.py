"""A faster loop over lark's own LALR tables and contextual lexers, for source that parses.

Lark's LALR parser spends most of a parse in per-token Python plumbing (a lexer generator
per state, a LineCounter, a ParserState method per token, an action lookup that re-reads
its configuration). `Driver.parse` runs the same algorithm in one loop over the very
objects lark built: the parse table, the per-state lexers' compiled scanners and
callbacks, and the rule callbacks (our AST builders behind lark's child filters). Same
tokens (type, value, positions), same reductions in the same order, same callbacks: the
same AST. It has no error handling at all: at the first token that does not fit (or
characters no terminal matches) it raises `NotParsed`, and `parser.parse_source` parses
the file again with lark, whose error recovery reports the diagnostics exactly as before.
tests/unit/compiler/test_lalr_driver.py checks that both agree on every example, every
compiler case file and generated programs.
"""

from __future__ import annotations

from lark import Lark, Token
from lark.parse_tree_builder import ExpandSingleChild
from lark.parsers.lalr_analysis import Shift

# Token(type, value, ...) without its two Python-level constructor calls (lark's
# `Token._future_new` does exactly this: str.__new__, then the eight slots).
_new_str = str.__new__


class NotParsed(Exception):
    """The source does not parse cleanly: parse it with lark for the diagnostics."""


class Driver:
    def __init__(self, lark: Lark, start: str = "start"):
        frontend = lark.parser
        parser = frontend.parser.parser  # lark.parsers.lalr_parser._Parser
        table = parser.parse_table
        callbacks = parser.callbacks
        self.start_state = table.start_states[start]
        self.end_state = table.end_states[start]
        # state -> terminal -> (shift?, next state) or (shift?, rule size, rule name, callback);
        # a rule of one symbol whose callback is lark's ExpandSingleChild (a `?rule` such as
        # the steps of the expression precedence chain) reduces to its child: size 0 marks it
        # (its value stays on the stack, only the state changes).
        actions = {}
        for state, row in table.states.items():
            out = {}
            for term, (action, arg) in row.items():
                if action is Shift:
                    out[term] = (True, arg, None, None)
                else:
                    callback = callbacks[arg]
                    size = len(arg.expansion)
                    if size == 1 and type(callback) is ExpandSingleChild:
                        out[term] = (False, -1, arg.origin.name, None)
                    else:
                        out[term] = (False, size, arg.origin.name, callback)
            actions[state] = out
        self.actions = actions
        self.token_callbacks = {name: cb for name, cb in callbacks.items() if isinstance(name, str)}
        # state -> (match functions of the compiled scanners, token callbacks, ignored types,
        # types that may hold newlines)
        lexers = {}
        shared = {}
        for state, lexer in frontend.lexer.lexers.items():
            key = id(lexer)
            if key not in shared:
                scanner = lexer.scanner  # builds lexer.callback too
                shared[key] = (tuple(mre.match for mre in scanner._mres), dict(lexer.callback),
                               lexer.ignore_types, lexer.newline_types)
            lexers[state] = shared[key]
        self.lexers = lexers

    def parse(self, text: str):
        """The value of the start rule for `text`, or NotParsed."""
        actions, lexers, token_callbacks = self.actions, self.lexers, self.token_callbacks
        end_state = self.end_state
        state_stack = [self.start_state]
        value_stack = []
        push_state, push_value = state_stack.append, value_stack.append
        pos, line, line_start, end = 0, 1, 0, len(text)
        token = None
        while True:
            # ---- the next token, lexed by the lexer of the current state (BasicLexer.next_token)
            matchers, lex_callbacks, ignore_types, newline_types = lexers[state_stack[-1]]
            token = None
            while pos < end:
                for match in matchers:
                    m = match(text, pos)
                    if m:
                        break
                else:
                    raise NotParsed
                value, kind = m.group(0), m.lastgroup
                ignored = kind in ignore_types
                if ignored and kind not in lex_callbacks:  # skipped: no token made
                    if kind in newline_types:
                        newlines = value.count("\n")
                        if newlines:
                            line += newlines
                            line_start = pos + value.rindex("\n") + 1
                    pos += len(value)
                    continue
                t = _new_str(Token, value)
                t.type, t.start_pos, t.value, t.line, t.column = kind, pos, value, line, pos - line_start + 1
                if kind in newline_types:
                    newlines = value.count("\n")
                    if newlines:
                        line += newlines
                        line_start = pos + value.rindex("\n") + 1
                pos += len(value)
                t.end_line = line
                t.end_column = pos - line_start + 1
                t.end_pos = pos
                if kind in lex_callbacks:
                    t = lex_callbacks[kind](t)
                if not ignored:
                    token = t
                    break
            if token is None:
                break
            # ---- feed it (ParserState.feed_token): reduce as the table says, then shift
            kind = token.type
            while True:
                step = actions[state_stack[-1]].get(kind)
                if step is None:
                    raise NotParsed
                shift, arg, origin, callback = step
                if shift:
                    push_state(arg)
                    push_value(token if kind not in token_callbacks else token_callbacks[kind](token))
                    break
                if arg < 0:  # one child, passed up as it is
                    state_stack[-1] = actions[state_stack[-2]][origin][1]
                    continue
                if arg:
                    children = value_stack[-arg:]
                    del state_stack[-arg:]
                    del value_stack[-arg:]
                else:
                    children = []
                value = callback(children)
                push_state(actions[state_stack[-1]][origin][1])
                push_value(value)
        # ---- end of input: reduce until the start rule is accepted
        while True:
            step = actions[state_stack[-1]].get("$END")
            if step is None or step[0]:
                raise NotParsed
            _, arg, origin, callback = step
            if arg < 0:
                state_stack[-1] = actions[state_stack[-2]][origin][1]
                if state_stack[-1] == end_state:
                    return value_stack[-1]
                continue
            if arg:
                children = value_stack[-arg:]
                del state_stack[-arg:]
                del value_stack[-arg:]
            else:
                children = []
            value = callback(children)
            push_state(actions[state_stack[-1]][origin][1])
            push_value(value)
            if state_stack[-1] == end_state:
                return value_stack[-1]
