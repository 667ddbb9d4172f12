"""The safe expression parser: values against numpy references, and rejected inputs."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from cgfem.case.expressions import (
    MAX_DEPTH,
    Expression,
    VectorExpression,
    as_expression,
    as_vector_expression,
    parse_expression,
)
from cgfem.errors import InputError


@pytest.fixture
def xyz() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(20240611)
    return tuple(rng.uniform(0.1, 2.0, size=(4, 5)) for _ in range(3))


REFERENCES = [
    ("4e11*(0.01-z)*z", lambda x, y, z: 4e11 * (0.01 - z) * z),
    ("-4e11*(0.01-z)*z", lambda x, y, z: -4e11 * (0.01 - z) * z),
    ("sqrt(x*x+y*y)", lambda x, y, z: np.sqrt(x * x + y * y)),
    ("exp(-x)*sin(y)+cos(z)/3", lambda x, y, z: np.exp(-x) * np.sin(y) + np.cos(z) / 3),
    ("--x", lambda x, y, z: x),
    ("-+-x", lambda x, y, z: x),
    ("---x", lambda x, y, z: -x),
    ("x - y - z", lambda x, y, z: (x - y) - z),
    ("x / y / z", lambda x, y, z: (x / y) / z),
    ("x - y * z + x / y", lambda x, y, z: x - y * z + x / y),
    ("-x**2", lambda x, y, z: -(x**2)),
    ("x**-1.5", lambda x, y, z: x**-1.5),
    ("x**2**3", lambda x, y, z: x**8),
    ("(x + 1)**3 - 2*y", lambda x, y, z: (x + 1) ** 3 - 2 * y),
    ("1.5E-3*x + .5*y + 2.*z + 1e+2", lambda x, y, z: 1.5e-3 * x + 0.5 * y + 2.0 * z + 100.0),
    ("sin(cos(exp(sqrt(x))))", lambda x, y, z: np.sin(np.cos(np.exp(np.sqrt(x))))),
    ("2 + x - 3 + 4", lambda x, y, z: 2 + x - 3 + 4),
    ("1 - 2 - x", lambda x, y, z: -1 - x),
    (" \tx\n*\ty ", lambda x, y, z: x * y),
]


@pytest.mark.parametrize("source, reference", REFERENCES, ids=[s for s, _ in REFERENCES])
def test_values_match_numpy(source, reference, xyz) -> None:
    x, y, z = xyz
    value = parse_expression(source)(x, y, z)
    assert value.dtype == np.float64
    assert value.shape == (4, 5)
    np.testing.assert_allclose(value, reference(x, y, z), rtol=1e-14, atol=0.0)


@pytest.mark.parametrize(
    "source, value",
    [
        ("-2**2", -4.0),
        ("2**3**2", 512.0),
        ("(2**3)**2", 64.0),
        ("2**-1", 0.5),
        ("-(-3)", 3.0),
        ("7/2", 3.5),
        ("1 - 2 - 3", -4.0),
        ("2*3+4*5", 26.0),
        ("sqrt(16) + exp(0) + cos(0) - sin(0)", 6.0),
        ("4e11", 4e11),
        ("2**64", 2.0**64),
    ],
)
def test_constant_folding(source: str, value: float) -> None:
    expr = parse_expression(source)
    assert expr.is_constant
    assert expr.constant_value == value
    assert np.all(expr(np.zeros(2), 0.0, 0.0) == value)


def test_constants_broadcast_to_the_points() -> None:
    x = np.linspace(0.0, 1.0, 6).reshape(2, 3)
    value = parse_expression("3")(x, 0.0, np.zeros((1, 3)))
    assert value.shape == (2, 3)
    assert value.dtype == np.float64
    assert np.all(value == 3.0)
    value[0, 0] = 7.0  # a fresh, writable array
    assert parse_expression("3")(x, 0.0, 0.0)[0, 0] == 3.0


def test_variables_broadcast_against_each_other() -> None:
    x = np.array([1.0, 2.0, 3.0])
    z = np.array([[10.0], [20.0]])
    value = parse_expression("x + z")(x, 0.0, z)
    np.testing.assert_array_equal(value, [[11.0, 12.0, 13.0], [21.0, 22.0, 23.0]])
    assert parse_expression("y")(1.0, 5.0, 2.0).shape == ()


def test_non_constant_has_no_constant_value() -> None:
    expr = parse_expression("1 + x*0")
    assert not expr.is_constant
    with pytest.raises(ValueError):
        expr.constant_value


def test_as_expression_numbers_and_strings() -> None:
    assert as_expression(3, "f").constant_value == 3.0
    assert as_expression(-1.6e-6, "f").constant_value == -1.6e-6
    assert as_expression("2*x", "f")(1.5, 0.0, 0.0) == 3.0
    for bad in (True, None, [1.0], float("inf"), float("nan")):
        with pytest.raises(InputError) as info:
            as_expression(bad, "bodies.a.body_force[2]")
        assert info.value.field == "bodies.a.body_force[2]"


def test_vector_expression_shape_and_values() -> None:
    vec = as_vector_expression(["0", "4e11*(0.01-z)*z", 2.5], "value")
    z = np.array([0.0, 0.0025, 0.005])
    value = vec(0.0, 0.0, z)
    assert value.shape == (3, 3)
    np.testing.assert_allclose(value[:, 1], 4e11 * (0.01 - z) * z, rtol=1e-15)
    np.testing.assert_array_equal(value[:, 0], 0.0)
    np.testing.assert_array_equal(value[:, 2], 2.5)
    assert not vec.is_constant
    assert as_vector_expression([1, 2, "3*2"], "v").constant_value == (1.0, 2.0, 6.0)
    with pytest.raises(InputError) as info:
        as_vector_expression(["0", "0", "q"], "boundary[1].value")
    assert info.value.field == "boundary[1].value[2]"
    with pytest.raises(TypeError):
        VectorExpression((parse_expression("x"),) * 2)


def test_expressions_pickle_and_compare_by_source() -> None:
    expr = parse_expression("exp(-x)*y")
    again = pickle.loads(pickle.dumps(expr))
    assert again == expr
    assert again(1.0, 2.0, 0.0) == pytest.approx(2.0 * np.exp(-1.0), rel=1e-15)
    assert isinstance(again, Expression)


def test_deep_but_allowed_nesting() -> None:
    depth = MAX_DEPTH - 1
    expr = parse_expression("(" * depth + "x" + ")" * depth)
    assert expr(2.0, 0.0, 0.0) == 2.0


REJECTED = [
    ('__import__("os")', 0, "unknown name '__import__'"),
    ("os", 0, "unknown name 'os'"),
    ("t * x", 0, "unknown name 't'"),
    ("x + pi", 4, "unknown name 'pi'"),
    ("x.real", 1, "attribute access"),
    ("abs(x)", 0, "unknown name 'abs'"),
    ("log(x)", 0, "unknown name 'log'"),
    ("sin(x, y)", 5, "commas"),
    ("'x'", 0, "strings"),
    ("x[0]", 1, "brackets"),
    ("x // 2", 2, "'//'"),
    ("x % 2", 2, "'%'"),
    ("x + ", 4, "ends unexpectedly"),
    ("x y", 2, "unexpected 'y'"),
    ("(x + 1", 0, "never closed"),
    ("x + 1)", 5, "no matching '('"),
    ("1e999", 0, "overflows"),
    ("x**x", 1, "must be a constant"),
    ("x**65", 1, "exceeds 64"),
    ("2**-(100)", 1, "exceeds 64"),
    ("1e300**2", 5, "overflows"),
    ("1/0", 1, "division by zero"),
    ("sqrt(-1)", 0, "not finite"),
    ("sin", 0, "must be called"),
    ("x(2)", 0, "not a function"),
    ("sin()", 3, "empty parentheses"),
    ("2x", 0, "malformed number"),
    ("1.2.3", 0, "malformed number"),
    ("x = 1", 2, "unexpected character '='"),
    ("-" * (MAX_DEPTH + 1) + "x", MAX_DEPTH, "deeper than"),
    ("(" * (MAX_DEPTH + 1) + "x" + ")" * (MAX_DEPTH + 1), MAX_DEPTH, "deeper than"),
]


@pytest.mark.parametrize("source, position, words", REJECTED, ids=[s[:20] for s, _, _ in REJECTED])
def test_rejected_with_field_and_position(source: str, position: int, words: str) -> None:
    with pytest.raises(InputError) as info:
        parse_expression(source, "boundary[4].value[1]")
    error = info.value
    assert error.field == "boundary[4].value[1]"
    assert words in error.message
    assert f"at position {position} " in error.message
    assert "\n" not in str(error)


def test_rejected_without_position() -> None:
    for source, words in [("", "empty expression"), ("   ", "empty expression"), ("x+" * 1001, "longer than")]:
        with pytest.raises(InputError) as info:
            parse_expression(source, "f")
        assert info.value.field == "f"
        assert words in info.value.message


def test_long_flat_expression_evaluates_without_deep_recursion() -> None:
    source = "+".join(["x"] * 900)  # 1799 characters, 900 terms
    expr = parse_expression(source)
    assert expr(np.array([1.0, 2.0]), 0.0, 0.0).tolist() == [900.0, 1800.0]


def test_error_message_quotes_the_source() -> None:
    with pytest.raises(InputError) as info:
        parse_expression('__import__("os")', "f")
    assert str(info.value) == (
        "f: unknown name '__import__' at position 0 in expression '__import__(\"os\")' "
        "(allowed: x, y, z, sin, cos, exp, sqrt)"
    )
