"""The experiment files are the record of every result: the paper's algorithm with the settings
it leaves open taken from the code it builds on (conf/experiment/paper_*.yaml) or chosen by us
(unsourced_*.yaml), our recipe (recipe_*.yaml, quickstart.yaml) and, beyond the paper, distance
from the robot's own body (embodied_*.yaml), a robot that plans its movement (planned_*.yaml)
and a body that sweeps L while the eye pursues (continuous_*.yaml)."""

from pathlib import Path

import pytest
from omegaconf import OmegaConf

from parallax.config import RESULT_NEUTRAL_KEYS, compose, flatten, upgrade_saved, validate

EXPERIMENTS = Path(__file__).resolve().parents[1] / "conf" / "experiment"
SETUPS = [
    "single_5",
    "single_7",
    "single_10",
    "single_13",
    "single_15",
    "single_20",
    "multi_5_10",
    "multi_5_20",
    "multi_5_20_weighted",
]
CHECKPOINTS = Path(__file__).resolve().parents[1] / "docs" / "results" / "checkpoints"
STEP_SIZES = Path(__file__).resolve().parents[1] / "conf" / "step_sizes"
DICTIONARY_RATES = STEP_SIZES.parent / "dictionary_rate"
#: The body sweeping L, compared with the recipe before its perturbation: it has none.
CONTINUOUS = "continuous_multi_5_20_weighted"
#: The families over the paper's set-ups, each <family>_<setup>.yaml for every set-up.
FAMILIES = ["paper", "unsourced", "recipe"]


def _flat(overrides):
    cfg = compose(overrides)
    validate(cfg)
    return flatten(OmegaConf.to_container(cfg, resolve=True))


def test_every_setup_has_every_family_and_nothing_else():
    names = sorted(p.stem for p in EXPERIMENTS.glob("*.yaml"))
    expected = sorted(
        [f"{family}_{s}" for family in FAMILIES for s in SETUPS]
        + ["paper_algorithm", "unsourced_algorithm", "quickstart"]
        + ["embodied_multi_5_20_weighted", "embodied_growth", "planned_multi_5_20_weighted"]
        + ["geometric_multi_5_20_weighted"]
        + [CONTINUOUS]
        + ["sensitivity_single_5", "sensitivity_multi_5_10"]
        + [f"without_{improvement}" for improvement in WITHOUT]
    )
    assert names == expected


#: The recipe on 5–20 cm with weighting less each improvement of docs/improvements.md §1–7 that
#: it uses (§3, the warm-up of random starts, is the single positions'), and the settings each
#: one puts back to the unsourced family's (whose records the without_* records are compared with).
WITHOUT = {
    "step_sizes": {
        "policy.advantage_lr",
        "policy.actor_lr",
        "policy.weight_decay",
        "policy.actor_projection_radius",
        "policy.discount",
    },
    "state_difference": {"policy.feature_norm"},
    "lm_weight_decay": {"distance.lm.weight_decay"},
    "eye_position": {"policy.eye_position_reference_m"},
    "reward_change": {"policy.reward_change_gain"},
    "best_readout": {"train.distance_readout"},
}


@pytest.mark.parametrize("improvement", sorted(WITHOUT))
def test_each_leave_one_out_file_puts_back_the_unsourced_settings_of_one_improvement(improvement):
    recipe = _flat(["experiment=recipe_multi_5_20_weighted"])
    without = _flat([f"experiment=without_{improvement}"])
    differ = {
        k
        for k in set(recipe) | set(without)
        if recipe.get(k) != without.get(k) and k not in RESULT_NEUTRAL_KEYS
    }
    assert differ == WITHOUT[improvement]
    unsourced = _flat(["experiment=unsourced_multi_5_20_weighted"])
    for key in differ:
        if key == "policy.feature_norm":
            # §1's bounded input stays: without §2 the state is θ centred and scaled to unit norm
            assert without[key] == "centred_unit"
        else:
            assert without[key] == unsourced[key], key
    text = (EXPERIMENTS / f"without_{improvement}.yaml").read_text()
    sections = {f"§{n}" for n in range(1, 8) if f"docs/improvements.md §{n}:" in text}
    assert len(sections) == 1 and sections != {"§3"}  # §3 is the single positions' only


@pytest.mark.parametrize("name", sorted(p.stem for p in EXPERIMENTS.glob("*.yaml")))
def test_every_experiment_composes_and_validates(name):
    flat = _flat([f"experiment={name}"])
    if not name.endswith("_algorithm") and name not in ("quickstart", CONTINUOUS):
        # every set-up of Tables 2–5 has §5's perturbation in the same run (Tables 3 and 5)
        assert flat["perturbation.camera_rotation_deg"] == 15.0
        assert flat["perturbation.blur_sigma"] == 2.0
        assert flat["perturbation.start_fraction"] is not None


