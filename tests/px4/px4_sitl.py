"""Real PX4 SITL (with its SIH simulator) for tests and demos: start it, ride radios on it, stop it.

    with px4_sih(speed_factor=4.0, home=(-34.9212, 138.6011, 0.0)) as px4:
        # fly with MAVSDK on px4.mavsdk_url (PX4's offboard/API link, udp 14540+i)
        with radios_on(px4, MISSION, radio_port=14600, truth_dir=DIR):
            ...  # wire-format datagrams on the vehicle's clock arrive on udp 14600

``px4_sih`` starts ``px4`` headless on a fresh working directory (fresh parameters), with the
home placed by the SIH_LOC_* parameters, waits for "Ready for takeoff!", and always stops it
(SIGTERM, then SIGKILL) and deletes the directory with its ulog (150-400 MB per run).
``radios_on`` runs ``python -m sim MISSION --radios-only`` on PX4's GCS link (PX4 binds
18570+i and, once the radios talk to it, sends to them instead of 127.0.0.1:14550).

The PX4 binary: env ``PX4_SITL_BIN`` (``.../build/px4_sitl_default/bin/px4``; its ``../etc`` is
used), else ``DEFAULT_BUILD`` if it exists; ``find_px4()`` returns None otherwise and the
``px4`` tests skip. Instances: ``free_instance()`` picks i in 1..9 whose
ports are all free; instance i has MAVLink system id i + 1.
"""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mexgen_gcs.mission.run import free_udp_port
from tests.sim.sim_helpers import SimProcess, start_radios_only

#: Where PX4's own instructions leave a SITL build (a clone in the home directory).
DEFAULT_BUILD = Path("~/PX4-Autopilot/build/px4_sitl_default/bin/px4").expanduser()
READY_TEXT = "Ready for takeoff"
READY_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 15.0
#: PX4's own defaults for SIH (SIH_LOC_LAT0 / LON0 / H0): Zurich.
SIH_DEFAULT_HOME = (47.397742, 8.545594, 489.4)


def find_px4() -> Path | None:
    """The PX4 SITL binary: PX4_SITL_BIN, else the default build; None if there is none."""
    env = os.environ.get("PX4_SITL_BIN")
    path = Path(env).expanduser() if env else DEFAULT_BUILD
    ok = path.is_file() and os.access(path, os.X_OK) and (path.parent.parent / "etc").is_dir()
    return path if ok else None


def instance_ports(i: int) -> dict[str, int]:
    """UDP ports of PX4 instance i (ROMFS/px4fmu_common/init.d-posix/px4-rc.mavlink)."""
    return {"offboard_remote": 14540 + i, "offboard_local": 14580 + i, "gcs_local": 18570 + i,
            "payload_local": 14280 + i, "gimbal_local": 13030 + i, "sih_display": 19450 + i}


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def free_instance() -> int:
    """An instance number 1..9 whose ports are all free now (random order: fewer clashes)."""
    choices = list(range(1, 10))
    random.shuffle(choices)
    for i in choices:
        if all(_port_free(p) for p in instance_ports(i).values()):
            return i
    raise RuntimeError("no free PX4 instance (1..9): their UDP ports are taken")


