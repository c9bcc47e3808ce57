"""The shipped Hydra configs compose and validate; run names; reading a run's config back."""

from __future__ import annotations

from pathlib import Path

import pytest
from omegaconf import OmegaConf

from parallax.config import ConfigError, compose, flatten, validate
from parallax.parts import seeds_for

CONF = Path(__file__).resolve().parents[2] / "conf"
CHECKPOINTS = CONF.parent / "docs" / "results" / "checkpoints"


def test_default_config_composes_and_validates():
    cfg = compose()
    validate(cfg)
    assert cfg.curriculum.name == "multi_5_20"
    assert len(cfg.curriculum.lateral_positions) == 16
    assert cfg.distance.weighting is True


def _own_settings(group: str, name: str) -> dict:
    """The settings a config file of ``group`` sets itself (its defaults list aside), flattened
    to dotted keys from the root of the config."""
    path = CONF / group / f"{name}.yaml"
    own = OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    own.pop("defaults", None)
    if not own:  # a file that only names the schema's defaults
        return {}
    is_global = path.read_text().startswith("# @package _global_")
    return flatten(own if is_global else {group: own})


@pytest.mark.parametrize("name", sorted(p.stem for p in (CONF / "experiment").glob("*.yaml")))
def test_every_experiment_composes_with_its_own_settings(name):
    cfg = compose([f"experiment={name}"])
    validate(cfg)
    # no later entry of the defaults list overrides what the file itself sets
    composed = flatten(OmegaConf.to_container(cfg, resolve=True))
    own = _own_settings("experiment", name)
    assert own and {key: composed.get(key) for key in own} == own


@pytest.mark.parametrize("name", sorted(p.stem for p in (CONF / "curriculum").glob("*.yaml")))
def test_every_curriculum_composes_with_its_own_settings(name):
    cfg = compose([f"curriculum={name}"])
    validate(cfg)
    composed = flatten(OmegaConf.to_container(cfg, resolve=True))
    own = _own_settings("curriculum", name)
    assert {key: composed.get(key) for key in own} == own


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
        ("train.distance_readout=peak", "train.distance_readout"),
    ],
)
def test_validate_names_the_key(override, key):
    with pytest.raises(ConfigError) as info:
        validate(compose([override]))
    assert info.value.key == key


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


def test_a_saved_config_that_lacks_a_setting_is_refused_not_filled_in(tmp_path):
    from omegaconf import OmegaConf

    from parallax.config import load_run_config

    saved = OmegaConf.to_container(compose([]))
    (tmp_path / "config.yaml").write_text(OmegaConf.to_yaml(saved))
    assert load_run_config(tmp_path).distance.lm.weight_decay == 0.1
    del saved["distance"]["lm"]["weight_decay"]
    saved["distance"]["outlier_mads"] = None
    (tmp_path / "config.yaml").write_text(OmegaConf.to_yaml(saved))
    with pytest.raises(ValueError) as error:
        load_run_config(tmp_path)
    assert "lacks distance.lm.weight_decay" in str(error.value)
    assert "does not know: distance.outlier_mads" in str(error.value)


def test_a_saved_config_that_lacks_a_setting_that_changes_no_result_takes_its_default(tmp_path):
    from omegaconf import OmegaConf

    from parallax.config import load_run_config

    saved = OmegaConf.to_container(compose([]))
    del saved["train"]["stop_after_non_finite"], saved["train"]["resume_from"]
    (tmp_path / "config.yaml").write_text(OmegaConf.to_yaml(saved))
    loaded = load_run_config(tmp_path)
    assert (loaded.train.stop_after_non_finite, loaded.train.resume_from) == (3, "latest")


def test_a_changed_setting_is_named_when_resuming():
    from parallax.config import changed_settings

    saved = compose(["policy.reward_change_gain=0"])
    assert changed_settings(saved, compose([])) == ["policy.reward_change_gain: 0.0 → 10.0"]
    assert changed_settings(saved, compose(["policy.reward_change_gain=0", "device=cpu"])) == []


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
        "the perturbation's start presentation (perturbation.start_fraction × "
        "train.presentations): 133 → 267"
    ]
    unperturbed = OmegaConf.merge(saved, {"perturbation": {"start_fraction": None}})
    assert any("start presentation" in change for change in changed_settings(saved, unperturbed))
    # a checkpoint that has not reached the start (133, nor 267) may move it; one past it may not
    assert changed_settings(saved, moved, reached=133) == []
    assert changed_settings(saved, moved, reached=134) == changed_settings(saved, moved)
    assert changed_settings(saved, unperturbed, reached=100) == []
    assert changed_settings(saved, moved, schedule=False) == []


@pytest.mark.parametrize(
    "run", sorted(p.parent.name for p in CHECKPOINTS.glob("*/config.yaml")), ids=str
)
def test_the_committed_runs_hold_every_setting_and_resume_under_their_experiment(run):
    from parallax.config import changed_settings, load_run_config

    saved = load_run_config(CHECKPOINTS / run)  # refuses a config that lacks a setting
    experiment = run.rsplit("_seed", 1)[0]  # folders are named <experiment>_seed<n>
    current = compose([f"experiment={experiment}", f"seed={saved.seed}"])
    assert changed_settings(saved, current) == []
