"""python -m parallax.tools.analysis.policy_collapse: when the actor reached its ball and the
policy turned deterministic, read from a run's metrics.jsonl."""

from __future__ import annotations

import json

import pytest
from omegaconf import OmegaConf

from parallax.config.schema import Config
from parallax.tools.analysis import policy_collapse as pc


def _run(tmp_path, radius, norms, entropies, maes, perturbed_from=None):
    cfg = OmegaConf.structured(Config)
    cfg.policy.actor_projection_radius = radius
    cfg.metrics.summary_trials = 4
    (tmp_path / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    lines = []
    for k, (norm, entropy, mae) in enumerate(zip(norms, entropies, maes, strict=True), start=1):
        lines.append(
            {
                "presentation": k,
                "perturbed": perturbed_from is not None and k >= perturbed_from,
                "policy_actor_norm": norm,
                "policy_entropy": entropy,
                "mae_recent": mae,
                "mae_recent_per_position": {"5": mae, "10": 2 * mae},
                "pans": [[0.0, 0.0]],  # one robot, two positions: two trials a presentation
            }
        )
    (tmp_path / "metrics.jsonl").write_text("".join(json.dumps(l) + "\n" for l in lines))
    return tmp_path


def test_the_first_crossings_and_the_early_best_once_the_window_is_full(tmp_path):
    run = _run(
        tmp_path,
        radius=100.0,
        norms=[1, 50, 99.5, 100, 100, 100],
        entropies=[1.9, 1.0, 0.5, 0.005, 0.001, 0.001],
        maes=[0.1, 0.7, 0.4, 0.9, 3.0, 0.2],  # presentation 1 has two trials: not a full window
        perturbed_from=6,
    )
    c = pc.collapse(run, early=4)
    assert c["ball_at"] == 3 and c["entropy_at"] == 4
    assert c["early_best"] == (0.4, 3)
    # the last presentation before the perturbation
    assert c["last"] == (3.0, 6.0) and c["presentations"] == 5


def test_never_crossed_and_no_ball(tmp_path):
    run = _run(tmp_path, radius=None, norms=[1, 2, 3], entropies=[1.9, 1.9, 1.9], maes=[1, 1, 1])
    c = pc.collapse(run)
    assert c["ball_at"] is None and c["entropy_at"] is None and c["radius"] is None


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        pc.main([str(tmp_path)])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert str(tmp_path) in line
