"""The field-trial terminal UI: one Textual app over a snapshot source (live or replay).

``build_app(source)`` makes the app (tests use it too). ``run_with_ui(controller)`` flies a
mission with the UI attached in the same event loop; ``run_replay(snapshots)`` plays a
recorded flight through the same panels. The app only reads immutable MissionSnapshots (at
the few hertz the mission publishes them) and sends commands through the source; widgets are
handed what they show and never reach into the app. Map frame: local ENU metres about home.
"""

from __future__ import annotations

import asyncio
import gc
import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

from textual import on, work
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal
from textual.driver import Driver
from textual.events import Key
from textual.widgets import Footer

from mexgen_gcs.io.snapshot import MissionSnapshot
from mexgen_gcs.mission.state import MissionState
from mexgen_gcs.ui.confirm_screen import ConfirmScreen
from mexgen_gcs.ui.event_log import EventLog
from mexgen_gcs.ui.map_view import MapView, scene_from_snapshot
from mexgen_gcs.ui.method_screen import MethodScreen
from mexgen_gcs.ui.planner_panel import PlannerPanel
from mexgen_gcs.ui.replay_bar import ReplayBar
from mexgen_gcs.ui.source import LiveSource, ReplaySource, SnapshotSource
from mexgen_gcs.ui.status_bar import StatusBar
from mexgen_gcs.ui.tags_table import TagsTable
from mexgen_gcs.ui.terminal_driver import nonblocking_driver_class
from mexgen_gcs.ui.terminal_logging import terminal_logging_held
from mexgen_gcs.ui.warning_banner import WarningBanner

if TYPE_CHECKING:
    from mexgen_gcs.mission.controller import MissionController, MissionResult

log = logging.getLogger(__name__)

MISSION_ACTIONS = frozenset({"pause", "resume", "rtl", "land", "abort", "method"})
DANGEROUS = {
    "rtl": "Return to launch now? The mission ends and the vehicle flies home and lands.",
    "land": "Land here, now? The mission ends and the vehicle descends where it is.",
    "abort": "Abort the mission? The vehicle returns to launch and lands.",
}
#: states in which the vehicle may be in the air and quitting must bring it home first
PRE_FLIGHT = ("connecting", "preflight")
#: states in which the mission no longer takes commands (the vehicle is returning or down)
MISSION_OVER = ("returning", "landed", "done")
DEFAULT_LINGER_S = 10.0
#: wall seconds after the UI starts when its objects are frozen out of the cyclic GC
FREEZE_AFTER_S = 2.0


