"""python -m parallax.tools.analysis.network_calls: what each retraining of the distance network
did, read from a run's metrics.jsonl."""

from __future__ import annotations

import json

import pytest
from omegaconf import OmegaConf

from parallax.config.schema import Config
from parallax.tools.analysis import network_calls as nc


def _run(tmp_path, fits, validation_fraction=0.15, perturbed_from=None, warm_start=True):
    """fits: (trained, epochs, stop rule or "") per presentation."""
    cfg = OmegaConf.structured(Config)
    cfg.distance.validation_fraction = validation_fraction
    cfg.distance.warm_start = warm_start
    cfg.distance.max_fail = 6
    (tmp_path / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    lines = []
    for k, (trained, epochs, stop) in enumerate(fits, start=1):
        line = {
            "presentation": k,
            "perturbed": perturbed_from is not None and k >= perturbed_from,
            "distance_error": {"total": float(k)},
            "lm_trained": float(trained),
            "lm_epochs": float(epochs),
        }
        line |= {f"lm_stopped_{rule}": float(rule == stop) for rule in nc.RULES}
        lines.append(line)
    (tmp_path / "metrics.jsonl").write_text("".join(json.dumps(l) + "\n" for l in lines))
    return tmp_path


FITS = [
    (0, 0, ""),  # the queue is not full yet: no fit
    (1, 40, "max_fail"),  # the first fit, from random weights
    (1, 6, "max_fail"),  # no epoch beat the starting weights: unchanged
    (1, 8, "max_fail"),  # its second epoch was the best
    (1, 6, "max_fail"),
    (1, 3, "min_grad"),
]


def test_a_fit_that_fails_max_fail_times_from_its_start_leaves_the_network(tmp_path):
    before, after = nc.network_calls(_run(tmp_path, FITS, perturbed_from=5))
    assert (before["first"], before["last"], before["fits"]) == (1, 4, 3)
    assert before["unchanged"] == pytest.approx(1 / 3)
    assert before["epochs"] == pytest.approx(54 / 3)
    assert before["stopped"]["max_fail"] == 1.0 and before["distance_error"] == 4.0
    assert after["unchanged"] == pytest.approx(1 / 2)
    assert after["stopped"]["min_grad"] == pytest.approx(1 / 2)


@pytest.mark.parametrize("settings", [{"validation_fraction": 0.0}, {"warm_start": False}])
def test_blocks_and_no_unchanged_share_without_a_validation_stop_or_a_warm_start(
    tmp_path, capsys, settings
):
    run = _run(tmp_path, FITS, **settings)
    blocks = nc.network_calls(run, blocks=4)
    assert [(b["first"], b["last"]) for b in blocks] == [(1, 4), (5, 6)]
    assert all(b["unchanged"] is None for b in blocks)
    nc.main([str(run), "--blocks", "4"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith(f"| {run}")]
    assert len(rows) == 2 and "| 5–6 | 2 | – |" in rows[1]


@pytest.mark.parametrize("args", [["--blocks", "0"], []])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args):
    run = tmp_path / "run"
    run.mkdir()
    if args:  # a good run, a bad option
        _run(run, FITS)
    with pytest.raises(SystemExit) as exit_info:
        nc.main([str(run), *args])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_a_replay_reads_the_same_figures_and_each_blocks_own_predictions(tmp_path, capsys):
    from tests.conftest import train_tiny_run

    run = train_tiny_run(
        tmp_path / "run",
        [
            "train.presentations=8",
            "distance.validation_fraction=0.34",
            "distance.max_fail=2",
            "distance.initial_epochs=50",
            "distance.epochs_per_call=50",
        ],
    )
    trained = nc.network_calls(run, blocks=4)
    as_trained = nc.replayed_network_calls(run, [], blocks=4)
    for mine, theirs in zip(as_trained, trained, strict=True):
        assert (mine["fits"], mine["unchanged"], mine["epochs"]) == (
            theirs["fits"],
            theirs["unchanged"],
            theirs["epochs"],
        )
        assert mine["eye_mae"] == theirs["eye_mae"] is not None
    assert as_trained[-1]["distance_error"] is not None
    fresh = nc.replayed_network_calls(run, ["distance.warm_start=false"], blocks=4)
    assert all(row["unchanged"] is None for row in fresh)  # a new network is never the old one
    nc.main([str(run), "--blocks", "4", "--replay", "distance.warm_start=false"])
    out = capsys.readouterr().out
    assert "distance.warm_start=false" in out and out.count(str(run)) == 2
    # a run still training (no summary yet) is replayed as far as its record goes
    (run / "summary.json").unlink()
    lines = (run / "metrics.jsonl").read_text().splitlines(keepends=True)
    (run / "metrics.jsonl").write_text("".join(lines[:6]))
    so_far = nc.replayed_network_calls(run, ["distance.warm_start=false"], blocks=4)
    assert [row["fits"] for row in so_far] == [row["fits"] for row in fresh[:1]] + [
        sum(1 for line in lines[4:6] if json.loads(line).get("lm_trained"))
    ]
    assert so_far[0] == fresh[0]


def test_what_the_eye_allows_is_small_for_a_perfect_eye_and_large_for_a_blind_one():
    from parallax.config import compose
    from parallax.tools.analysis.eye_bound import perfect_pans
    from tests.conftest import TINY

    cfg = compose([*TINY, "distance.initial_epochs=200"])
    laterals = tuple(float(l) for l in cfg.curriculum.lateral_positions)
    distances = [3.0 + 0.1 * (k % 71) for k in range(60)]
    pans = perfect_pans(laterals, tuple(distances))
    records = [{"pans": [list(p)], "distances": [d]} for p, d in zip(pans, distances)]
    perfect = nc.eye_allows(cfg, records, "pans")
    blind = [{**r, "pans": [[0.0] * len(laterals)]} for r in records]  # the same vector each time
    assert perfect["median"] < 5.0 < nc.eye_allows(cfg, blind, "pans")["median"]
    assert nc.eye_allows(cfg, records[:19], "pans") is None  # too few for five folds


def test_the_eyes_vectors_split_into_a_learnable_bias_a_scatter_and_misses():
    from parallax.config import compose
    from parallax.tools.analysis.eye_bound import perfect_pans
    from tests.conftest import TINY

    cfg = compose(TINY)
    laterals = tuple(float(l) for l in cfg.curriculum.lateral_positions)
    distances = [3.0 + 0.5 * k for k in range(10)]
    undershoot = perfect_pans(laterals, tuple(distances)) - 0.3  # a bias alone
    records = [{"pans": [list(p)], "distances": [d]} for p, d in zip(undershoot, distances)]
    alone = nc.eye_figures(cfg, records, "pans")
    assert alone["bias"] == pytest.approx(-0.3) and alone["mae"] == pytest.approx(0.3)
    assert alone["scatter"] == pytest.approx(0.0, abs=1e-9) and alone["missed"] == 0.0
    records[4]["pans"][0][0] += 2.0  # one presentation misses α* by 1.7° at its first position
    missed = nc.eye_figures(cfg, records, "pans")
    assert missed["missed"] == pytest.approx(0.1) and missed["scatter"] > 0.1
    assert nc.eye_figures(cfg, [{"distances": [3.0]}], "pans") is None  # no vectors logged
    where = nc.eye_by_position(cfg, records, "pans")  # the miss is at the first position, at 5 m
    first, *others = where["positions"].values()
    assert first["missed"] == pytest.approx(0.1) and all(o["missed"] == 0.0 for o in others)
    assert all(o["bias"] == pytest.approx(-0.3) for o in others)
    assert where["ranges"] == {"3-4.9": 0.0, "5-6.9": 0.25, "7-10": 0.0}
