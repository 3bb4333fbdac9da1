"""Shared helpers of the robustness tests.

``compiles``: the names of the programs XLA compiles during a test.

``bad_input(category, fn, *, match, exc=ValueError, value=...)`` runs ``fn()``, asserts that it
raises ``exc`` whose message matches ``match`` (``pytest.raises(..., match=...)``) and, when the
environment variable ``BLURTRAP_BAD_INPUT_LOG`` names a file, appends one JSON line
``{"category", "input", "error"}`` to it *after* the check passed. ``tally_bad_inputs.py``
turns that log into the table of ``tests/robustness/README.md``. Appending single short lines
is safe across pytest-xdist workers.
"""

import json
import os

import jax
import pytest

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


class CompileCounter:
    """Names of the functions XLA compiles while registered (``jax.monitoring``)."""

    def __init__(self):
        self.names: list[str] = []

    def __call__(self, event, duration, **kwargs):
        if event == COMPILE_EVENT:
            self.names.append(str(kwargs.get("fun_name", "?")))

    def reset(self):
        self.names.clear()


@pytest.fixture
def compiles():
    """A :class:`CompileCounter` listening for the duration of the test."""
    counter = CompileCounter()
    jax.monitoring.register_event_duration_secs_listener(counter)
    yield counter
    jax.monitoring.unregister_event_duration_listener(counter)


def _log(category: str, value, message: str) -> None:
    path = os.environ.get("BLURTRAP_BAD_INPUT_LOG")
    if not path:
        return
    line = json.dumps(
        {"category": category, "input": repr(value)[:300], "error": message[:400]},
        ensure_ascii=True,
    )
    with open(path, "a", encoding="utf-8") as f:
        f.write(line + "\n")


@pytest.fixture
def bad_input():
    def check(category: str, fn, *, match: str, exc=ValueError, value=None):
        with pytest.raises(exc, match=match) as info:
            fn()
        _log(category, value, str(info.value))
        return info.value

    check.record = _log  # for errors already caught and checked by the test itself
    return check
