"""Calling a compiled (numba) kernel without its dispatcher's per-call type resolution.

A numba dispatcher types every argument at every call before it picks the compiled version: ~0.04 µs an
array, ~0.5 µs a structref (whose type it asks Python for). For a kernel called at every physics step with
the same buffers, that is more than the Python around it. The compiled version's entry point unboxes the
arguments without typing them, so it must only ever receive arguments of the types it was compiled for: a
caller keeps it together with the objects that fix those types (the same arrays, the same records) and goes
back to the dispatcher when one of them changes. ``tests/quad_uneven_env/test_compiled_call.py`` checks it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any


def entry_point(kernel: Any, args: Sequence[Any]) -> Callable[..., Any] | None:
    """The entry point of ``kernel``'s version compiled for the numba types of ``args``, or None (not compiled
    for them yet: call ``kernel(*args)`` first; or ``kernel`` is not a numba dispatcher).

    :param kernel: a ``numba.njit`` function (its dispatcher).
    :param args: arguments of a call; the returned function takes arguments of exactly these types only (an
        array of another dtype, dimension, layout or writability is read as if it had them).
    """
    typeof, overloads = getattr(kernel, "typeof_pyval", None), getattr(kernel, "overloads", None)
    if typeof is None or overloads is None:
        return None
    try:
        signature = tuple(typeof(a) for a in args)
    except Exception:  # an argument numba cannot type: the dispatcher's call would raise too
        return None
    compiled = overloads.get(signature)
    return None if compiled is None else compiled.entry_point


def argument_type(kernel: Any, value: Any) -> Any:
    """The numba type ``kernel``'s dispatcher gives ``value`` as an argument (numba's ``pyobject`` for a value it
    cannot type), or None when ``kernel`` is not a numba dispatcher: to check that a new object (e.g. a new terrain's
    array) fits an entry point resolved before. Python-level typing, ~6 µs for an array (the dispatcher's own call
    types an array in C, ~0.04 µs): for a cache miss, not for every call."""
    typeof = getattr(kernel, "typeof_pyval", None)
    if typeof is None:
        return None
    try:
        return typeof(value)
    except Exception:  # numba refused to type it: nothing an entry point was compiled for
        return None