@dataclass
class Px4Sitl:
    """A running PX4 SITL instance."""

    proc: subprocess.Popen[bytes]
    instance: int
    speed_factor: float
    home: tuple[float, float, float]
    workdir: Path
    log_path: Path
    started_wall_s: float = field(default_factory=time.monotonic)

    @property
    def sysid(self) -> int:
        return self.instance + 1

    @property
    def offboard_port(self) -> int:
        """PX4 sends its offboard/API link here (MAVSDK binds it)."""
        return 14540 + self.instance

    @property
    def mavsdk_url(self) -> str:
        return f"udpin://127.0.0.1:{self.offboard_port}"

    @property
    def gcs_link_port(self) -> int:
        """PX4's GCS link binds this port; it answers whoever talks to it first."""
        return 18570 + self.instance

    @property
    def gcs_link_url(self) -> str:
        """For ``python -m sim --radios-only --vehicle`` (or ``mavutil`` as ``udpout:``)."""
        return f"udpout:127.0.0.1:{self.gcs_link_port}"

    def log_text(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def alive(self) -> bool:
        return self.proc.poll() is None

    def shell(self, command: str, *args: str) -> str:
        """Run a PX4 shell command on this instance (``px4-<command>`` beside the binary)."""
        exe = Path(self.proc.args[0]).with_name(f"px4-{command}")  # type: ignore[index]
        proc = subprocess.run([str(exe), "--instance", str(self.instance), *args],
                              cwd=self.workdir, capture_output=True, text=True, timeout=10,
                              check=True)
        return proc.stdout

    def add_gcs_link(self, listen_port: int, remote_port: int) -> None:
        """A further MAVLink link in PX4's Normal (GCS) mode: PX4 binds ``listen_port`` and
        sends to 127.0.0.1:``remote_port`` (a second ground station, e.g. QGroundControl's)."""
        self.shell("mavlink", "start", "-u", str(listen_port), "-o", str(remote_port),
                   "-t", "127.0.0.1", "-r", "400000")  # no -m: Normal


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@contextlib.contextmanager
def px4_sih(speed_factor: float = 4.0, home: tuple[float, float, float] = SIH_DEFAULT_HOME,
            *, instance: int | None = None, params: dict[str, float] | None = None,
            late_params: dict[str, float] | None = None,
            binary: Path | None = None) -> Iterator[Px4Sitl]:
    """Start PX4 SITL + SIH headless; yield it ready for takeoff; always stop and clean up.

    ``home`` = (lat_deg, lon_deg, alt_m AMSL) through SIH_LOC_LAT0/LON0/H0 (float32 parameters:
    ~0.4 m resolution; PX4's home is then its estimate there, ~0.1 m off). ``params``: any
    other PX4 parameters, set at start-up (``PX4_PARAM_<name>``).
    """
    exe = binary or find_px4()
    if exe is None:
        raise RuntimeError("no PX4 SITL binary: set PX4_SITL_BIN")
    etc = exe.parent.parent / "etc"
    i = free_instance() if instance is None else instance
    workdir = Path(tempfile.mkdtemp(prefix=f"px4sih{i}-"))
    log_path = workdir / "px4.log"
    env = os.environ | {
        "PX4_SYS_AUTOSTART": "10040", "PX4_SIMULATOR": "sihsim",
        "PX4_SIM_MODEL": "sihsim_quadx", "PX4_SIM_SPEED_FACTOR": f"{speed_factor:g}",
        "PX4_PARAM_SIH_LOC_LAT0": f"{home[0]:.7f}", "PX4_PARAM_SIH_LOC_LON0": f"{home[1]:.7f}",
        "PX4_PARAM_SIH_LOC_H0": f"{home[2]:.2f}",
    } | {f"PX4_PARAM_{k}": f"{v:g}" for k, v in (params or {}).items()}
    proc: subprocess.Popen[bytes] | None = None
    try:
        with log_path.open("wb") as log:
            proc = subprocess.Popen(
                [str(exe), "-d", "-i", str(i), "-w", str(workdir), str(etc)], cwd=workdir,
                env=env, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                start_new_session=True)
        px4 = Px4Sitl(proc, i, speed_factor, home, workdir, log_path)
        deadline = time.monotonic() + READY_TIMEOUT_S
        while READY_TEXT not in px4.log_text():
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"PX4 did not become ready:\n{px4.log_text()[-3000:]}")
            time.sleep(0.1)
        # ``late_params`` are set through PX4's shell once it is ready: some (NAV_DLL_ACT 2)
        # keep PX4 from ever saying "Ready for takeoff" until a ground station connects.
        for name, value in (late_params or {}).items():
            px4.shell("param", "set", name, f"{value:g}")
        yield px4
    finally:
        if proc is not None:
            _stop(proc)
        shutil.rmtree(workdir, ignore_errors=True)


@contextlib.contextmanager
def radios_on(px4: Px4Sitl, mission: Path, *, radio_port: int, truth_dir: Path,
              extra: list[str] | None = None) -> Iterator[SimProcess]:
    """The simulator's radios riding on this PX4's GCS link; stopped (SIGTERM) at the end.

    Datagrams go to 127.0.0.1:``radio_port``; ``truth_dir/truth.jsonl`` is written.
    """
    rider = start_radios_only(mission, truth_dir, vehicle=px4.gcs_link_url,
                              radio_port=radio_port,
                              extra=["--vehicle-sysid", str(px4.sysid), *(extra or [])])
    try:
        yield rider
    finally:
        rider.stop()


def fly_with_radios(px4: Px4Sitl, mission: Path, tmp_path: Path,
                    timeout_s: float) -> subprocess.CompletedProcess[str]:
    """``mexgen-gcs fly MISSION`` against this PX4 with the simulator's radios riding on its
    GCS link, as a user flies it (headless, seed 1, logs under ``tmp_path/flights``, the
    radios' truth under ``tmp_path/radios``). PX4 SIH leaves the data-link-loss action at the
    firmware default, disabled, which the preflight check refuses; set before start-up it
    would keep PX4 from "Ready for takeoff" without a GCS, so these flights accept it
    knowingly (``--accept-unsafe-params NAV_DLL_ACT``)."""
    radio_port = free_udp_port()
    with radios_on(px4, mission, radio_port=radio_port, truth_dir=tmp_path / "radios"):
        return subprocess.run(
            [sys.executable, "-m", "mexgen_gcs", "fly", str(mission), "--headless",
             "--connect", px4.mavsdk_url, "--radio", f"udp://127.0.0.1:{radio_port}",
             "--log-dir", str(tmp_path / "flights"), "--seed", "1",
             "--accept-unsafe-params", "NAV_DLL_ACT"],
            capture_output=True, text=True, timeout=timeout_s)
