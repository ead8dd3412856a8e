"""The batch machinery end to end on the quick preset: process pool, a real local Dask
cluster on loopback, resumption after a kill or an interrupt, the CLI and the report."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import psutil
import pytest
import yaml

from mexgen_gcs.cli import main
from mexgen_gcs.config import CLASSIC_ESTIMATOR
from mexgen_gcs.errors import ConfigError
from mexgen_gcs.experiments.cli import ExperimentOutcome, run_experiment, run_specs
from mexgen_gcs.experiments.parallel import execute
from mexgen_gcs.experiments.runner import TIMING_COLUMNS
from mexgen_gcs.experiments.scenario import scenario
from mexgen_gcs.experiments.store import RunStore, read_rows, row_key, series_path

pytestmark = pytest.mark.long  # worker pools, the experiment CLI as a subprocess

MODEL = "cv-ift"
METHODS = ("pim", "mc8", "mexgen")
STARTS, REPS, SEED = 3, 2, 11
SC = scenario("localise", MODEL, quick=True)
ARGS = ["experiment", "localise", "--model", MODEL, "--methods", ",".join(METHODS),
        "--starts", str(STARTS), "--reps", str(REPS), "--seed", str(SEED), "--quick"]
N_RUNS = STARTS * REPS * len(METHODS)


def _numbers(rows: list[dict[str, str]]) -> dict[tuple[str, str, int, int], dict[str, str]]:
    keyed = {row_key(r): {k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows}
    assert len(keyed) == len(rows), "duplicate runs"
    return keyed


def _pool_workers() -> list[psutil.Process]:
    procs = []
    for p in psutil.Process().children(recursive=True):
        with contextlib.suppress(psutil.Error):
            if "spawn_main" in " ".join(p.cmdline()):
                procs.append(p)
    return procs


def _run(out: Path, **kw: object) -> ExperimentOutcome:
    return run_experiment(SC, METHODS, starts=STARTS, reps=REPS, seed=SEED, out_dir=out,
                          **kw)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One uninterrupted run of the experiment on the local process pool (2 workers)."""
    out = tmp_path_factory.mktemp("reference")
    result = _run(out, workers=2)
    assert (result.completed, result.skipped, result.failures) == (N_RUNS, 0, ())
    return out


def test_pool_runs_every_run_once_and_writes_the_report(reference: Path) -> None:
    rows = read_rows(reference)
    assert Counter(r["method"] for r in rows) == dict.fromkeys(METHODS, STARTS * REPS)
    _numbers(rows)
    for name in ("summary.md", "localise-time.png", "localise-success.png",
                 f"trajectories-{MODEL}.png", f"missions/{MODEL}-mexgen.yaml"):
        assert (reference / name).stat().st_size > 0, name
    summary = (reference / "summary.md").read_text()
    assert "| CV-IFT | MexGen | 6 |" in summary and "Paired against MexGen" in summary
    for r in rows:
        assert series_path(reference, r["model"], r["method"], int(r["start"]),
                           int(r["rep"])).exists()


def test_methods_are_paired_on_the_same_truth(reference: Path) -> None:
    rows = read_rows(reference)
    for s in range(STARTS):
        assert len({r["truth_digest"] for r in rows if r["start"] == str(s)}) == 1
    assert len({r["truth_digest"] for r in rows}) == STARTS


def test_a_rerun_has_nothing_to_do(reference: Path, tmp_path: Path) -> None:
    out = tmp_path / "copy"
    shutil.copytree(reference, out)
    result = _run(out, workers=1)
    assert (result.completed, result.skipped) == (0, N_RUNS)
    assert read_rows(out) == read_rows(reference)


def test_local_dask_cluster_gives_the_same_numbers(reference: Path, tmp_path: Path) -> None:
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        result = _run(tmp_path, scheduler=cluster.scheduler_address)
    assert (result.completed, result.failures) == (N_RUNS, ())
    assert _numbers(read_rows(tmp_path)) == _numbers(read_rows(reference))


def test_unreachable_scheduler_is_bad_input() -> None:
    with socket.socket() as s:  # a free port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    specs = run_specs(SC, ("pim",), 1, 1, SEED)
    with pytest.raises(ConfigError, match="cannot connect"):
        list(execute(specs, scheduler=f"tcp://127.0.0.1:{port}", connect_timeout_s=1.0))


def test_resumes_from_the_state_a_kill_leaves(reference: Path, tmp_path: Path) -> None:
    """Every state a kill can leave: complete rows, a torn row being written, the series of
    a run whose row never made it, a half-written temporary file."""
    out = tmp_path / "killed"
    shutil.copytree(reference, out)
    csv_path = out / "runs.csv"
    lines = csv_path.read_text().splitlines(keepends=True)
    keep = 7
    csv_path.write_text("".join(lines[: 1 + keep]) + lines[1 + keep][:40])
    for r in read_rows(reference)[keep + 1:]:
        series_path(out, r["model"], r["method"], int(r["start"]), int(r["rep"])).unlink()
    (out / "series" / MODEL / "junk.npz.tmp").write_bytes(b"\x00" * 10)
    result = _run(out, workers=2)
    assert (result.completed, result.skipped) == (N_RUNS - keep, keep)
    assert _numbers(read_rows(out)) == _numbers(read_rows(reference))


