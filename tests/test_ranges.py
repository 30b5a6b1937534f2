"""One range grammar a:b:n for sweep --dt, tune --speeds and extremes --axis (impactval.ranges)."""
from __future__ import annotations

import math

import pytest
from click.testing import CliRunner

from impactval import ranges
from impactval import sweep as sw
from impactval.cli import main
from impactval.errors import ImpactvalError
from impactval.extremes import parse_axis as extremes_axis
from impactval.tune import parse_speeds

from hostile_cases import BAD_RANGE_CASES

SAME_TEXTS = ["1e-5:1e-8:4", "1e-8:1e-5:4", "2e-3:1e-3:5", "1e-4:1e-6:7,5e-3", "3e-3,1e-3:1e-2:3"]


def _three(text: str) -> tuple[list[float], list[float], list[float], list[float], list[float]]:
    from impactval.cli import _parse_dts

    sweep_dt = sorted(sw.parse_axis(text, "dt", "float", ["mujoco"])["mujoco"])
    speeds = list(parse_speeds(text))
    axis_dt = list(extremes_axis("dt=" + text, 4e-5).values)
    axis_v = list(extremes_axis("velocity=" + text).values)
    run_dt = sorted(_parse_dts(text))
    return sweep_dt, speeds, axis_dt, axis_v, run_dt


@pytest.mark.parametrize("text", SAME_TEXTS)
def test_the_three_commands_read_the_same_values(text):
    """sweep --dt, tune --speeds, extremes --axis and run --dt."""
    sweep_dt, speeds, axis_dt, axis_v, run_dt = _three(text)
    assert sweep_dt == speeds == axis_dt == axis_v == run_dt          # the same floats, not merely close
    assert len(set(sweep_dt)) == len(sweep_dt)


def test_a_range_is_geometric_both_ends_included_either_direction():
    assert ranges.parse_range("1e-5:1e-8:4", "--dt") == [1e-5, 1e-6, 1e-7, 1e-8]    # exact decades
    assert ranges.parse_range("1e-8:1e-5:4", "--dt") == [1e-8, 1e-7, 1e-6, 1e-5]
    vals = ranges.parse_range("0.1:10:5", "--speeds")
    ratios = [b / a for a, b in zip(vals, vals[1:])]
    assert vals[0] == 0.1 and vals[-1] == 10.0
    assert all(abs(r / math.sqrt(10) - 1) < 1e-11 for r in ratios)   # 10^(1/2) per step, 12 digits kept
    vals = ranges.parse_range("2e-3:1e-3:5", "--dt")
    assert all(abs(b / a / 2 ** -0.25 - 1) < 1e-11 for a, b in zip(vals, vals[1:]))


BAD_FORMS = BAD_RANGE_CASES     # (text, words the one line must hold besides the option), shared


def _cli_line(args: list[str]) -> str:
    res = CliRunner().invoke(main, args, catch_exceptions=True)
    assert res.exit_code == 2, (args, res.output, res.exception)
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("impactval: error:"), (args, res.output)
    return lines[0]


@pytest.mark.parametrize("text, words", BAD_FORMS, ids=[t for t, _ in BAD_FORMS])
def test_every_bad_form_is_exit_2_with_one_line_naming_the_option(tmp_path, text, words):
    commands = {
        "--dt": ["sweep", "plate_steel", "--dt", text, "--out", str(tmp_path / "s")],
        "--speeds": ["tune", "mujoco", "plate_steel", "--speeds", text, "--out", str(tmp_path / "t")],
        "--axis velocity": ["extremes", "plate_steel", "--axis", f"velocity={text}", "--out", str(tmp_path / "e")],
        "run --dt": ["run", "plate_steel", "--dt", text, "--out", str(tmp_path / "r")],
    }
    for option, args in commands.items():
        line = _cli_line(args)
        option = option.removeprefix("run ")
        assert option in line and words in line, (option, line)
    assert not any((tmp_path / d).exists() and any((tmp_path / d).iterdir()) for d in "ster")   # refused before work


def test_old_extremes_range_is_refused_naming_the_new_form():
    with pytest.raises(ImpactvalError, match=r"e.g. --axis velocity=0.1:10:5"):
        extremes_axis("velocity=0.1..10:5")
    with pytest.raises(ImpactvalError, match=r"--axis dt=t_m/1e4:t_m:9"):
        extremes_axis("dt=t_m/1e4..t_m", 4e-5)
    line = _cli_line(["extremes", "plate_steel", "--axis", "velocity=0.1..10:5"])
    assert "a:b:n" in line


def test_range_items_mix_with_lists_and_prefixes():
    ax = sw.parse_axis("1e-6,pybullet.1e-7:1e-9:3", "dt", "float", ["mujoco", "pybullet"])
    assert ax == {"mujoco": [1e-6], "pybullet": [1e-7, 1e-8, 1e-9]}
    assert parse_speeds("0.5, 0.1:10:3, 1") == (0.1, 0.5, 1.0, 10.0)
    assert extremes_axis("stiffness=pmma,1e9:1e11:3").values == ("pmma", 1e9, 1e10, 1e11)
    assert extremes_axis("target.velocity=-1,0").values == (-1.0, 0.0)   # a list may cross zero where the field may
    with pytest.raises(ImpactvalError, match="--axis stiffness: give at least one"):
        extremes_axis("stiffness=,")