@pytest.mark.parametrize("family", FAMILIES)
def test_each_family_covers_tables_2_to_5(family):
    from parallax.metrics import position_label
    from parallax.tools.report import paper_results as paper

    lists = {}
    for setup in SETUPS:
        flat = _flat([f"experiment={family}_{setup}"])
        labels = tuple(position_label(l) for l in flat["curriculum.lateral_positions"])
        lists[setup] = (labels, flat["distance.weighting"])
    assert {labels for labels, _ in lists.values() if len(labels) == 1} == {
        (p,) for p in paper.TABLE_POSITIONS_CM
    }
    assert set(paper.DISTANCE_ROWS.values()) <= set(lists.values())


def _the_papers_own_settings(flat):
    """What the paper gives, the same in the paper and the unsourced family."""
    assert flat["policy.feature_norm"] == "none"
    assert flat["policy.eye_position_reference_m"] == 0
    assert flat["policy.reward_change_gain"] == 0
    assert flat["env.initial_pan_jitter_deg"] == 0
    assert flat["env.stimuli.count"] == 100
    assert flat["distance.lm.weight_decay"] == 0
    assert flat["distance.queue_size"] == 300
    assert flat["train.distance_readout"] == "last"
    assert flat["perturbation.start_fraction"] == 0.5


@pytest.mark.parametrize("setup", SETUPS)
def test_the_paper_family_uses_nothing_beyond_the_paper_and_its_lineage(setup):
    """Where the paper is silent, the settings of the code it builds on
    (conf/experiment/paper_algorithm.yaml names each one's source)."""
    flat = _flat([f"experiment=paper_{setup}"])
    _the_papers_own_settings(flat)
    assert flat["policy.discount"] == 0.3
    assert flat["policy.weight_decay"] == 0.01
    assert flat["policy.actor_projection_radius"] is None
    assert flat["policy.initial_actor_range"] == 0.4
    assert flat["policy.initial_critic_range"] == 0.05
    assert flat["distance.input_scaling"] == "none"
    assert flat["distance.warm_start"] is False
    assert flat["distance.validation_fraction"] == 0.15
    assert flat["distance.test_fraction"] == 0.15
    assert flat["distance.max_fail"] == 6
    assert flat["distance.epochs_per_call"] == 1000
    assert flat["distance.reset_mu"] is True
    # the step sizes are one of the active-efficient-coding code's sets, and η one of the values
    # those sets carry
    steps = ("policy.critic_lr", "policy.advantage_lr", "policy.actor_lr")
    sets = [flatten(OmegaConf.to_container(OmegaConf.load(p))) for p in STEP_SIZES.glob("*.yaml")]
    assert any(all(flat[key] == s[key] for key in steps) for s in sets)
    rates = [OmegaConf.load(p).coder.learning_rate for p in DICTIONARY_RATES.glob("*.yaml")]
    assert flat["coder.learning_rate"] in rates and len(rates) == len(sets)


@pytest.mark.parametrize("setup", SETUPS)
def test_the_unsourced_family_keeps_the_settings_its_records_were_made_with(setup):
    """Where the paper is silent, our choices (conf/experiment/unsourced_algorithm.yaml): the
    settings of the runs in docs/results/runs/unsourced."""
    flat = _flat([f"experiment=unsourced_{setup}"])
    _the_papers_own_settings(flat)
    assert flat["policy.discount"] == 1.0  # algorithm 3's average-reward TD error
    assert flat["policy.weight_decay"] == 0 and flat["policy.actor_projection_radius"] == 100
    assert flat["policy.initial_actor_range"] == 0 and flat["policy.initial_critic_range"] == 0
    assert (flat["policy.critic_lr"], flat["policy.advantage_lr"], flat["policy.actor_lr"]) == (
        1.0,
        0.025,
        0.002,
    )
    assert flat["distance.input_scaling"] == "global"
    assert flat["distance.validation_fraction"] == 0 and flat["distance.test_fraction"] == 0
    assert flat["distance.reset_mu"] is False
    assert flat["train.presentations"] == 800


@pytest.mark.parametrize("setup", SETUPS)
def test_the_families_share_each_setups_lateral_list_weighting_and_perturbation(setup):
    flats = [_flat([f"experiment={family}_{setup}"]) for family in FAMILIES]
    same = ("curriculum.lateral_positions", "distance.weighting", "perturbation.blur_sigma")
    for key in same:
        assert len({flat[key] for flat in flats}) == 1, key


def test_plain_parallax_train_runs_the_recipe():
    plain, quickstart = _flat([]), _flat(["experiment=quickstart"])
    recipe_keys = (
        "policy.feature_norm",
        "policy.reward_change_gain",
        "policy.eye_position_reference_m",
        "env.initial_pan_jitter_deg",
        "distance.lm.weight_decay",
        "train.distance_readout",
        "distance.y",
    )
    recipe = _flat(["experiment=recipe_multi_5_20_weighted"])
    for key in recipe_keys:
        assert plain[key] == recipe[key] == quickstart[key], key


