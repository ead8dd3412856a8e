"""Markers for the whole suite, so ``-m "not e2e"`` is exactly the suite without simulator
processes (docs/testing.md has the commands).

- A test that uses a fixture starting the simulator (``sim_factory``), a flight log flown by
  it (``demo_log``, ``pim_log``) or PX4 (``px4_factory``) is marked ``e2e`` here, so a new
  test cannot forget the marker.
- A test not marked ``e2e`` (or ``px4``/``slow``) that starts the simulator or a flight as a
  subprocess anyway (``python -m sim``, ``mexgen-gcs sitl|fly``) fails with a message saying
  so, and so does one that starts any other Python process unless it is marked ``long``: the
  fast command stays in-process.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator, Sequence
from typing import Any

import pytest

E2E_FIXTURES = frozenset({"sim_factory", "demo_log", "pim_log", "px4_factory"})
"""Fixtures that start a simulator (or PX4) process, directly or through another fixture."""
FLIGHT_COMMANDS = frozenset({"sitl", "fly"})


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if E2E_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.e2e)


def starts_python(args: Any) -> bool:
    """Whether a subprocess command line starts Python (or the installed command line)."""
    if isinstance(args, str | bytes) or not isinstance(args, Sequence) or not args:
        return False
    first = str(args[0])
    return first == sys.executable or first.endswith(("python", "python3", "mexgen-gcs"))


def starts_a_flight(args: Any) -> bool:
    """Whether a subprocess command line starts the simulator or a flight."""
    if isinstance(args, str | bytes):
        return False  # shell strings: none in this suite
    argv = [str(a) for a in args] if isinstance(args, Sequence) else [str(args)]
    for i, a in enumerate(argv[:-1]):
        if a == "-m" and argv[i + 1] == "sim":
            return True
        if (a.endswith("mexgen-gcs") or (a == "-m" and argv[i + 1] == "mexgen_gcs")) and (
                FLIGHT_COMMANDS & set(argv[i + 1:i + 3])):
            return True
    return False


@pytest.fixture(autouse=True)
def _no_flight_subprocess_outside_e2e(request: pytest.FixtureRequest,
                                      monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    marked = {m for m in ("e2e", "long", "px4", "slow") if request.node.get_closest_marker(m)}
    if marked & {"e2e", "px4", "slow"}:
        yield
        return
    real_init = subprocess.Popen.__init__

    def guarded(self: subprocess.Popen[Any], args: Any, *a: Any, **kw: Any) -> None:
        if starts_a_flight(args):
            pytest.fail(f"{request.node.nodeid} starts {args!r}: a simulator or flight "
                        "process; mark the test e2e (tests/conftest.py)", pytrace=False)
        if starts_python(args) and not marked:
            pytest.fail(f"{request.node.nodeid} starts {args!r}: a Python process; mark the "
                        "test long (tests/conftest.py)", pytrace=False)
        real_init(self, args, *a, **kw)

    monkeypatch.setattr(subprocess.Popen, "__init__", guarded)
    yield

