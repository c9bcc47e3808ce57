"""Saved configurations are read in this parallax's words: a run's config.yaml and a checkpoint's
"config" that an older parallax wrote with coder.robot_updates=sum and policy.robot_updates=in_turn
(both "each", parallax.config.schema.ROBOT_UPDATES) read back, compare equal to a freshly composed
config and resume; one without policy.learn_reset_step, which an older parallax did not have,
reads it as false (what that parallax did)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from omegaconf import OmegaConf

from parallax import checkpoint
from parallax.config import (
    ROBOT_UPDATES,
    changed_settings,
    compose,
    load_run_config,
    upgrade_saved,
)
from parallax.train import run_directory_error

CHECKPOINTS = Path(__file__).resolve().parents[2] / "docs" / "results" / "checkpoints"
#: The words an older parallax wrote for "each".
OLDER_WORDS = {"coder": "sum", "policy": "in_turn"}


def _saved_by_an_older_parallax() -> dict:
    """The default run's resolved config, as the trainer saves it, in the older words and
    without the settings an older parallax did not have."""
    config = OmegaConf.to_container(compose([]), resolve=True)
    for group, word in OLDER_WORDS.items():
        config[group]["robot_updates"] = word
    del config["policy"]["learn_reset_step"]
    return config


def _run_directory(folder: Path, config: dict) -> Path:
    """A run directory as the trainer leaves it: its config.yaml and a checkpoint recording the
    same settings."""
    folder.mkdir()
    (folder / "config.yaml").write_text(yaml.safe_dump(config))
    state = {key: 0 for key in checkpoint.REQUIRED_KEYS} | {"config": config}
    checkpoint.save_atomic(state, folder / checkpoint.CHECKPOINT_NAME)
    return folder


def test_the_older_words_are_each_and_nothing_else_changes():
    saved = _saved_by_an_older_parallax()
    upgraded = upgrade_saved(saved)
    assert {group: upgraded[group]["robot_updates"] for group in OLDER_WORDS} == {
        "coder": "each",
        "policy": "each",
    }
    assert saved["coder"]["robot_updates"] == "sum"  # a copy: the saved one is left alone
    rest = {key: value for key, value in upgraded.items() if key not in OLDER_WORDS}
    assert rest == {key: value for key, value in saved.items() if key not in OLDER_WORDS}
    for word in ROBOT_UPDATES:
        policy = {"robot_updates": word, "learn_reset_step": False}
        chosen = {"coder": {"robot_updates": word, "pairing": "reference"}, "policy": policy}
        assert upgrade_saved(chosen) == chosen
    assert upgrade_saved({}) == {}
    dict_config = upgrade_saved(OmegaConf.create(saved))
    assert dict_config.coder.robot_updates == dict_config.policy.robot_updates == "each"


def test_a_run_config_in_the_older_words_reads_as_the_default_run(tmp_path):
    run = _run_directory(tmp_path / "run", _saved_by_an_older_parallax())
    saved = load_run_config(run)
    assert saved.coder.robot_updates == saved.policy.robot_updates == "each"
    assert changed_settings(saved, compose([])) == []


def test_a_checkpoint_in_the_older_words_reads_and_resumes(tmp_path):
    run = _run_directory(tmp_path / "run", _saved_by_an_older_parallax())
    state = checkpoint.read(run / checkpoint.CHECKPOINT_NAME, config=compose([]))
    assert state["config"]["coder"]["robot_updates"] == "each"
    assert state["config"]["policy"]["robot_updates"] == "each"
    # what parallax-train asks before it resumes a run directory
    assert run_directory_error(compose([]), run) is None


def test_a_checkpoint_of_other_settings_is_still_refused(tmp_path):
    config = _saved_by_an_older_parallax()
    config["coder"]["robot_updates"] = "mean"
    run = _run_directory(tmp_path / "run", config)
    with pytest.raises(checkpoint.CheckpointError, match="coder.robot_updates: 'mean' → 'each'"):
        checkpoint.read(run / checkpoint.CHECKPOINT_NAME, config=compose([]))


def test_the_committed_run_records_read_in_this_parallaxs_words():
    folders = sorted(path.parent for path in CHECKPOINTS.glob("*/config.yaml"))
    assert folders
    for folder in folders:
        written = yaml.safe_load((folder / "config.yaml").read_text())
        saved = load_run_config(folder)
        for group in OLDER_WORDS:
            assert written[group]["robot_updates"] in (OLDER_WORDS[group], *ROBOT_UPDATES)
            assert saved[group]["robot_updates"] in ROBOT_UPDATES


def test_a_setting_an_older_parallax_lacked_reads_as_what_it_did():
    saved = _saved_by_an_older_parallax()
    assert "learn_reset_step" not in saved["policy"]
    assert upgrade_saved(saved)["policy"]["learn_reset_step"] is False
    # a saved config that has it keeps its value
    saved["policy"]["learn_reset_step"] = True
    assert upgrade_saved(saved)["policy"]["learn_reset_step"] is True
