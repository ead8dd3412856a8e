"""`mexgen-gcs check` as a real subprocess, and the command line's other entry points."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from mexgen_gcs import cli

pytestmark = pytest.mark.long  # the command line as a subprocess

REPO = Path(__file__).resolve().parents[1]
MISSIONS = REPO / "missions"
DEMO_TEXT = (MISSIONS / "demo.yaml").read_text(encoding="utf-8")
EXAMPLES = ["demo.yaml", "follow_cv.yaml", "localise_cv_ift.yaml", "localise_mismatch.yaml"]


def run_cli(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess[str]:
    """`python -m mexgen_gcs ...`: the same entry point as the installed `mexgen-gcs`."""
    return subprocess.run([sys.executable, "-m", "mexgen_gcs", *args], capture_output=True,
                          text=True, timeout=120, cwd=cwd)


@pytest.mark.parametrize("name", EXAMPLES)
def test_check_examples(name: str) -> None:
    proc = run_cli("check", f"missions/{name}")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert f"missions/{name}: OK" in proc.stdout
    assert "planner" in proc.stdout and "area" in proc.stdout


def test_check_prints_warnings() -> None:
    proc = run_cli("check", "missions/demo.yaml")
    assert "Warnings (1):" in proc.stdout and "MPC_ACC_HOR" in proc.stdout
    assert "No warnings." in run_cli("check", "missions/follow_cv.yaml").stdout


def test_installed_script_runs_check() -> None:
    script = Path(sys.executable).with_name("mexgen-gcs")
    if not script.exists():
        pytest.skip("mexgen-gcs script not installed beside this interpreter")
    proc = subprocess.run([str(script), "check", str(MISSIONS / "demo.yaml")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr


BAD = [
    # (case, old, new, expected fragments in stderr)
    ("unknown_key", "  speed_m_s: 10.0", "  sped_m_s: 10.0",
     [":11: flight.sped_m_s: unknown key 'sped_m_s' (did you mean 'speed_m_s'?)"]),
    ("wrong_type", "  alt_m: 50.0  ", "  alt_m: high  ",
     [":10: flight.alt_m: expected a valid number; found 'high'"]),
    ("missing_required", "name: demo\n", "",
     [":3: name: missing required key 'name'"]),
    ("bad_enum", "  method: mexgen ", "  method: best ",
     [":49: planner.method: expected 'mexgen', 'pim' or 'mc'; found 'best'"]),
    ("duplicate_tag", "{id: T2, freq", "{id: T1, freq",
     [":15: tags[1].id: duplicate tag id 'T1'", "expected unique ids"]),
    ("sim_tag_not_in_mission", "{id: T4, position_m", "{id: T5, position_m",
     [":79: sim.tags[3].id: 'T5' is not a mission tag; expected one of T1, T2, T3, T4"]),
    ("follow_without_section", "kind: localise ", "kind: follow ",
     [":3: follow: kind is 'follow', so a follow section is required"]),
    ("bad_yaml", "  p0_db: -7.0", "  p0_db: [-7.0", [":20:7: not valid YAML"]),
]


@pytest.mark.parametrize(("case", "old", "new", "fragments"), BAD, ids=[b[0] for b in BAD])
def test_check_bad_missions_exit_2(tmp_path: Path, case: str, old: str, new: str,
                                   fragments: list[str]) -> None:
    assert old in DEMO_TEXT
    path = tmp_path / f"{case}.yaml"
    path.write_text(DEMO_TEXT.replace(old, new, 1), encoding="utf-8")
    proc = run_cli("check", str(path))
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert str(path) in proc.stderr
    for fragment in fragments:
        expected = f"{path}{fragment}" if fragment.startswith(":") else fragment
        assert expected in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


def test_bad_yaml_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "syntax.yaml"
    path.write_text(DEMO_TEXT.replace("  p0_db: -7.0", "  p0_db: [-7.0", 1), encoding="utf-8")
    proc = run_cli("check", str(path))
    assert proc.returncode == 2
    # the flow sequence opened on line 19 is still open when the key on line 20 appears
    assert f"{path}:20:7: not valid YAML: expected ',' or ']'" in proc.stderr, proc.stderr


def test_check_missing_file_and_usage_errors(tmp_path: Path) -> None:
    proc = run_cli("check", str(tmp_path / "absent.yaml"))
    assert proc.returncode == 2 and "absent.yaml: no such mission file" in proc.stderr
    assert run_cli("check").returncode == 2
    assert run_cli("frobnicate").returncode == 2
    # in-process: a `sitl` subprocess counts as a flight (tests/conftest.py); argparse stops
    # these before anything flies
    assert cli.main(["sitl", "m.yaml", "--method", "best"]) == 2
    assert cli.main(["sitl", "m.yaml", "--speedup", "0"]) == 2


def test_help_and_version() -> None:
    proc = run_cli("--help")
    assert proc.returncode == 0
    for command in ("check", "sitl", "fly", "analyze", "replay", "experiment", "bench"):
        assert command in proc.stdout
    assert run_cli("--version").stdout.startswith("mexgen-gcs ")


def test_documented_flags_parse() -> None:
    parser = cli.build_parser()
    a = parser.parse_args(["sitl", "m.yaml", "--headless", "--method", "pim", "--seed", "3",
                           "--speedup", "4", "--log-dir", "d"])
    assert (a.command, a.mission, a.headless, a.method, a.seed, a.speedup, a.log_dir) == (
        "sitl", "m.yaml", True, "pim", 3, 4.0, "d")
    a = parser.parse_args(["fly", "m.yaml", "--connect", "udpin://0.0.0.0:14540",
                           "--radio", "udp://0.0.0.0:14600", "--headless"])
    assert (a.connect, a.radio, a.headless, a.method) == ("udpin://0.0.0.0:14540",
                                                          "udp://0.0.0.0:14600", True, None)
    assert parser.parse_args(["fly", "m.yaml"]).radio is None  # the mission's receiver.listen
    a = parser.parse_args(["analyze", "L", "--out", "O"])
    assert (a.log, a.out) == (["L"], "O")
    assert parser.parse_args(["replay", "L"]).log == "L"
    a = parser.parse_args(["experiment", "localise", "--model", "cv-ift", "--methods",
                           "mexgen,pim", "--starts", "2", "--reps", "3", "--workers", "4",
                           "--out", "D"])
    assert (a.scenario, a.model, a.methods, a.starts, a.reps, a.workers, a.out) == (
        "localise", "cv-ift", "mexgen,pim", 2, 3, 4, "D")
    a = parser.parse_args(["bench", "planner", "--json"])
    assert (a.what, a.json) == ("planner", True)


def test_missing_handler_module_is_not_available(monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(cli.HANDLERS, "bench", "mexgen_gcs.no_such_module:cmd_bench")
    assert cli.main(["bench", "filter"]) == 2
    assert "mexgen-gcs bench: not available in this build" in capsys.readouterr().err
    monkeypatch.setitem(cli.HANDLERS, "bench", "mexgen_gcs.cli:no_such_function")
    assert cli.main(["bench", "filter"]) == 2
    assert "not available in this build" in capsys.readouterr().err


def test_handlers_are_called_with_args(monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    seen: list[argparse.Namespace] = []

    def fake(args: argparse.Namespace) -> int:
        seen.append(args)
        return 1

    monkeypatch.setattr(cli, "_test_handler", fake, raising=False)
    monkeypatch.setitem(cli.HANDLERS, "replay", "mexgen_gcs.cli:_test_handler")
    assert cli.main(["replay", "some/log", "--speedup", "2"]) == 1
    assert seen[0].log == "some/log" and seen[0].speedup == 2.0

    from mexgen_gcs.errors import ConfigError, VehicleError

    def raises_config(args: argparse.Namespace) -> int:
        raise ConfigError("bad.yaml:3: version: expected 1")

    monkeypatch.setattr(cli, "_test_handler", raises_config, raising=False)
    assert cli.main(["replay", "x"]) == 2
    assert "bad.yaml:3: version: expected 1" in capsys.readouterr().err

    def raises_vehicle(args: argparse.Namespace) -> int:
        raise VehicleError("arm", "DENIED")

    monkeypatch.setattr(cli, "_test_handler", raises_vehicle, raising=False)
    assert cli.main(["replay", "x"]) == 1
    assert "arm failed: DENIED" in capsys.readouterr().err


def _flags(parser: argparse.ArgumentParser) -> set[str]:
    return {opt for action in parser._actions for opt in action.option_strings
            if opt.startswith("--") and opt not in ("--help",)}


def test_every_command_and_flag_is_documented() -> None:
    """docs/cli.md lists every subcommand and every flag the parser defines."""
    text = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == set(cli.HANDLERS) | {"check", "export-plan"}
    for name, subparser in sub.choices.items():
        assert f"## `mexgen-gcs {name}" in text, name
        for flag in _flags(subparser):
            assert f"`{flag}" in text, f"{name} {flag}"
    for flag in _flags(parser):
        assert f"`{flag}" in text, flag
    for code in ("| 0 |", "| 1 |", "| 2 |"):
        assert code in text
