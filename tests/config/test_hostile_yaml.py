"""Hostile mission files: deep nesting, alias loops, alias bombs and huge documents are refused
by the bounded YAML parser (exit 2, one line naming the file and the problem, no traceback),
before any schema work and at a cost of well under a second; aliases used sensibly still load.

The command-line cases run the real `mexgen-gcs check` as a subprocess. Their cost is the
child's CPU time (from getrusage) beyond that of `check` on an empty file, so interpreter
start-up and the load of a shared machine do not count against the parser.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mexgen_gcs.config import parse_mission
from mexgen_gcs.config.safe_yaml import MAX_BYTES, MAX_DEPTH, MAX_NODES
from mexgen_gcs.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]
DEMO_TEXT = (REPO / "missions" / "demo.yaml").read_text(encoding="utf-8")


def _alias_bomb(levels: int = 12, width: int = 10) -> str:
    lines = [f"a0: &a0 [{', '.join(['x'] * width)}]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


HOSTILE: dict[str, tuple[str, str]] = {
    # case: (document, words the message must contain)
    "deep_nesting": ("[" * 100_000 + "]" * 100_000, f"nested deeper than {MAX_DEPTH} levels"),
    "deep_mapping": ("a:\n" + "".join(" " * (2 * i) + "- b:\n" for i in range(1, 60)) + "x\n",
                     f"nested deeper than {MAX_DEPTH} levels"),
    "alias_loop": ("a: &a [*a]\n", "alias *a is inside its own anchor &a (an alias loop)"),
    "alias_loop_in_mapping": ("version: 1\nb: &b {c: [1, {d: *b}]}\n",
                              "alias *b is inside its own anchor &b (an alias loop)"),
    "alias_bomb": (_alias_bomb(), "(an alias bomb)"),
    "merge_key_bomb": ("a: &a {" + ", ".join(f"k{i}: {i}" for i in range(100)) + "}\n"
                       + "".join(f"m{i}: {{<<: *a}}\n" for i in range(200)),
                       "(an alias bomb)"),
    "huge_document": ("# padding\n" * (MAX_BYTES // 10 + 1) + DEMO_TEXT,
                      f"a mission file is at most {MAX_BYTES:,}"),
}


def _child_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _check(path: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    """`python -m mexgen_gcs check PATH` and the CPU seconds the child used."""
    before = _child_cpu_s()
    proc = subprocess.run([sys.executable, "-m", "mexgen_gcs", "check", str(path)],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    return proc, _child_cpu_s() - before


@pytest.fixture(scope="module")
def baseline_cpu_s(tmp_path_factory: pytest.TempPathFactory) -> float:
    """CPU seconds of `check` refusing an empty file: start-up and imports, no parsing."""
    empty = tmp_path_factory.mktemp("baseline") / "empty.yaml"
    empty.write_text("", encoding="utf-8")
    runs = []
    for _ in range(2):
        proc, cpu_s = _check(empty)
        assert proc.returncode == 2 and "the file is empty" in proc.stderr
        runs.append(cpu_s)
    return min(runs)


@pytest.mark.long  # the CLI as a subprocess
@pytest.mark.parametrize("case", ["deep_nesting", "alias_loop", "alias_bomb", "huge_document"])
def test_check_refuses_hostile_yaml(case: str, tmp_path: Path, baseline_cpu_s: float) -> None:
    text, words = HOSTILE[case]
    path = tmp_path / f"{case}.yaml"
    path.write_text(text, encoding="utf-8")
    proc, cpu_s = _check(path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(str(path)) and "refused" in lines[0] and words in lines[0], lines
    assert "Traceback" not in proc.stderr and "RecursionError" not in proc.stderr
    # refused before any expansion: at most the start-up's CPU again (an alias bomb expanded
    # costs minutes); a ratio, as both runs slow down alike on a busy machine
    assert cpu_s < 2.0 * baseline_cpu_s, (cpu_s, baseline_cpu_s)


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_parse_refuses_hostile_yaml_fast(case: str) -> None:
    text, words = HOSTILE[case]
    t0 = time.thread_time()
    with pytest.raises(ConfigError) as info:
        parse_mission(text, "hostile.yaml")
    assert time.thread_time() - t0 < 1.0
    message = str(info.value)
    assert "\n" not in message and message.startswith("hostile.yaml") and words in message


def test_too_many_nodes_is_refused_with_its_line() -> None:
    text = "version: 1\nsim:\n  faults: [" + ", ".join(["0"] * MAX_NODES) + "]\n"
    with pytest.raises(ConfigError, match=r"^big\.yaml:3:\d+: refused: the document has more "
                       rf"than {MAX_NODES:,} nodes"):
        parse_mission(text, "big.yaml")


def test_unreadable_scalars_are_messages_not_crashes() -> None:
    with pytest.raises(ConfigError, match=r"^d\.yaml:4:7: not valid YAML: '2020-99-99' looks "
                       r"like a date but is not one \(month must be in 1\.\.12\); quote it"):
        parse_mission(DEMO_TEXT.replace("name: demo", "name: 2020-99-99", 1), "d.yaml")
    with pytest.raises(ConfigError, match=r"^n\.yaml:3:10: not valid YAML: the number "
                       r"'1111.*has 5,000 digits; quote it to make it text"):
        parse_mission(DEMO_TEXT.replace("version: 1", "version: " + "1" * 5000, 1), "n.yaml")


def test_sensible_aliases_and_depth_still_load() -> None:
    text = (DEMO_TEXT.replace("{id: T1, freq_hz", "{id: &first T1, freq_hz", 1)
            .replace("{id: T1, position_m", "{id: *first, position_m", 1))
    assert "*first" in text
    mission = parse_mission(text, "aliases.yaml")
    assert mission.sim.tags[0].id == "T1" == mission.tags[0].id


def test_refusal_comes_before_the_schema() -> None:
    """A document that is hostile and wrong for the schema is refused as hostile."""
    with pytest.raises(ConfigError, match="alias loop") as info:
        parse_mission("version: 99\nnot_a_key: &a [*a]\n", "both.yaml")
    assert "version" not in str(info.value)
