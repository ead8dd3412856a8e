"""Benchmarks (`mexgen-gcs bench filter|planner [--json]`): measured, never asserted in tests.

``bench.timing`` times calls, ``bench.filter`` and ``bench.planner`` are the benchmarks,
``bench.cli`` the command.
"""
