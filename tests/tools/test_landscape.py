"""python -m parallax.tools.analysis.landscape: the reward around α* of a trained run's frozen
coder and policy."""

from __future__ import annotations

import json

import numpy as np
import pytest

from parallax.tools.analysis import landscape


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(tmp_path_factory.mktemp("run"), ["train.presentations=2"])


def test_sweep_is_centred_on_the_target_and_reads_only(tiny_run):
    before = (tiny_run / "checkpoint.pt").read_bytes()
    result = landscape.sweep(tiny_run, distances=(3.0, 9.0), textures=2, span=0.2, step=0.1)
    assert result["offsets_deg"] == pytest.approx([-0.2, -0.1, 0.0, 0.1, 0.2])
    assert len(result["peak_offsets_deg"]) == 4 and set(result["peak_offsets_deg"]) <= set(
        result["offsets_deg"]
    )
    # the reward is minus the summed errors of the scales (eq. 6)
    summed = np.sum([result["errors"][s] for s in result["scales"]], axis=0)
    np.testing.assert_allclose(result["reward"], -summed, rtol=1e-5)
    # E_π[a] lies within the action set
    assert all(-0.2 <= a <= 0.2 for a in result["mean_step_deg"])
    assert (tiny_run / "checkpoint.pt").read_bytes() == before


def test_cli_prints_the_peak_and_refuses_a_missing_checkpoint(tiny_run, tmp_path, capsys):
    out = tmp_path / "landscape.json"
    assert (
        landscape.main(
            [
                str(tiny_run),
                "--distances",
                "5",
                "--textures",
                "1",
                "--span",
                "0.1",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    assert "reward peak − α*" in capsys.readouterr().out
    assert json.loads(out.read_text())["lateral_position_m"] == pytest.approx(0.05)
    assert landscape.main([str(tmp_path)]) == 2
    assert "has no checkpoint.pt" in capsys.readouterr().err
    assert landscape.main([str(tiny_run), str(tmp_path)]) == 2  # every run is checked first
    assert "has no checkpoint.pt" in capsys.readouterr().err


def test_several_runs_are_compared_in_one_plot(tiny_run, tmp_path, capsys):
    png, out = tmp_path / "landscape.png", tmp_path / "both.json"
    assert (
        landscape.main(
            [
                str(tiny_run),
                str(tiny_run),
                "--distances",
                "5",
                "--textures",
                "1",
                "--span",
                "0.1",
                "--plot",
                str(png),
                "--json",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert printed.count(f"== {tiny_run}") == 2 and "plot:" in printed
    assert png.stat().st_size > 0
    both = json.loads(out.read_text())
    assert len(both) == 2 and both[0]["mean_step_deg"] == both[1]["mean_step_deg"]
