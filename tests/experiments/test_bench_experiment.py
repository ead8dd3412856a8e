"""`bench experiment` (a smoke test: the figures are measured, never asserted as speeds)."""

from __future__ import annotations

import json

import pytest

from mexgen_gcs.bench import experiment as bench_experiment
from mexgen_gcs.cli import main


def test_bench_experiment_times_each_cell_and_projects_the_table() -> None:
    out = bench_experiment.run(starts=2, models=("rw",), methods=("pim", "mexgen"), quick=True,
                               cores=(1, 2))
    assert [(c["model"], c["method"], c["runs"]) for c in out["cells"]] == [
        ("rw", "pim", 2), ("rw", "mexgen", 2)]
    for c in out["cells"]:
        assert c["cpu_s"] > 0 and c["runs_per_hour_per_core"] > 0
        lo, hi = c["cpu_per_run_range_s"]
        assert 0 < lo <= c["cpu_per_run_s"] <= hi
        assert sum(c["stage_share"].values()) == pytest.approx(1.0, abs=1e-6)
        assert c["stage_share"]["filter"] > 0 and c["stage_share"]["planner"] > 0
    table = out["table"]
    assert table["runs"] == 1 * 2 * 50 * 30
    # the projection is the cells' mean CPU per run times the table's runs per cell
    cpu_h = sum(c["cpu_per_run_s"] for c in out["cells"]) * 1500 / 3600
    assert table["cpu_h"] == pytest.approx(cpu_h)
    assert table["wall_h_on_cores"]["2"] == pytest.approx(cpu_h / 2)
    text = bench_experiment._table(out)
    assert "full table (3000 runs)" in text and "rw" in text


def test_bench_experiment_is_a_bench_subcommand(monkeypatch, capsys) -> None:
    calls = []
    real_run = bench_experiment.run

    def fake_run(**kw):  # the command's wiring only; the run itself is tested above
        calls.append(kw)
        return real_run(starts=1, models=("rw",), methods=("pim",), quick=True)

    monkeypatch.setattr(bench_experiment, "run", fake_run)
    assert main(["bench", "experiment", "--starts", "3", "--json"]) == 0
    assert calls == [{"starts": 3}]
    assert json.loads(capsys.readouterr().out)["table"]["runs"] == 1500


def test_bench_filter_times_both_estimators_on_a_moving_receiver() -> None:
    from mexgen_gcs.bench import filter as bench_filter

    out = bench_filter.run(iterations=3, sizes=(200,), models=("cv",))
    rows = {(r["estimator"], r["model"], r["n_particles"], r["pulse"]): r
            for r in out["results"]}
    assert set(rows) == {(e, "cv", 200, p) for e in ("classic", "robust")
                         for p in ("detection", "miss")}
    assert all(r["median_ms"] > 0 for r in rows.values())
    estimators = bench_filter.ESTIMATORS
    assert estimators["robust"].active and not estimators["classic"].active
    assert "robust" in bench_filter._table(out)
