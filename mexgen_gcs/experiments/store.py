"""An experiment's output directory: append-only run records that survive interruption.

No frames here (the series are stored as the runner makes them, ENU metres).

Layout of DIR:

- ``experiment.json``: what the directory holds (scenario, preset, seed, the settings of every
  model run so far). A later invocation with different ones is refused, so runs made with
  different settings never mix.
- ``runs.csv``: one row per finished run (``runner.COLUMNS``), appended and flushed to disk as
  each run finishes. A run is done iff its row is here; an interrupted experiment resumes by
  skipping those. A torn last line (killed while writing) is cut off on open.
- ``series/<model>/<method>-s<start>-r<rep>.npz``: the run's per-pulse series, written
  (atomically) before its row, so every row has its series.
- ``missions/<model>-<method>.yaml``: the mission each run of that model and method flies.
- ``.lock``: held while an invocation writes, so two cannot write the same directory at once.
"""

from __future__ import annotations

import csv
import fcntl
import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.errors import ConfigError
from mexgen_gcs.experiments.runner import COLUMNS, RunResult, RunSpec
from mexgen_gcs.experiments.scenario import Scenario, mission_yaml

FORMAT_VERSION = 5
"""2: runs.csv gained the tight-radius reading (runner.COLUMNS), presets paper|field; 3: the
claimed radii and their coverage, reality profiles and estimators; 4: every tag's final radius
and error (``final_*``), localised or not. A directory of another
format is refused for writing; the report reads them all."""
RUNS_CSV = "runs.csv"
EXPERIMENT_JSON = "experiment.json"

RunKey = tuple[str, str, int, int]


def row_key(row: dict[str, str]) -> RunKey:
    return (row["model"], row["method"], int(row["start"]), int(row["rep"]))


def series_path(out_dir: Path, model: str, method: str, start: int, rep: int) -> Path:
    return out_dir / "series" / model / f"{method}-s{start:03d}-r{rep:03d}.npz"


def read_rows(out_dir: Path) -> list[dict[str, str]]:
    """Every complete row of DIR/runs.csv (a torn last line is ignored)."""
    path = Path(out_dir) / RUNS_CSV
    if not path.exists():
        return []
    text = path.read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return [dict(r) for r in csv.DictReader(io.StringIO(text))]


def read_series(out_dir: Path, row: dict[str, str]) -> dict[str, NDArray[np.float32]] | None:
    """The per-pulse series of a row's run, or None if its file is missing."""
    path = series_path(Path(out_dir), row["model"], row["method"], int(row["start"]),
                       int(row["rep"]))
    if not path.exists():
        return None
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def read_identity(out_dir: Path) -> dict[str, Any] | None:
    path = Path(out_dir) / EXPERIMENT_JSON
    if not path.exists():
        return None
    return dict(json.loads(path.read_text(encoding="utf-8")))