class MexgenApp(App[None]):
    """Map, tags, planner, status and events for one snapshot source."""

    CSS_PATH = "app.tcss"
    TITLE = "mexgen-gcs"
    ENABLE_COMMAND_PALETTE = False
    # Textual declares these as instance variables of App, so no ClassVar here
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (100, "-wide")]  # noqa: RUF012
    VERTICAL_BREAKPOINTS = [(0, "-short"), (32, "-tall")]  # noqa: RUF012
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("p", "pause", "Pause"),
        Binding("c", "resume", "Resume"),
        Binding("r", "rtl", "RTL"),
        Binding("l", "land", "Land"),
        Binding("a", "abort", "Abort"),
        Binding("m", "method", "Method"),
        Binding("space", "replay('replay:toggle')", "Play/Pause"),
        Binding("n", "replay('replay:step')", "Step"),
        Binding("right_square_bracket", "replay('replay:faster')", "Faster"),
        Binding("left_square_bracket", "replay('replay:slower')", "Slower"),
        Binding("t", "truth", "Truth"),
        Binding("f", "next_tag", "Find tag", show=False),
        Binding("plus,equals_sign", "zoom(1)", "Zoom in", show=False),
        Binding("minus,underscore", "zoom(-1)", "Zoom out", show=False),
        Binding("up", "pan(0, 1)", "Pan", show=False, priority=True),
        Binding("down", "pan(0, -1)", "Pan", show=False, priority=True),
        Binding("left", "pan(-1, 0)", "Pan", show=False, priority=True),
        Binding("right", "pan(1, 0)", "Pan", show=False, priority=True),
        Binding("0", "fit", "Fit map", show=False),
        Binding("q", "quit", "Quit"),
        Binding("ctrl+q", "quit", "Quit", show=False, priority=True),
    ]

    def __init__(self, source: SnapshotSource, *, linger_s: float | None = DEFAULT_LINGER_S,
                 driver_class: type[Driver] | None = None) -> None:
        super().__init__(driver_class=driver_class)
        self.source = source
        self.linger_s = linger_s
        self.snapshot: MissionSnapshot | None = None
        self.ended = False
        self.quit_requested = False
        self._warnings: frozenset[str] = frozenset()
        self._truth_available = False
        self._tag_cursor = -1

    def get_driver_class(self) -> type[Driver]:
        base = super().get_driver_class()
        if base.__name__ == "LinuxDriver":
            return nonblocking_driver_class(base)
        return base

    # -- layout ------------------------------------------------------------------------------

    def compose(self) -> ComposeResult:
        yield WarningBanner(id="warnings")
        yield StatusBar(id="status")
        with Horizontal(id="main"):
            yield MapView(id="map")
            yield PlannerPanel(id="planner")
        yield TagsTable(id="tags")
        yield EventLog(id="events")
        if self.source.kind == "replay":
            yield ReplayBar(id="replay")
        yield Footer(compact=True)

    def on_mount(self) -> None:
        self.banner = self.query_one(WarningBanner)
        self.status_bar = self.query_one(StatusBar)
        self.map_view = self.query_one(MapView)
        self.planner = self.query_one(PlannerPanel)
        self.tags_table = self.query_one(TagsTable)
        self.event_log = self.query_one(EventLog)
        self.tags_table.can_focus = False
        self.event_log.can_focus = False
        self.title = "mexgen-gcs replay" if self.source.kind == "replay" else "mexgen-gcs"
        self.follow_snapshots()

    # -- snapshots in ------------------------------------------------------------------------

    @work(exclusive=True, group="snapshots")
    async def follow_snapshots(self) -> None:
        async for snap in self.source.snapshots():
            self.show_snapshot(snap)
        self.stream_ended()

    def show_snapshot(self, snap: MissionSnapshot) -> None:
        """Hand each panel its part of one snapshot."""
        if self.snapshot is None or snap.state != self.snapshot.state:
            self.call_after_refresh(self.refresh_bindings)
        self.snapshot = snap
        self.status_bar.show(snap)
        self.banner.show(snap.warnings, self._notice())
        self.map_view.show(scene_from_snapshot(snap))
        self.tags_table.show(snap.tags)
        self.planner.show(snap.plan, snap.method, snap.next_plan_in_s)
        self.event_log.show(snap.events)
        if isinstance(self.source, ReplaySource):
            self.query_one(ReplayBar).show(self.source.status())
        warnings = frozenset(snap.warnings)
        if warnings - self._warnings and self.source.kind == "live":
            self.bell()
        self._warnings = warnings
        if self.map_view.truth_available != self._truth_available:
            self._truth_available = self.map_view.truth_available
            self.refresh_bindings()

    def stream_ended(self) -> None:
        self.ended = True
        self.refresh_bindings()
        if isinstance(self.source, ReplaySource):
            self.query_one(ReplayBar).show(self.source.status())
            self.banner.show((), "REPLAY ENDED · q quits")
            return
        if self.quit_requested:
            self.exit()
            return
        self._refresh_notice()
        if self.linger_s is not None:
            self.set_timer(self.linger_s, self.exit)

    def _notice(self) -> str | None:
        snap = self.snapshot
        if self.ended and self.source.kind == "live":
            reason = snap.end_reason if snap is not None else None
            close = " · any key closes" + (f" (or in {self.linger_s:.0f} s)"
                                          if self.linger_s is not None else "")
            return f"MISSION ENDED: {reason or 'unknown'}{close}"
        if self.quit_requested:
            return "QUIT REQUESTED · returning home · the UI closes once landed"
        return None

    def _refresh_notice(self) -> None:
        self.banner.show(self.snapshot.warnings if self.snapshot else (), self._notice())

    def on_key(self, event: Key) -> None:
        if self.ended and self.source.kind == "live" and len(self.screen_stack) == 1:
            event.stop()
            self.exit()

    # -- commands out ------------------------------------------------------------------------

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if len(self.screen_stack) > 1:  # a dialog is open: its own keys only
            return False
        live = self.source.kind == "live"
        if action in MISSION_ACTIONS:
            if not live:
                return False
            over = self.snapshot is not None and self.snapshot.state in MISSION_OVER
            return None if (self.ended or self.quit_requested or over) else True
        if action == "replay":
            return not live
        if action == "truth":
            return True if self._truth_available else None
        return True

    def send(self, cmd: str) -> None:
        self.source.command(cmd)
        self.event_log.note(f"  operator → {cmd}")
        self.notify(f"sent: {cmd}", timeout=3)

    def action_pause(self) -> None:
        self.send("pause")

    def action_resume(self) -> None:
        self.send("resume")

    def _confirm_then_send(self, cmd: str) -> None:
        def answered(yes: bool | None) -> None:
            if yes:
                self.send(cmd)

        self.push_screen(ConfirmScreen(DANGEROUS[cmd], yes=cmd.upper()), answered)

    def action_rtl(self) -> None:
        self._confirm_then_send("rtl")

    def action_land(self) -> None:
        self._confirm_then_send("land")

    def action_abort(self) -> None:
        self._confirm_then_send("abort")

    def action_method(self) -> None:
        current = self.snapshot.method if self.snapshot is not None else "mexgen"

        def chosen(method: str | None) -> None:
            if method is not None and method != current:
                self.send(f"method:{method}")

        self.push_screen(MethodScreen(current), chosen)

    def action_replay(self, cmd: str) -> None:
        self.source.command(cmd)
        if isinstance(self.source, ReplaySource):
            self.query_one(ReplayBar).show(self.source.status())

    # -- the map -----------------------------------------------------------------------------

    def action_truth(self) -> None:
        on_ = self.map_view.toggle_truth()
        self.notify("true tag positions shown" if on_ else "true tag positions hidden",
                    timeout=2)

    def action_zoom(self, steps: int) -> None:
        self.map_view.zoom(steps)

    def action_pan(self, dx: int, dy: int) -> None:
        self.map_view.pan(dx, dy)

    def action_fit(self) -> None:
        self.map_view.reset_view()

    def action_next_tag(self) -> None:
        tags = self.snapshot.tags if self.snapshot is not None else ()
        if tags:
            self._tag_cursor = (self._tag_cursor + 1) % len(tags)
            tag = tags[self._tag_cursor]
            self.map_view.centre_on(tag.east_m, tag.north_m)
            self.tags_table.move_cursor(row=self._tag_cursor)

    @on(TagsTable.TagSelected)
    def centre_on_tag(self, message: TagsTable.TagSelected) -> None:
        self.map_view.centre_on(message.east_m, message.north_m)

    # -- quitting ----------------------------------------------------------------------------

    async def action_quit(self) -> None:
        if self.ended or self.source.kind == "replay":
            self.exit()
            return
        if self.quit_requested:
            self.notify("already returning home; the UI closes once landed", timeout=4)
            return
        snap = self.snapshot
        state = snap.state if snap is not None else MissionState.CONNECTING
        flying = snap is not None and (snap.telemetry.armed or snap.telemetry.in_air)
        if state == MissionState.RETURNING or (
                state in (MissionState.LANDED, MissionState.DONE) and not flying):
            question, cmd = "Close the UI once the vehicle has landed?", None
        elif state in PRE_FLIGHT and not flying:
            question, cmd = "Abort the mission (not yet armed) and quit?", "abort"
        else:
            question, cmd = ("Quit? The vehicle returns to launch and lands first; the UI "
                             "closes once it has landed.", "rtl")

        def answered(yes: bool | None) -> None:
            if not yes:
                return
            if cmd is not None:
                self.send(cmd)
            self.quit_requested = True
            self.refresh_bindings()
            self._refresh_notice()

        self.push_screen(ConfirmScreen(question, yes="QUIT"), answered)


