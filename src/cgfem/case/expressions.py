"""Safe arithmetic expressions in ``x, y, z`` for case files (our own parser, no ``eval``).

Grammar (Python precedence; ``**`` is right-associative and binds tighter than a unary sign
on its left, so ``-2**2 == -4`` and ``2**3**2 == 512``)::

    expr    := term (('+' | '-') term)*
    term    := unary (('*' | '/') unary)*
    unary   := ('+' | '-') unary | power
    power   := primary ('**' unary)?
    primary := NUMBER | 'x' | 'y' | 'z' | FUNC '(' expr ')' | '(' expr ')'
    FUNC    := 'sin' | 'cos' | 'exp' | 'sqrt'

The exponent of ``**`` must be a constant (numbers only) with ``|exponent| <= 64``; constant
subexpressions are folded at parse time and must be finite. Anything else (other names,
attribute access, strings, commas, ``//``, ``%``, ...) raises :class:`~cgfem.errors.InputError`
naming the character position. The parse tree is compiled once into nested closures over
numpy ufuncs; n-ary ``+ -`` and ``* /`` chains are evaluated in a loop, so the Python stack
depth of an evaluation is bounded by the nesting limit, not by the expression length.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

from cgfem.errors import InputError

__all__ = [
    "MAX_EXPONENT",
    "MAX_LENGTH",
    "MAX_DEPTH",
    "Expression",
    "VectorExpression",
    "as_expression",
    "as_vector_expression",
    "parse_expression",
]

#: Longest accepted expression, characters.
MAX_LENGTH = 2000
#: Deepest accepted nesting of parentheses, function calls and unary signs.
MAX_DEPTH = 100
#: Largest accepted |exponent| of ``**``.
MAX_EXPONENT = 64.0

VARIABLES = ("x", "y", "z")
FUNCTIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "sin": np.sin,
    "cos": np.cos,
    "exp": np.exp,
    "sqrt": np.sqrt,
}
_BINARY: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "+": np.add,
    "-": np.subtract,
    "*": np.multiply,
    "/": np.divide,
    "**": np.power,
}

_NUMBER = re.compile(r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_WORD = re.compile(r"[A-Za-z0-9_.]*")
_SHOWN = 80  # characters of the source quoted in error messages

#: evaluates a compiled (sub)expression on float64 arrays x, y, z
Evaluator = Callable[[np.ndarray, np.ndarray, np.ndarray], "np.ndarray | float"]


class _Token(NamedTuple):
    kind: str  # "num", "name", "op" or "end"
    text: str
    pos: int
    value: float = 0.0


@dataclass(frozen=True)
class _Compiled:
    """A compiled subexpression: its evaluator and, if it uses no variable, its value."""

    fn: Evaluator
    constant: float | None = None


def _shown(source: str) -> str:
    text = source if len(source) <= _SHOWN else source[: _SHOWN - 3] + "..."
    return repr(text)


class _Parser:
    """Recursive-descent parser compiling a token list into a :class:`_Compiled`."""

    def __init__(self, source: str, field: str) -> None:
        self.source = source
        self.field = field
        self.depth = 0
        self.tokens = self._tokenize()
        self.i = 0

    # -- errors and tokens -------------------------------------------------------------
    def error(self, what: str, pos: int, hint: str = "") -> InputError:
        message = f"{what} at position {pos} in expression {_shown(self.source)}"
        return InputError(self.field, f"{message} ({hint})" if hint else message)

    def _tokenize(self) -> list[_Token]:
        s, n, i = self.source, len(self.source), 0
        tokens: list[_Token] = []
        while i < n:
            c = s[i]
            if c in " \t\r\n":
                i += 1
            elif c in "0123456789" or (c == "." and i + 1 < n and s[i + 1] in "0123456789"):
                m = _NUMBER.match(s, i)
                assert m is not None
                if m.end() < n and _WORD.match(s, m.end()).group():
                    bad = s[i : _WORD.match(s, m.end()).end()]
                    raise self.error(f"malformed number {bad!r}", i)
                value = float(m.group())
                if not math.isfinite(value):
                    raise self.error(f"number {m.group()!r} overflows", i)
                tokens.append(_Token("num", m.group(), i, value))
                i = m.end()
            elif _NAME.match(s, i):
                name = _NAME.match(s, i).group()
                if name not in VARIABLES and name not in FUNCTIONS:
                    allowed = ", ".join((*VARIABLES, *FUNCTIONS))
                    raise self.error(f"unknown name {name!r}", i, f"allowed: {allowed}")
                tokens.append(_Token("name", name, i))
                i += len(name)
            elif s.startswith("**", i):
                tokens.append(_Token("op", "**", i))
                i += 2
            elif s.startswith("//", i) or c == "%":
                op = "//" if c == "/" else "%"
                raise self.error(f"operator {op!r} is not allowed", i)
            elif c in "+-*/()":
                tokens.append(_Token("op", c, i))
                i += 1
            elif c == ".":
                raise self.error("attribute access ('.') is not allowed", i)
            elif c == ",":
                raise self.error("commas are not allowed (functions take one argument)", i)
            elif c in "'\"":
                raise self.error("strings are not allowed", i)
            elif c in "[]{}":
                raise self.error(f"brackets {c!r} are not allowed", i)
            else:
                raise self.error(f"unexpected character {c!r}", i)
        tokens.append(_Token("end", "", n))
        return tokens

    def peek(self) -> _Token:
        return self.tokens[self.i]

    def take(self) -> _Token:
        token = self.tokens[self.i]
        self.i += 1
        return token

    def at(self, *ops: str) -> bool:
        token = self.peek()
        return token.kind == "op" and token.text in ops

    def enter(self, pos: int) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.error(f"expression nests deeper than {MAX_DEPTH} levels", pos)

    # -- grammar -----------------------------------------------------------------------
    def parse(self) -> _Compiled:
        if self.peek().kind == "end":
            raise InputError(self.field, f"empty expression {_shown(self.source)}")
        tree = self.expr()
        token = self.peek()
        if token.kind != "end":
            if token.text == ")":
                raise self.error("unbalanced parenthesis: ')' has no matching '('", token.pos)
            raise self.error(f"unexpected {token.text!r}", token.pos)
        return tree

    def expr(self) -> _Compiled:
        return self._chain(self.term, ("+", "-"))

    def term(self) -> _Compiled:
        return self._chain(self.unary, ("*", "/"))

    def _chain(self, operand: Callable[[], _Compiled], ops: tuple[str, str]) -> _Compiled:
        first = operand()
        rest: list[tuple[_Token, _Compiled]] = []
        while self.at(*ops):
            rest.append((self.take(), operand()))
        if not rest:
            return first
        # fold a constant prefix, then evaluate the remaining operands in a loop
        head = first
        while rest and head.constant is not None and rest[0][1].constant is not None:
            op, right = rest.pop(0)
            head = self._fold(op, head, right)
        if not rest:
            return head
        steps = tuple((_BINARY[op.text], right.fn) for op, right in rest)
        head_fn = head.fn

        def chain(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray | float:
            value = head_fn(x, y, z)
            for ufunc, fn in steps:
                value = ufunc(value, fn(x, y, z))
            return value

        return _Compiled(chain)

    def unary(self) -> _Compiled:
        if not self.at("+", "-"):
            return self.power()
        sign = self.take()
        self.enter(sign.pos)
        operand = self.unary()
        self.depth -= 1
        if sign.text == "+":
            return operand
        if operand.constant is not None:
            return _constant(-operand.constant)
        fn = operand.fn
        return _Compiled(lambda x, y, z: np.negative(fn(x, y, z)))

    def power(self) -> _Compiled:
        base = self.primary()
        if not self.at("**"):
            return base
        op = self.take()
        self.enter(op.pos)
        exponent = self.unary()
        self.depth -= 1
        if exponent.constant is None:
            raise self.error("the exponent of '**' must be a constant (numbers only)", op.pos)
        if abs(exponent.constant) > MAX_EXPONENT:
            raise self.error(
                f"exponent {exponent.constant:g} of '**' exceeds {MAX_EXPONENT:g} in magnitude", op.pos
            )
        if base.constant is not None:
            return self._fold(op, base, exponent)
        fn, p = base.fn, exponent.constant
        return _Compiled(lambda x, y, z: np.power(fn(x, y, z), p))

    def primary(self) -> _Compiled:
        token = self.take()
        if token.kind == "num":
            return _constant(token.value)
        if token.kind == "name" and token.text in VARIABLES:
            if self.at("("):
                raise self.error(f"{token.text!r} is not a function", token.pos)
            index = VARIABLES.index(token.text)
            return _Compiled(lambda x, y, z: (x, y, z)[index])
        if token.kind == "name":
            if not self.at("("):
                raise self.error(f"function {token.text!r} must be called as {token.text}(...)", token.pos)
            argument = self.group(self.take())
            ufunc = FUNCTIONS[token.text]
            if argument.constant is not None:
                with np.errstate(all="ignore"):
                    value = float(ufunc(np.float64(argument.constant)))
                if not math.isfinite(value):
                    raise self.error(f"{token.text}({argument.constant:g}) is not finite", token.pos)
                return _constant(value)
            fn = argument.fn
            return _Compiled(lambda x, y, z: ufunc(fn(x, y, z)))
        if token.kind == "op" and token.text == "(":
            return self.group(token)
        if token.kind == "end":
            raise self.error("expression ends unexpectedly", token.pos)
        raise self.error(f"expected a number, x, y, z, a function call or '(', got {token.text!r}", token.pos)

    def group(self, opening: _Token) -> _Compiled:
        """The parenthesised expression after ``opening`` (already taken), with its ')'."""
        self.enter(opening.pos)
        if self.at(")"):
            raise self.error("empty parentheses", opening.pos)
        inner = self.expr()
        if not self.at(")"):
            token = self.peek()
            if token.kind == "end":
                raise self.error("unbalanced parenthesis: '(' is never closed", opening.pos)
            raise self.error(f"expected ')', got {token.text!r}", token.pos)
        self.take()
        self.depth -= 1
        return inner

    def _fold(self, op: _Token, left: _Compiled, right: _Compiled) -> _Compiled:
        assert left.constant is not None and right.constant is not None
        if op.text == "/" and right.constant == 0.0:
            raise self.error("division by zero", op.pos)
        with np.errstate(all="ignore"):
            value = float(_BINARY[op.text](np.float64(left.constant), np.float64(right.constant)))
        if not math.isfinite(value):
            what = f"{left.constant:g} {op.text} {right.constant:g}"
            raise self.error(f"constant {what} overflows or is undefined", op.pos)
        return _constant(value)


def _constant(value: float) -> _Compiled:
    return _Compiled(lambda x, y, z: value, value)


@dataclass(frozen=True)
class Expression:
    """A parsed scalar expression in ``x, y, z``; build it with :func:`parse_expression`.

    Calling it evaluates on arrays: ``expr(x, y, z)`` with ``x, y, z`` broadcastable
    returns a new float64 array of shape ``np.broadcast(x, y, z).shape`` (constants too).
    Equality and hashing use the source text only.
    """

    source: str
    _compiled: _Compiled = field(repr=False, compare=False)

    def __call__(self, x: np.ndarray | float, y: np.ndarray | float, z: np.ndarray | float) -> np.ndarray:
        xa = np.asarray(x, dtype=np.float64)
        ya = np.asarray(y, dtype=np.float64)
        za = np.asarray(z, dtype=np.float64)
        shape = np.broadcast(xa, ya, za).shape
        value = self._compiled.fn(xa, ya, za)
        return np.array(np.broadcast_to(value, shape), dtype=np.float64)

    @property
    def is_constant(self) -> bool:
        """Whether the expression uses none of ``x, y, z``."""
        return self._compiled.constant is not None

    @property
    def constant_value(self) -> float:
        """The value of a constant expression; ``ValueError`` if it depends on ``x, y, z``."""
        if self._compiled.constant is None:
            raise ValueError(f"expression {self.source!r} is not constant")
        return self._compiled.constant

    def __reduce__(self) -> tuple[Callable[[str], "Expression"], tuple[str]]:
        # closures do not pickle: rebuild from the source
        return (parse_expression, (self.source,))


def parse_expression(source: str, field: str = "expression") -> Expression:
    """Parse ``source``; any defect raises :class:`InputError` with ``field`` and the position."""
    if not isinstance(source, str):
        raise InputError(field, f"expected an expression string, got {source!r}")
    if len(source) > MAX_LENGTH:
        raise InputError(field, f"expression is longer than {MAX_LENGTH} characters ({len(source)})")
    return Expression(source, _Parser(source, field).parse())


def as_expression(value: object, field: str = "expression") -> Expression:
    """A number (int/float, not bool) as a constant expression, or a string parsed as one."""
    if isinstance(value, str):
        return parse_expression(value, field)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(field, f"expected a number or an expression string, got {value!r}")
    try:
        number = float(value)
    except OverflowError:
        raise InputError(field, f"number {value!r} is too large") from None
    if not math.isfinite(number):
        raise InputError(field, f"must be finite, got {value!r}")
    return Expression(repr(number), _constant(number))


@dataclass(frozen=True)
class VectorExpression:
    """Three expressions: the x, y and z components of a vector field.

    ``vec(x, y, z)`` returns a float64 array of shape ``np.broadcast(x, y, z).shape + (3,)``.
    """

    components: tuple[Expression, Expression, Expression]

    def __post_init__(self) -> None:
        components = tuple(self.components)
        if len(components) != 3 or not all(isinstance(c, Expression) for c in components):
            raise TypeError("VectorExpression needs exactly three Expression components")
        object.__setattr__(self, "components", components)

    def __call__(self, x: np.ndarray | float, y: np.ndarray | float, z: np.ndarray | float) -> np.ndarray:
        return np.stack([c(x, y, z) for c in self.components], axis=-1)

    @property
    def is_constant(self) -> bool:
        """Whether all three components are constant."""
        return all(c.is_constant for c in self.components)

    @property
    def constant_value(self) -> tuple[float, float, float]:
        """The constant vector; ``ValueError`` if a component depends on ``x, y, z``."""
        a, b, c = (e.constant_value for e in self.components)
        return (a, b, c)


def as_vector_expression(values: object, field: str) -> VectorExpression:
    """A list of 3 numbers or expression strings; errors name ``field[i]``."""
    if not isinstance(values, (list, tuple)) or len(values) != 3:
        raise InputError(field, f"expected a list of 3 numbers or expressions, got {values!r}")
    a, b, c = (as_expression(v, f"{field}[{i}]") for i, v in enumerate(values))
    return VectorExpression((a, b, c))
