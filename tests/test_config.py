"""The shipped Hydra configs compose, and bad ones fail early with one line naming the key."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from parallax.config import ConfigError, compose, validate
from parallax.experiment import seeds_for

CONF = Path(__file__).resolve().parents[1] / "conf"


def test_default_config_composes_and_validates():
    cfg = compose()
    validate(cfg)
    assert cfg.curriculum.name == "multi_5_20"
    assert len(cfg.curriculum.lateral_positions) == 16
    assert cfg.distance.weighting is True


@pytest.mark.parametrize("name", sorted(p.stem for p in (CONF / "curriculum").glob("*.yaml")))
def test_every_curriculum_composes(name):
    validate(compose([f"curriculum={name}"]))


@pytest.mark.parametrize(
    "override,key",
    [
        ("curriculum.lateral_positions=[]", "curriculum.lateral_positions"),
        ("curriculum.lateral_positions=[0.1,0.05]", "curriculum.lateral_positions"),
        ("distance.queue_size=0", "distance.queue_size"),
        ("coder.scales=[medium]", "coder.scales"),
        ("coder.scale_specs.coarse.window=300", "coder.scale_specs.coarse.window"),
        ("device=tpu", "device"),
        ("train.start_jitter_presentations=-1", "train.start_jitter_presentations"),
        ("train.start_jitter_presentations=0.5", "train.start_jitter_presentations"),
        ("train.distance_readout=peak", "train.distance_readout"),
    ],
)
def test_validate_names_the_key(override, key):
    with pytest.raises(ConfigError) as info:
        validate(compose([override]))
    assert info.value.key == key


@pytest.mark.parametrize(
    "override,needle",
    [
        ("curriculum.lateral_positions=[]", "curriculum.lateral_positions"),
        ("coder.scales=[medium]", "coder.scales"),
        ("no_such_key=1", "no_such_key"),
    ],
)
def test_cli_bad_config_fails_before_writing(tmp_path, override, needle):
    run_dir = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "parallax.train", override, f"hydra.run.dir={run_dir}"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert proc.returncode != 0
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    assert needle in lines[0]
    assert not run_dir.exists()


def test_run_names_are_flat_and_short():
    from parallax.config import MAX_RUN_NAME, run_name

    assert run_name("") == "default"
    assert run_name("curriculum=multi_5_10,distance.y=2") == "curriculum=multi_5_10,distance.y=2"
    long_a = ",".join(f"key{i}=value{i}" for i in range(60))
    long_b = long_a + ",extra=1"
    assert len(run_name(long_a)) <= MAX_RUN_NAME and run_name(long_a) != run_name(long_b)
    assert "/" not in run_name("hydra/launcher=joblib")


def test_seeds_for_is_deterministic_and_distinct():
    assert seeds_for(0, 5) == seeds_for(0, 5)
    assert len(set(seeds_for(0, 5))) == 5
    assert seeds_for(0, 5) != seeds_for(1, 5)


def test_a_run_saved_before_a_setting_existed_has_that_settings_old_value():
    from omegaconf import OmegaConf

    from parallax.config import SETTINGS_ADDED_LATER, changed_settings

    current = compose([])
    saved = OmegaConf.create(OmegaConf.to_container(current))
    del saved.distance.lm["weight_decay"]
    del saved.distance["outlier_mads"]
    del saved.env["initial_pan_jitter_deg_per_m"]
    del saved.policy["eye_position_reference_m"]
    del saved.policy["reward_change_gain"]
    del saved.train["start_jitter_presentations"]
    del saved.train["distance_readout"]
    assert set(SETTINGS_ADDED_LATER) == {
        "distance.lm.weight_decay",
        "distance.outlier_mads",
        "env.initial_pan_jitter_deg_per_m",
        "policy.eye_position_reference_m",
        "policy.reward_change_gain",
        "train.start_jitter_presentations",
        "train.distance_readout",
    }
    # the reward-change feature came with a default of its own: a run saved before it had none,
    # so resuming it under the new default is a change of setting, not a silent switch
    assert changed_settings(saved, current) == ["policy.reward_change_gain: 0.0 → 10.0"]
    current = compose(["policy.reward_change_gain=0"])
    assert changed_settings(saved, current) == []
    assert changed_settings(
        saved, compose(["distance.lm.weight_decay=0.01", "policy.reward_change_gain=0"])
    ) == ["distance.lm.weight_decay: 0.0 → 0.01"]


def test_a_run_is_lengthened_only_where_its_perturbation_stays():
    from omegaconf import OmegaConf

    from parallax.config import changed_settings, perturbation_start

    saved = compose(
        [
            "perturbation=rotate_blur",
            "train.presentations=200",
            "perturbation.start_fraction=0.6667",
        ]
    )
    assert perturbation_start(saved) == 133
    # more presentations with the start moved back to presentation 133: a longer continuation
    longer = compose(
        [
            "perturbation=rotate_blur",
            "train.presentations=400",
            "perturbation.start_fraction=0.3325",
        ]
    )
    assert changed_settings(saved, longer) == []
    # more presentations alone would switch the perturbation on at 267, after the run had it on
    moved = compose(
        [
            "perturbation=rotate_blur",
            "train.presentations=400",
            "perturbation.start_fraction=0.6667",
        ]
    )
    assert changed_settings(saved, moved) == [
        "the perturbation's start presentation (perturbation.start_fraction × train.presentations): 133 → 267"
    ]
    unperturbed = OmegaConf.merge(saved, {"perturbation": {"start_fraction": None}})
    assert any("start presentation" in change for change in changed_settings(saved, unperturbed))
