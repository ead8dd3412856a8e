"""The suite's marker guard (tests/conftest.py) recognises simulator and flight commands."""

import sys

from tests.conftest import starts_a_flight, starts_python


def test_guard_recognises_flight_commands() -> None:
    assert starts_a_flight([sys.executable, "-m", "sim", "demo.yaml"])
    assert starts_a_flight([sys.executable, "-m", "mexgen_gcs", "sitl", "m.yaml"])
    assert starts_a_flight(["/x/bin/mexgen-gcs", "fly", "m.yaml"])
    assert not starts_a_flight([sys.executable, "-m", "mexgen_gcs", "check", "m.yaml"])
    assert not starts_a_flight(["git", "grep", "sim"])
    assert starts_python([sys.executable, "-c", "pass"])
    assert starts_python(["/venv/bin/mexgen-gcs", "check", "m.yaml"])
    assert not starts_python(["git", "grep", "x"])