@pytest.mark.parametrize("setup", SETUPS)
def test_only_the_recipes_single_positions_start_from_a_random_pan(setup):
    """docs/improvements.md §3: a warm-up of random starts at a single lateral position; at
    several positions every trial starts from pan 0, as in the paper."""
    flat = _flat([f"experiment=recipe_{setup}"])
    if setup.startswith("single"):
        assert flat["env.initial_pan_jitter_deg"] == 2.0
        assert flat["train.start_jitter_presentations"] == 100
    else:
        assert flat["env.initial_pan_jitter_deg"] == 0


@pytest.mark.parametrize("run", sorted(p.name for p in CHECKPOINTS.glob("*_seed*")))
def test_the_committed_models_are_reproduced_by_one_experiment_name(run):
    """Each committed model's saved config is what `experiment=<name> seed=n` composes, for the
    folder <name>_seed<n>."""
    saved_cfg = upgrade_saved(OmegaConf.load(CHECKPOINTS / run / "config.yaml"))
    saved = flatten(OmegaConf.to_container(saved_cfg, resolve=True))
    name, seed = run.rsplit("_seed", 1)
    current = _flat([f"experiment={name}", f"seed={seed}"])
    differ = {
        key: (saved.get(key), current.get(key))
        for key in set(saved) | set(current)
        if key not in RESULT_NEUTRAL_KEYS and saved.get(key) != current.get(key)
    }
    assert differ == {}


@pytest.mark.parametrize(
    "name",
    [
        "paper_multi_5_20_weighted",
        "unsourced_multi_5_20_weighted",
        "recipe_multi_5_20_weighted",
        "embodied_growth",
        "planned_multi_5_20_weighted",
    ],
)
def test_each_family_trains_and_resumes_exactly(name, tmp_path, tiny_overrides):
    """Shrunk like the other tests' runs, each family trains; stopped and resumed, it gives the
    numbers of an uninterrupted run, across §5's perturbation (and the growth spurt)."""
    from parallax.trainer import Trainer

    overrides = [f"experiment={name}", *tiny_overrides, "env.stimuli.count=6"]
    overrides = [o for o in overrides if not o.startswith("curriculum.lateral_positions")]
    # 0.2 of 4 and of 6 presentations both round to 1: the stop changes no setting
    overrides += ["curriculum.lateral_positions=[0.05,0.1]", "perturbation.start_fraction=0.2"]
    if name == "embodied_growth":  # 0.4 of 4 and of 6 both round to 2: the spurt's presentation
        overrides += ["env.walk.growth_start_fraction=0.4", "distance.fit_from=2"]

    def train(run_dir, presentations):
        trainer = Trainer(compose(overrides + [f"train.presentations={presentations}"]), run_dir)
        try:
            trainer.fit()
        finally:
            trainer.exp.close()
        return (run_dir / "metrics.jsonl").read_text()

    whole = train(tmp_path / "whole", 6)
    train(tmp_path / "parts", 4)
    assert train(tmp_path / "parts", 6) == whole


#: conf/open_setting/: each file switches these settings of the paper family away from the value
#: it uses (docs/paper_algorithm.md, the sensitivity study).
OPEN_SETTINGS = {
    "xi_1": {"policy.discount"},
    "projection": {"policy.weight_decay", "policy.actor_projection_radius"},
    "normalised_features": {"policy.feature_norm"},
    "reset_step_learnt": {"policy.learn_reset_step"},
    "pan_kept": {"env.pan_reset"},
    "continued_network": {"distance.warm_start"},
    "per_input_scaling": {"distance.input_scaling"},
    "matlab_network": {
        "distance.input_scaling",
        "distance.warm_start",
        "distance.keep_first_scaling",
    },
    "plain_lm": {
        "distance.validation_fraction",
        "distance.test_fraction",
        "distance.epochs_per_call",
        "distance.initial_epochs",
        "distance.reset_mu",
    },
}


def test_every_open_setting_file_is_listed():
    folder = EXPERIMENTS.parent / "open_setting"
    assert sorted(p.stem for p in folder.glob("*.yaml")) == sorted(OPEN_SETTINGS)


@pytest.mark.parametrize("setting", sorted(OPEN_SETTINGS))
@pytest.mark.parametrize("setup", ["single_5", "multi_5_10"])
def test_an_open_setting_file_switches_its_settings_and_nothing_else(setting, setup):
    lineage = _flat([f"experiment=paper_{setup}"])
    switched = _flat([f"experiment=paper_{setup}", f"+open_setting={setting}"])
    differ = {k for k in set(lineage) | set(switched) if lineage.get(k) != switched.get(k)}
    assert differ == OPEN_SETTINGS[setting]