def build_app(source: SnapshotSource, *, linger_s: float | None = DEFAULT_LINGER_S) -> MexgenApp:
    """The app over a source (LiveSource, ReplaySource or any SnapshotSource)."""
    return MexgenApp(source, linger_s=linger_s)


async def run_with_ui(controller: MissionController, *, headless: bool = False,
                      size: tuple[int, int] | None = None, auto_pilot: Any = None,
                      linger_s: float | None = DEFAULT_LINGER_S) -> MissionResult:
    """Fly `controller.run()` with the UI attached; returns its MissionResult.

    The mission and the UI are two tasks of one TaskGroup in the running loop. The UI task
    never raises: if the UI fails or is closed early the mission goes on without it. Quitting
    while flying commands RTL and the UI stays until the vehicle has landed.
    """
    over = asyncio.Event()
    source = LiveSource(controller, over)
    app = build_app(source, linger_s=linger_s)

    async def view() -> None:
        # Once the UI is up, its thousands of long-lived objects (widgets, styles, caches)
        # are frozen out of the cyclic collector: full collections then stay short instead
        # of stalling the shared loop for hundreds of milliseconds.
        freeze = asyncio.get_running_loop().call_later(FREEZE_AFTER_S, gc.freeze)
        try:
            with terminal_logging_held():
                await app.run_async(headless=headless, size=size, auto_pilot=auto_pilot)
        except (Exception, SystemExit) as exc:  # the view must never take the mission down
            log.error("terminal UI failed (%s: %s); the mission continues without it",
                      type(exc).__name__, exc)
        finally:
            freeze.cancel()
            gc.unfreeze()
        if not over.is_set():
            log.warning("the terminal UI closed before the mission ended; it continues "
                        "headless (Ctrl+C aborts: return to launch)")

    try:
        async with asyncio.TaskGroup() as tg:
            mission = tg.create_task(controller.run(), name="mission")
            mission.add_done_callback(lambda _task: over.set())
            tg.create_task(view(), name="ui")
    except ExceptionGroup as eg:
        raise eg.exceptions[0] from None
    return mission.result()


async def run_replay_async(snapshots: Sequence[MissionSnapshot], speedup: float = 1.0, *,
                           headless: bool = False, size: tuple[int, int] | None = None,
                           auto_pilot: Any = None) -> None:
    """Replay recorded snapshots through the same panels (space, n, [ and ] drive it)."""
    app = build_app(ReplaySource(snapshots, speedup), linger_s=None)
    with terminal_logging_held():
        await app.run_async(headless=headless, size=size, auto_pilot=auto_pilot)


def run_replay(snapshots: Sequence[MissionSnapshot], speedup: float = 1.0) -> None:
    """Blocking `run_replay_async` for the `replay` command."""
    asyncio.run(run_replay_async(snapshots, speedup))
