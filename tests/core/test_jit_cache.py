"""The kernel cache is keyed by every source file of core/: numba checks a cached kernel
against its own file only, so a change to a helper inlined from another file must start a
fresh cache (core.jit)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numba

from mexgen_gcs.core import jit

CORE = Path(jit.__file__).parent


def test_a_change_to_an_inlined_helper_in_another_file_changes_the_cache(tmp_path):
    copy = tmp_path / "core"
    shutil.copytree(CORE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    key = jit.cache_key(copy)
    assert key == jit.cache_key(CORE)  # the same sources, the same cache
    radio = copy / "radio.py"  # distance2_and_gain, inlined into the planner's kernels
    radio.write_text(radio.read_text(encoding="utf-8").replace(
        "def distance2_and_gain", "def distance2_and_gain  ", 1), encoding="utf-8")
    assert jit.cache_key(copy) != key


def test_kernels_are_cached_under_the_key(monkeypatch, tmp_path):
    assert Path(numba.config.CACHE_DIR).name == jit.cache_key()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert jit.cache_dir("abc") == tmp_path / "abc"
    from mexgen_gcs.core.rollout_kernels import update_step

    assert Path(update_step._cache._cache_path).is_relative_to(numba.config.CACHE_DIR)