class RunStore:
    """The writer of one experiment directory (see the module docstring). Use as a context
    manager; ``append`` each finished run."""

    def __init__(self, out_dir: str | os.PathLike[str], sc: Scenario, seed: int,
                 methods: tuple[str, ...]) -> None:
        self.out_dir = Path(out_dir)
        self.scenario = sc
        self.seed = seed
        self.methods = methods
        self._lock_fh: io.TextIOWrapper | None = None
        self._csv_fh: io.TextIOWrapper | None = None
        self._writer: Any = None
        self.done: set[RunKey] = set()

    def __enter__(self) -> RunStore:
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"--out {self.out_dir}: cannot create it: {exc}") from None
        self._lock_fh = open(self.out_dir / ".lock", "a", encoding="utf-8")
        try:
            fcntl.flock(self._lock_fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock_fh.close()
            self._lock_fh = None
            raise ConfigError(f"--out {self.out_dir}: another experiment is writing there; "
                              "wait for it or choose another directory") from None
        try:
            self._check_identity()
            self._open_csv()
            self._write_missions()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._csv_fh is not None:
            self._csv_fh.close()
            self._csv_fh = None
        if self._lock_fh is not None:
            self._lock_fh.close()
            self._lock_fh = None

    # -- opening -----------------------------------------------------------------------------

    def _check_identity(self) -> None:
        sc = self.scenario
        settings = sc.describe()
        ident = read_identity(self.out_dir)
        want = {"format": FORMAT_VERSION, "scenario": sc.kind, "preset": sc.label,
                "seed": self.seed}
        if ident is None:
            ident = {**want, "settings": {}}
        if ident.get("format") != FORMAT_VERSION:
            raise ConfigError(
                f"--out {self.out_dir} was written by experiment format {ident.get('format')!r}"
                f" (this is {FORMAT_VERSION}: new runs.csv columns); its summary can still be "
                "rewritten, but choose another directory for new runs")
        for key, value in want.items():
            if ident.get(key) != value:
                raise ConfigError(
                    f"--out {self.out_dir} holds a different experiment ({key} = "
                    f"{ident.get(key)!r}, this one has {value!r}); choose another directory")
        known = ident.setdefault("settings", {}).get(sc.model)
        if known is not None:
            fresh = json.loads(json.dumps(settings))
            diff = sorted(k for k in set(known) | set(fresh) if known.get(k) != fresh.get(k))
            if diff:
                raise ConfigError(
                    f"--out {self.out_dir} holds {sc.model} runs made with other settings "
                    f"({', '.join(diff)}); choose another directory")
        ident["settings"][sc.model] = settings
        _atomic_write(self.out_dir / EXPERIMENT_JSON,
                      (json.dumps(ident, indent=2, sort_keys=True) + "\n").encode("utf-8"))

    def _open_csv(self) -> None:
        path = self.out_dir / RUNS_CSV
        if path.exists():
            data = path.read_bytes()
            if data and not data.endswith(b"\n"):  # torn last line: cut it off
                with open(path, "r+b") as fh:
                    fh.truncate(data.rfind(b"\n") + 1)
            with open(path, encoding="utf-8", newline="") as fh:
                header = next(csv.reader(fh), None)
            if header is not None and tuple(header) != COLUMNS:
                raise ConfigError(f"{path}: its columns are not this version's ({header[:3]}...);"
                                  " choose another directory")
            self.done = {row_key(r) for r in read_rows(self.out_dir)}
        new = not path.exists() or path.stat().st_size == 0
        self._csv_fh = open(path, "a", encoding="utf-8", newline="")  # noqa: SIM115
        self._writer = csv.DictWriter(self._csv_fh, fieldnames=COLUMNS, lineterminator="\n")
        if new:
            self._writer.writeheader()
            self._flush()

    def _write_missions(self) -> None:
        d = self.out_dir / "missions"
        d.mkdir(exist_ok=True)
        for method in self.methods:
            text = mission_yaml(self.scenario, method)
            _atomic_write(d / f"{self.scenario.model}-{method}.yaml", text.encode("utf-8"))

    # -- writing -----------------------------------------------------------------------------

    def pending(self, specs: list[RunSpec]) -> list[RunSpec]:
        """The specs whose runs are not in runs.csv yet, in order."""
        return [s for s in specs if s.key not in self.done]

    def append(self, result: RunResult) -> None:
        """Store one finished run: its series file, then its row (flushed to disk)."""
        if self._writer is None:
            raise RuntimeError("RunStore is not open")
        key = result.spec.key
        if key in self.done:
            return
        buf = io.BytesIO()
        np.savez_compressed(buf, **result.series)  # type: ignore[arg-type]  # numpy stubs
        _atomic_write(series_path(self.out_dir, *key), buf.getvalue())
        self._writer.writerow(result.row)
        self._flush()
        self.done.add(key)

    def _flush(self) -> None:
        assert self._csv_fh is not None
        self._csv_fh.flush()
        os.fsync(self._csv_fh.fileno())


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
