"""``fields.excerpt``, how every error message shows a user's value: ``repr`` itself for a short value, a bounded
one-line excerpt for any other, at a cost bounded by what it shows (a shared structure of 9 ** 12 leaves, which
``repr`` could never print, takes no longer than a short list)."""

from __future__ import annotations

import numpy as np
import pytest

from quad_uneven_env.fields import EXCERPT_CHARS, Param, clip, excerpt


@pytest.mark.parametrize(
    "value", [0.5, -3, "abc", None, True, [0.5, 0.37, 0.1], (1, 2), {"a": 1, "b": [2, 3]}, float("nan")]
)
def test_a_short_value_reads_as_its_repr(value):
    assert excerpt(value) == repr(value)


def test_a_small_array_reads_as_its_list():
    assert excerpt(np.array([1.0, 2.0])) == "[1.0, 2.0]" and excerpt(np.array(2.5)) == "2.5"


def shared_tree(levels: int) -> list:
    """9 ** levels leaves in ``levels`` lists: each level holds the previous one 9 times (what YAML aliases make)."""
    node: list = [0.1] * 9
    for _ in range(levels - 1):
        node = [node] * 9
    return node


@pytest.mark.parametrize(
    ("value", "start"),
    [(list(range(10**6)), "[0, 1, 2, 3, 4, 5, ..."), ("x" * 10**6, "'xxxxx"),
     ({str(i): i for i in range(10**5)}, "{'0': 0, "), (shared_tree(12), "[[[[...], [...], "),
     (np.zeros((2000, 2000)), "array([[0., 0., ..., 0., 0.], "),
     ("line one\nline two\n" * 1000, "'line one\\nline two"), (10**400, "10000")],
    ids=["long list", "long string", "many keys", "shared tree", "large array", "many lines", "huge int"],
)  # fmt: skip
def test_a_large_value_gives_a_short_line(value, start):
    text = excerpt(value)
    assert len(text) <= EXCERPT_CHARS and "\n" not in text
    assert text.startswith(start), text


def test_a_field_error_quotes_an_excerpt():
    with pytest.raises(ValueError) as err:
        Param("gap", 0.1, "m", "", lo=0.0).check(list(range(10**6)), "terrain")
    assert str(err.value) == "terrain.gap must be a number in [0, inf) (m), got [0, 1, 2, 3, 4, 5, ...] of type list"


def test_clip_keeps_a_short_text_and_cuts_a_long_one():
    assert clip("pickle data was truncated") == "pickle data was truncated"
    assert clip("a\n  b") == "a b"
    cut = clip("y" * 1000, 50)
    assert len(cut) == 50 and cut.endswith("...")
