"""`isaac run` says in one line, on stderr, when it is about to compile the engine's kernels
(numba's cache lacks them: a first run takes 15-40 s in all), and says nothing when they are cached
or with --quiet."""

from __future__ import annotations

import pytest
from close_gate import TINY_SCENE

import isaac.engine.compile_ahead as compile_ahead
from isaac.app.cli import main

NOTICE = "compiling the engine's kernels"


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY_SCENE)
    return path


def _cache_looks_cold(monkeypatch, cold: bool) -> None:
    """The first `is_cold` question (the notice's) answered `cold`; the later ones (the
    simulation's own compile-ahead check) see the real, warm cache."""
    answers = iter([cold])
    real = compile_ahead.is_cold
    monkeypatch.setattr(compile_ahead, "is_cold", lambda kernel: next(answers, real(kernel)))


@pytest.mark.parametrize("cold", [True, False])
def test_a_run_says_it_compiles_only_when_the_cache_lacks_the_kernels(
    scene, monkeypatch, capsys, cold
):
    _cache_looks_cold(monkeypatch, cold)
    assert main(["run", str(scene), "--steps", "2"]) == 0
    err = capsys.readouterr().err
    assert (NOTICE in err) == cold
    if cold:
        line = next(ln for ln in err.splitlines() if NOTICE in ln)
        # what to expect, in one line
        assert "first steps come after about 10 s" in line and "15-40 s in all" in line


def test_quiet_runs_say_nothing_about_compiling(scene, monkeypatch, capsys):
    _cache_looks_cold(monkeypatch, True)
    assert main(["run", str(scene), "--steps", "2", "--quiet"]) == 0
    assert NOTICE not in capsys.readouterr().err