def test_an_interrupt_keeps_finished_runs(reference: Path, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C part-way: the finished runs stay; the same call again finishes the rest."""
    appended = []
    original = RunStore.append

    def append_then_interrupt(self: RunStore, result: object) -> None:
        original(self, result)  # type: ignore[arg-type]
        appended.append(result)
        if len(appended) == 4:
            raise KeyboardInterrupt

    monkeypatch.setattr(RunStore, "append", append_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        _run(tmp_path, workers=2)
    assert len(read_rows(tmp_path)) == 4
    # the pool's workers were stopped, not left to finish the queued runs
    deadline = time.monotonic() + 30.0
    while _pool_workers() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _pool_workers()
    monkeypatch.setattr(RunStore, "append", original)
    result = _run(tmp_path, workers=2)
    assert (result.completed, result.skipped) == (N_RUNS - 4, 4)
    assert _numbers(read_rows(tmp_path)) == _numbers(read_rows(reference))


def test_cli_killed_part_way_then_rerun(reference: Path, tmp_path: Path) -> None:
    """The real command, killed (SIGKILL to its process group, workers included) once its
    first run is stored, then run again: the same runs, none lost, none twice."""
    cmd = [sys.executable, "-m", "mexgen_gcs", *ARGS, "--workers", "1", "--out", str(tmp_path)]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and proc.poll() is None:
            if len(read_rows(tmp_path)) >= 1:
                break
            time.sleep(0.02)
        assert read_rows(tmp_path), "the experiment stored no run within 120 s"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        assert proc.stderr is not None
        proc.stderr.close()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "already in" in done.stdout
    assert _numbers(read_rows(tmp_path)) == _numbers(read_rows(reference))


def test_cli_reports_bad_input_with_exit_2(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*ARGS[:4], "--methods", "pim,mc16", "--out", str(tmp_path)]) == 2
    assert "mc16" in capsys.readouterr().err
    assert main(["experiment", "localise", "--model", "rw", "--starts", "1", "--reps", "1",
                 "--methods", "pim", "--quick", "--workers", "1", "--out", str(tmp_path)]) == 0
    # same directory, another seed: refused, nothing run
    assert main(["experiment", "localise", "--model", "rw", "--starts", "1", "--reps", "1",
                 "--methods", "pim", "--quick", "--seed", "5", "--out", str(tmp_path)]) == 2
    assert "seed" in capsys.readouterr().err
    assert len(read_rows(tmp_path)) == 1
    assert "mexgen-gcs experiment localise --model rw" in (tmp_path / "commands.log").read_text()


def test_cli_follow_writes_the_time_series_plots(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["experiment", "follow", "--model", "cv", "--methods", "pim,mexgen", "--starts",
               "2", "--reps", "1", "--quick", "--workers", "2", "--out", str(tmp_path)])
    assert rc == 0
    assert "4 runs done" in capsys.readouterr().out
    for name in ("follow-cv.png", "trajectories-cv.png", "summary.md"):
        assert (tmp_path / name).stat().st_size > 0
    assert "| CV | MexGen | 2 |" in (tmp_path / "summary.md").read_text()


def test_cli_preset_field_flies_the_mission_defaults(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["experiment", "localise", "--model", "cv", "--preset", "field", "--methods",
                 "pim", "--starts", "1", "--reps", "1", "--quick", "--workers", "1", "--out",
                 str(tmp_path)]) == 0
    ident = json.loads((tmp_path / "experiment.json").read_text())
    assert ident["preset"] == "field-quick" and ident["format"] == 5
    mission = yaml.safe_load((tmp_path / "missions" / "cv-pim.yaml").read_text())
    assert mission["radio"] == {"front_back_db": 3.0, "sensitivity_db": -60.0,
                                "detection_spread_db": 2.0, "pd_max": 0.95,
                                **{k.split(".")[1]: v for k, v in CLASSIC_ESTIMATOR.items()}}
    assert read_rows(tmp_path)[0]["preset"] == "field-quick"
    summary = (tmp_path / "summary.md").read_text()
    assert "field-quick preset" in summary and "sensitivity -60 dB" in summary
    assert "Coverage of the final estimate" in summary
    assert "--preset field" in (tmp_path / "commands.log").read_text()
    # the default preset is the paper's: another directory's identity
    assert main(["experiment", "localise", "--model", "cv", "--methods", "pim", "--starts", "1",
                 "--reps", "1", "--quick", "--workers", "1", "--out", str(tmp_path)]) == 2
    assert "preset" in capsys.readouterr().err
