"""The one exception hierarchy of mexgen-gcs.

Errors are raised deep down and caught only at boundaries (planner worker, mission controller,
command line), where they become an operator message, a safe action and a log record.
"""

from __future__ import annotations


class MexgenError(Exception):
    """Base of every error this package raises on purpose."""


class ConfigError(MexgenError):
    """A mission file or setting is wrong. The message names the file, the key and the fix."""


class EstimationError(MexgenError):
    """The estimation core was asked something it cannot do (e.g. zero particles)."""


class PlannerError(MexgenError):
    """Planning failed; the mission holds position and logs it."""


class WireError(MexgenError):
    """A datagram does not follow detection wire format v1. `reason` is the counter key."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


class VehicleError(MexgenError):
    """A vehicle command failed or timed out. Carries the call and the result."""

    def __init__(self, call: str, result: str) -> None:
        super().__init__(f"{call} failed: {result}")
        self.call = call
        self.result = result


class LogFormatError(MexgenError):
    """A flight log is of an unknown or newer format version, or not a flight log at all."""
