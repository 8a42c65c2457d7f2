"""Every numeric and address option of every sub-command refuses NaN, infinity, a negative
number, a float that overflows (1e400), an absurdly large whole number and text while the command
line is parsed: one line naming the option and the value, exit status 2, never a traceback, a
hang or a run that would never finish. A few of them end to end, as a user types them."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from isaac.app.cli import build_parser

REPO = Path(__file__).resolve().parents[1]
HUGE = "9" * 30  # a whole number no option means

# command line before the option, option, values it must refuse (each beside the six above
# where it refuses those: "inf", a text word, ...). A value an option takes is not listed.
BAD = ["nan", "inf", "-inf", "-1", "1e400", "abc", ""]
OPTIONS = [
    (["run", "scene.yaml"], "--steps", BAD + [HUGE, "1.5", "1e3"]),
    (["inspect", "log.mcap"], "--step", BAD + ["1.5"]),
    (["replay", "log.mcap"], "--from-step", BAD),
    (["replay", "log.mcap"], "--to-step", BAD),
    (["replay", "log.mcap"], "--tolerance", BAD),
    (["replay", "log.mcap"], "--max-reported", BAD + ["0"]),
    (["diff", "a.mcap", "b.mcap"], "--tolerance", BAD),
    (["view", "log.rrd"], "--port", BAD + [HUGE, "65536"]),
    (["view", "log.rrd"], "--grpc-port", BAD + [HUGE, "65536"]),
    (["view", "log.rrd"], "--bind", ["999.1.1.1", "example.org", "", "127.0.0.1:80", "[::1]"]),
    (["tradeoff", "scene.yaml"], "--reference-dt", BAD + ["0", "2", HUGE]),
    (["tradeoff", "scene.yaml"], "--duration", BAD + ["0"]),
    (["tradeoff", "scene.yaml"], "--repeats", BAD + ["0", HUGE]),
    (["tradeoff", "scene.yaml"], "--min-time", BAD + [HUGE]),
    (["sweep", "sweep.yaml"], "--workers", BAD + ["0", HUGE]),
    (["sweep", "sweep.yaml"], "--chunk", BAD + ["0"]),
    (["sweep", "sweep.yaml"], "--scheduler", ["foo", "", "tcp://127.0.0.1", "tcp://h:99999"]),
]
CASES = [
    pytest.param(before, option, value, id=f"{before[0]} {option} {value or repr(value)}")
    for before, option, values in OPTIONS
    for value in values
]


@pytest.mark.parametrize("before, option, value", CASES)
def test_a_bad_option_value_is_one_line_and_exit_2(before, option, value, capsys):
    parser = build_parser(before[0])
    with pytest.raises(SystemExit) as stop:
        parser.parse_args([*before, f"{option}={value}"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    (line,) = err.splitlines()
    assert line.startswith(f"isaac {before[0]}: error: argument {option}: "), line
    assert repr(value) in line  # the value, as given


@pytest.mark.parametrize(
    "before, option, value, parsed",
    [
        (["replay", "log.mcap"], "--tolerance", "0", 0.0),
        (["replay", "log.mcap"], "--tolerance", "1e-9", 1e-9),
        (["run", "scene.yaml"], "--steps", "0", 0),
        (["run", "scene.yaml"], "--steps", "100000000", 100_000_000),
        (["view", "log.rrd"], "--bind", "localhost", "127.0.0.1"),
        (["view", "log.rrd"], "--bind", "::1", "::1"),
        (["view", "log.rrd"], "--port", "0", 0),
        (["view", "log.rrd"], "--port", "65535", 65535),
        (["tradeoff", "scene.yaml"], "--min-time", "0", 0.0),
        (["sweep", "sweep.yaml"], "--scheduler", "tcp://[::1]:8786", "tcp://[::1]:8786"),
    ],
)
def test_a_good_option_value_is_taken_as_it_says(before, option, value, parsed):
    args = build_parser(before[0]).parse_args([*before, option, value])
    got = getattr(args, option.lstrip("-").replace("-", "_"))
    assert got == parsed and type(got) is type(parsed)
    assert not isinstance(got, float) or math.isfinite(got)


def isaac(*args):
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,  # each refuses at once; a run of 10^30 steps would not end
    )


def one_line_refusal(result, *words):
    assert result.returncode == 2, (result.returncode, result.stderr)
    (line,) = result.stderr.splitlines()
    assert "Traceback" not in line and all(w in line for w in words), line
    return line


def test_replay_refuses_an_infinite_tolerance_before_comparing(tmp_path):
    # with X = inf, X * (1 + |a|) is NaN where a value is 0: equal values diverged
    for value in ("inf", "1e400", "nan"):
        line = one_line_refusal(isaac("replay", "no-such.mcap", "--tolerance", value), value)
        assert "--tolerance: must be a finite number >= 0" in line


def test_replay_log_refuses_an_infinite_tolerance_from_a_program():
    from isaac.errors import LogError
    from replay.compare import diff_logs, replay_log

    for call in (
        lambda t: replay_log("x.mcap", tolerance=t),
        lambda t: diff_logs("a", "b", tolerance=t),
    ):
        with pytest.raises(LogError, match="--tolerance must be a finite number >= 0, got inf"):
            call(math.inf)


def test_run_refuses_more_steps_than_a_scene_may_hold_instead_of_running_forever():
    one_line_refusal(
        isaac("run", "scenes/bounce.yaml", "--quiet", "--steps", HUGE), "--steps", HUGE
    )


def test_tradeoff_refuses_an_infinite_or_endless_duration_in_one_line():
    one_line_refusal(isaac("tradeoff", "scenes/bounce.yaml", "--duration", "inf"), "--duration")
    # finite, but 2.4e11 steps of the finest dt run: refused before anything runs
    line = one_line_refusal(
        isaac("tradeoff", "scenes/bounce.yaml", "--duration", "1e9", "--no-plot"), "--duration"
    )
    assert "more than the 100000000 a run may take" in line


def test_a_usage_error_is_one_line_naming_the_option():
    one_line_refusal(isaac("inspect", "x.mcap", "--step", "abc"), "--step", "'abc'")
    one_line_refusal(isaac("sweep", "x.yaml", "--workers", HUGE), "--workers", HUGE)
    one_line_refusal(isaac("run"), "scene", "isaac run --help")
