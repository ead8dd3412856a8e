"""The README's commands run as written: the mission check, `--help` of every command in its
commands table (and the table lists every subcommand), and the collection of every pytest
command it gives. The quick ones only: the simulator flight and the test runs themselves are
covered by the e2e tests and by CI."""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from mexgen_gcs.cli import build_parser, main

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text(encoding="utf-8")
CI_TEST_COMMAND = "python -m pytest -q -n 2 --dist worksteal"


def _blocks() -> list[str]:
    return re.findall(r"^```(?:bash|sh)?\n(.*?)^```", README, flags=re.S | re.M)


def _commands() -> list[str]:
    """Every shell command in the README's code blocks, `&&` chains split into their parts."""
    out = []
    for block in _blocks():
        for line in block.splitlines():
            line = line.split(" #", 1)[0].strip()
            out += [part.strip() for part in line.split("&&") if part.strip()]
    return out


def _table_commands() -> list[str]:
    section = README.split("## Commands", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"^\| `([^`]+)` \|", section, flags=re.M)


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])])}


def _start(args: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, *args], cwd=REPO, env=_env(), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def _finish(procs: dict[str, subprocess.Popen[str]], timeout_s: float) -> dict[str, str]:
    outputs = {}
    for what, proc in procs.items():
        out, _ = proc.communicate(timeout=timeout_s)
        assert proc.returncode == 0, f"{what}: exit {proc.returncode}\n{out[-2000:]}"
        outputs[what] = out
    return outputs


def _subcommands() -> set[str]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return set(sub.choices)


def test_readme_is_a_front_door_not_a_notebook() -> None:
    assert len(README.splitlines()) <= 180
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", README), "dates belong in docs/results/"
    assert not re.search(r"\bcommits? [0-9a-f]{7,40}\b", README), "so do commit hashes"


def test_the_readme_test_command_is_the_one_ci_runs() -> None:
    assert CI_TEST_COMMAND in _commands()
    assert CI_TEST_COMMAND in (REPO / ".ci" / "run").read_text(encoding="utf-8")


def test_the_commands_table_lists_every_subcommand() -> None:
    listed = {cmd.split()[1] for cmd in _table_commands() if cmd.startswith("mexgen-gcs ")}
    assert listed == _subcommands()
    assert any(cmd.startswith("python -m sim ") for cmd in _table_commands())


@pytest.mark.e2e  # starts `python -m sim --help` and the collections as processes
def test_the_readmes_quick_commands_run_as_written(capsys: pytest.CaptureFixture[str]) -> None:
    """`mexgen-gcs check ...` as given, `--help` of every command in the table, and the
    collection of every pytest command. The subprocesses run at once, so the test takes about
    as long as the slowest (the collection: about 8 s of CPU); the `mexgen-gcs` help runs in
    this process, through the console script's own `main`."""
    procs: dict[str, subprocess.Popen[str]] = {}
    checks = [c for c in _commands() if c.startswith("mexgen-gcs check ")]
    assert checks, "the README shows how to check a mission"
    for cmd in checks:
        procs[cmd] = _start(["-m", "mexgen_gcs", *cmd.split()[1:]])
    for cmd in _table_commands():
        if cmd.startswith("python -m sim "):
            procs[f"{cmd} --help"] = _start(["-m", "sim", "--help"])
    pytest_cmds = [c for c in _commands() if c.startswith("python -m pytest")]
    assert pytest_cmds
    for cmd in pytest_cmds:
        # -n 0 after the command's own -n: collect in one process, not in workers
        argv = [*shlex.split(cmd)[1:], "--collect-only", "-n", "0"]
        procs[f"{cmd} --collect-only"] = _start(argv)
    for cmd in _table_commands():
        if cmd.startswith("mexgen-gcs "):
            assert main([cmd.split()[1], "--help"]) == 0, cmd
            assert f"usage: mexgen-gcs {cmd.split()[1]}" in capsys.readouterr().out, cmd
    out = _finish(procs, timeout_s=240)
    for cmd in checks:
        assert "Mission 'demo'" in out[cmd], out[cmd]
    assert "usage:" in out["python -m sim MISSION.yaml --help"]
    for cmd in pytest_cmds:
        collected = re.search(r"(\d+)(?:/\d+)? tests? collected", out[f"{cmd} --collect-only"])
        assert collected and int(collected.group(1)) > 100, out[f"{cmd} --collect-only"][-500:]
