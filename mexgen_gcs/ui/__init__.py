"""The field-trial terminal UI (Textual): map, tags, planner, status, events and commands.

Entry points live in ``mexgen_gcs.ui.app``: ``run_with_ui(controller)`` for a live mission,
``run_replay(snapshots, speedup)`` for a recorded one, ``build_app(source)`` for tests.
Importing this package does not import Textual.
"""
