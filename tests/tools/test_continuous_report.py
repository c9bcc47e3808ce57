"""python -m parallax.tools.report.continuous: its tables from a report, and bad input."""

from __future__ import annotations

import pytest

from parallax.tools.report.continuous import (
    EYE_PARTS,
    RANGES,
    _spread,
    main,
    markdown,
    paired_against,
)


def _report():
    cell = _spread([1.0, 2.0, 3.0])
    row = {
        "speed_m": 0.002,
        "iterations": 101,
        "target_turn_deg": 0.038,
        "eye_mae_deg": 0.1,
        "distance_total": 2.0,
        "tracking_error_deg": 0.12,
        "retinal_slip_deg": 0.01,
    }
    return {
        "runs": ["a", "b", "c"],
        "recipe_runs": ["r"],
        "tracking": {"5": {"continuous": cell, "pick_and_place": _spread([0.5])}},
        "distance": {
            "continuous": {
                **{k: cell for k in RANGES + EYE_PARTS},
                "iterations": 101,
                "training_iterations": 9,
            },
            "pick_and_place": {
                **{k: cell for k in RANGES + EYE_PARTS},
                "iterations": 480,
                "training_iterations": 9,
            },
        },
        "pairing": {"reference": row, "consecutive": row},
        "speed": [row],
        "readouts": {"pursuit gain": cell},
        "stopping": [{"rule": "fixed: to 5 cm", "travel_cm": cell, "total": cell}],
    }


def test_the_spread_is_the_mean_and_the_sample_sd():
    cell = _spread([1.0, 2.0, 3.0])
    assert (cell["mean"], cell["sd"], cell["n"]) == (2.0, 1.0, 3)


def test_the_tables_hold_every_row():
    text = markdown(_report())
    assert "| 5 | 2.000 ± 1.000 | 0.500 |" in text
    assert "| continuous (last pan) | 2.00 ± 1.00 |" in text
    assert "| 101 | 9 | 2.000 ± 1.000 |" in text
    assert "| consecutive | 0.100 | 2.00 | 0.120 | 0.0100 |" in text
    assert "| 2 | 101 | 0.038 |" in text
    assert "| fixed: to 5 cm | 2.0 ± 1.0 | 2.00 ± 1.00 |" in text


def test_a_folder_without_runs_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(
            [str(tmp_path), "--pairing", str(tmp_path), "--speeds", str(tmp_path)]
            + ["--recipe", str(tmp_path), "--markdown", str(tmp_path / "out.md")]
        )
    assert stop.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not (tmp_path / "out.md").exists()


def _evaluated_run(seed: int, per_distance: dict[str, float]) -> dict:
    from omegaconf import OmegaConf

    return {
        "cfg": OmegaConf.create({"seed": seed}),
        "eval": {"distance": {"per_distance": per_distance}},
    }


def test_the_sweep_is_paired_with_pick_and_place_on_shared_seeds_and_photographs():
    grid = [f"{3 + 0.1 * k:.2f}" for k in range(40)]
    sweeps = [
        _evaluated_run(s, {d: 2.0 + s + 0.01 * k for k, d in enumerate(grid)}) for s in (0, 1, 2)
    ]
    # pick-and-place is 1 point worse at every photograph on seeds 0 and 1; seed 4 has no sweep
    picks = [
        _evaluated_run(s, {d: 3.0 + s + 0.01 * k for k, d in enumerate(grid)}) for s in (0, 1, 4)
    ]
    paired = paired_against(sweeps, picks)
    assert paired["seed_list"] == [0, 1] and paired["samples"] == 80
    assert paired["mean"] == pytest.approx(-1.0)
    assert paired["high"] < 0 and paired["verdict"] == "a lower"
    report = _report()
    report["paired"] = {"pick_and_place": paired}
    assert "| pick-and-place (best-encoded pan) | 0, 1 | -1.00 |" in markdown(report)
