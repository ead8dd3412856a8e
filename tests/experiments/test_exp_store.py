"""The output directory: append-only rows, torn lines, identity, the lock; the progress bar."""

from __future__ import annotations

import io
import json
from dataclasses import replace
from pathlib import Path

import pytest

from mexgen_gcs.errors import ConfigError
from mexgen_gcs.experiments.progress import Progress
from mexgen_gcs.experiments.runner import COLUMNS, RunSpec, run_one
from mexgen_gcs.experiments.scenario import scenario
from mexgen_gcs.experiments.store import RunStore, read_rows, read_series

SC = scenario("localise", "rw", quick=True)
METHODS = ("pim", "mexgen")


@pytest.fixture(scope="module")
def results() -> list:
    return [run_one(RunSpec(SC, m, 0, s, 0)) for s in (0, 1) for m in METHODS]


def test_rows_and_series_are_stored_as_runs_finish(tmp_path: Path, results: list) -> None:
    with RunStore(tmp_path, SC, 0, METHODS) as store:
        assert store.pending([r.spec for r in results]) == [r.spec for r in results]
        store.append(results[0])
        # on disk already, before the store is closed
        assert [r["method"] for r in read_rows(tmp_path)] == ["pim"]
        store.append(results[1])
        store.append(results[0])  # a duplicate is ignored
    rows = read_rows(tmp_path)
    assert rows == [results[0].row, results[1].row]
    s = read_series(tmp_path, rows[1])
    assert s is not None and s.keys() == results[1].series.keys()
    assert (tmp_path / "missions" / "rw-mexgen.yaml").exists()
    with RunStore(tmp_path, SC, 0, METHODS) as store:
        assert store.pending([r.spec for r in results]) == [r.spec for r in results[2:]]


def test_a_torn_last_line_is_cut_off_on_open(tmp_path: Path, results: list) -> None:
    with RunStore(tmp_path, SC, 0, METHODS) as store:
        store.append(results[0])
    csv_path = tmp_path / "runs.csv"
    whole = csv_path.read_text()
    torn_row = ",".join(results[1].row.values())[:37]
    csv_path.write_text(whole + torn_row)
    assert read_rows(tmp_path) == [results[0].row]  # readers skip it
    with RunStore(tmp_path, SC, 0, METHODS) as store:
        assert csv_path.read_text() == whole
        store.append(results[1])
    assert read_rows(tmp_path) == [results[0].row, results[1].row]


def test_a_directory_holds_one_experiment(tmp_path: Path) -> None:
    with RunStore(tmp_path, SC, 0, METHODS):
        pass
    with RunStore(tmp_path, scenario("localise", "cv", quick=True), 0, METHODS):
        pass  # another model of the same experiment is fine
    with pytest.raises(ConfigError, match="seed"):
        RunStore(tmp_path, SC, 1, METHODS).__enter__()
    with pytest.raises(ConfigError, match="preset"):
        RunStore(tmp_path, scenario("localise", "rw"), 0, METHODS).__enter__()
    with pytest.raises(ConfigError, match="preset"):
        RunStore(tmp_path, scenario("localise", "rw", True, "field"), 0, METHODS).__enter__()
    with pytest.raises(ConfigError, match="scenario"):
        RunStore(tmp_path, scenario("follow", "rw", quick=True), 0, METHODS).__enter__()
    with pytest.raises(ConfigError, match="lookahead_s"):
        RunStore(tmp_path, replace(SC, lookahead_s=3.0), 0, METHODS).__enter__()


def test_one_writer_at_a_time(tmp_path: Path) -> None:
    with RunStore(tmp_path, SC, 0, METHODS), pytest.raises(ConfigError, match="another"):
        RunStore(tmp_path, SC, 0, METHODS).__enter__()
    with RunStore(tmp_path, SC, 0, METHODS):  # released on exit
        pass


def test_progress_draws_on_a_terminal_only() -> None:
    now = [0.0]
    out = io.StringIO()
    p = Progress(4, "localise rw", out, clock=lambda: now[0], force=True)
    for _ in range(3):
        now[0] += 10.0
        p.update()
    now[0] += 10.0
    p.update(failed=True)
    p.close()
    text = out.getvalue()
    assert "localise rw" in text and "1/4" in text
    assert "4/4" in text and "100%" in text and "1 failed" in text
    assert "0:00:40" in text  # elapsed on the given clock
    quiet = io.StringIO()
    q = Progress(2, "x", quiet)  # a StringIO is not a tty
    q.update()
    q.close()
    assert quiet.getvalue() == ""


def test_a_directory_of_the_previous_format_is_refused_for_writing(tmp_path: Path) -> None:
    """Format 1 (no tight reading in runs.csv): new runs go elsewhere, nothing is touched."""
    ident = {"format": 1, "scenario": "localise", "preset": "paper-quick", "seed": 0,
             "settings": {}}
    (tmp_path / "experiment.json").write_text(json.dumps(ident))
    header = ",".join(COLUMNS[:24]) + "\n"
    (tmp_path / "runs.csv").write_text(header)
    with pytest.raises(ConfigError, match="format 1"):
        RunStore(tmp_path, SC, 0, METHODS).__enter__()
    assert (tmp_path / "runs.csv").read_text() == header
