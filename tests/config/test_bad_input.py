"""Bad input stops `parallax-train` with one line naming the key and the value, exit status 2,
no traceback and nothing written, before Hydra creates a run directory; in a sweep a bad job
fails alone. Nothing here trains except the good job of the sweep test."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from parallax.train import check_command_line

PREFIX = "parallax-train: error: "


def _images_that_are_text(folder: Path) -> Path:
    folder.mkdir()
    for name in ("a.png", "b.png", "c.jpg"):
        (folder / name).write_text("not an image")
    return folder


def _parallax_train(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    script = Path(sys.executable).with_name("parallax-train")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "parallax.train"]
    return subprocess.run(command + args, capture_output=True, text=True, cwd=cwd, timeout=300)


#: (override, what the error line must contain: the key and the value as the config holds it)
COMMAND_LINES = [
    ("train.presentations=abc", "train.presentations=abc"),
    ("env.stimuli.dir=/nonexistent/folder", "env.stimuli.dir=/nonexistent/folder"),
    ("env.stimuli.dir={images}", "env.stimuli.dir={images}"),
    ("env.distances.start=0", "env.distances.start=0.0"),
    ("env.distances.start=12", "env.distances.start=12.0"),
    ("distance.y=-1", "distance.y=-1.0"),
    ("policy.actions=[]", "policy.actions=[]"),
    ("perturbation.blur_sigma=-2", "perturbation.blur_sigma=-2.0"),
    ("perturbation.camera_rotation_deg=nan", "perturbation.camera_rotation_deg=nan"),
    ("foo.bar=1", "foo.bar=1"),
    ("train.presentaions=5", "train.presentaions=5"),
    ("experiment=nope", "experiment=nope"),
    ("env.walk.stride_slip=0.6", "env.walk.stride_slip=0.6"),
    ("movement.explore=0", "movement.explore=0.0"),
    ("distance.max_fail=0", "distance.max_fail=0"),
]


#: Of those, the ones run as whole parallax-train processes: a type Hydra's schema refuses, a
#: file that cannot be read and a choice Hydra cannot compose (the rest are the same path,
#: checked in-process below).
WHOLE_COMMANDS = [c for c in COMMAND_LINES if c[0].split("=")[0] in ("train.presentations",
    "env.stimuli.dir", "experiment") and "nonexistent" not in c[0]]  # fmt: skip


@pytest.mark.parametrize("override, named", WHOLE_COMMANDS, ids=[c[0] for c in WHOLE_COMMANDS])
def test_parallax_train_stops_with_one_line(tmp_path, override, named):
    images = _images_that_are_text(tmp_path / "images")
    override, named = override.format(images=images), named.format(images=images)
    run_dir = tmp_path / "run"
    proc = _parallax_train([override, f"hydra.run.dir={run_dir}"], tmp_path)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(PREFIX + named), lines[0]
    assert "Traceback" not in proc.stderr + proc.stdout
    assert not run_dir.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["images"]


#: Checked in-process (the same function `parallax-train` calls before Hydra starts).
BAD_VALUES = [
    ("env.fovea_px=151", "env.fovea_px=151"),
    ("env.fovea_px=300", "env.fovea_px=300"),
    # numbers that cannot work: NaN, inf, negative, zero
    ("seed=-1", "seed=-1"),
    ("seed=1.5", "seed=1.5"),
    ("seed=abc", "seed=abc"),
    ("env.stimuli.seed=-3", "env.stimuli.seed=-3"),
    ("train.presentations=0", "train.presentations=0"),
    ("train.checkpoint_every=0", "train.checkpoint_every=0"),
    ("train.image_every=-1", "train.image_every=-1"),
    ("train.threads=-1", "train.threads=-1"),
    ("train.start_jitter_presentations=-1", "train.start_jitter_presentations=-1"),
    ("train.start_jitter_presentations=0.5", "train.start_jitter_presentations=0.5"),
    ("metrics.mae_window=0", "metrics.mae_window=0"),
    ("metrics.summary_trials=0", "metrics.summary_trials=0"),
    ("metrics.distance_window=0", "metrics.distance_window=0"),
    ("env.image_size=8", "env.image_size=8"),
    ("env.image_size=4096", "env.image_size=4096"),
    ("env.trial_length=1", "env.trial_length=1"),
    ("env.distances.step=0", "env.distances.step=0.0"),
    ("env.distances.stop=inf", "env.distances.stop=inf"),
    ("env.initial_pan_jitter_deg=-1", "env.initial_pan_jitter_deg=-1.0"),
    ("env.initial_pan_jitter_deg=nan", "env.initial_pan_jitter_deg=nan"),
    ("env.max_pan_increment_deg=0", "env.max_pan_increment_deg=0.0"),
    ("env.robots=0", "env.robots=0"),
    ("env.robots_per_turn=-1", "env.robots_per_turn=-1"),
    ("env.stimuli.count=0", "env.stimuli.count=0"),
    ("env.stimuli.count=400", "env.stimuli.count=400"),
    ("env.stimuli.resolution=4", "env.stimuli.resolution=4"),
    ("coder.atoms=0", "coder.atoms=0"),
    ("coder.sparsity=0", "coder.sparsity=0"),
    ("coder.learning_rate=-0.1", "coder.learning_rate=-0.1"),
    ("coder.learning_rate=inf", "coder.learning_rate=inf"),
    ("coder.scale_specs.fine.stride=0", "coder.scale_specs.fine.stride=0"),
    ("coder.scale_specs.coarse.subsample=3", "coder.scale_specs.coarse.subsample=3"),
    ("coder.scale_specs.coarse.window=300", "coder.scale_specs.coarse.window=300"),
    ("coder.scale_specs.fine.window=12", "coder.scale_specs.fine.window=12"),
    ("policy.critic_lr=-1", "policy.critic_lr=-1.0"),
    ("policy.advantage_lr=nan", "policy.advantage_lr=nan"),
    ("policy.actor_lr=inf", "policy.actor_lr=inf"),
    ("policy.discount=1.5", "policy.discount=1.5"),
    ("policy.reward_rate=0", "policy.reward_rate=0.0"),
    ("policy.weight_decay=-0.1", "policy.weight_decay=-0.1"),
    ("policy.weight_decay=20", "policy.weight_decay=20.0"),
    ("policy.temperature=0", "policy.temperature=0.0"),
    ("policy.zscore_horizon=-1", "policy.zscore_horizon=-1"),
    ("policy.eye_position_reference_m=-0.5", "policy.eye_position_reference_m=-0.5"),
    ("policy.reward_change_gain=nan", "policy.reward_change_gain=nan"),
    ("policy.actor_projection_radius=0", "policy.actor_projection_radius=0.0"),
    ("policy.actor_projection_radius=-1", "policy.actor_projection_radius=-1.0"),
    ("distance.queue_size=0", "distance.queue_size=0"),
    ("distance.hidden=0", "distance.hidden=0"),
    ("distance.hidden=500", "distance.hidden=500"),
    ("distance.y=0", "distance.y=0.0"),
    ("distance.y=inf", "distance.y=inf"),
    ("distance.epochs_per_call=0", "distance.epochs_per_call=0"),
    ("distance.initial_epochs=0", "distance.initial_epochs=0"),
    ("distance.sensitivity.nearest_distance=0", "distance.sensitivity.nearest_distance=0.0"),
    ("distance.sensitivity.tolerance=-1", "distance.sensitivity.tolerance=-1.0"),
    ("distance.lm.mu=0", "distance.lm.mu=0.0"),
    ("distance.lm.mu_decrease=1", "distance.lm.mu_decrease=1.0"),
    ("distance.lm.mu_increase=0.5", "distance.lm.mu_increase=0.5"),
    ("distance.lm.weight_decay=-1", "distance.lm.weight_decay=-1.0"),
    ("distance.lm.max_params=0", "distance.lm.max_params=0"),
    ("distance.queue_size=100000", "distance.queue_size=100000"),
    ("distance.sensitivity.patch=0", "distance.sensitivity.patch=0"),
    ("distance.sensitivity.subsample=0", "distance.sensitivity.subsample=0.0"),
    ("distance.lm.mu_max=0", "distance.lm.mu_max=0.0"),
    ("distance.lm.min_grad=-1", "distance.lm.min_grad=-1.0"),
    ("distance.lm.max_jacobian_elements=0", "distance.lm.max_jacobian_elements=0"),
    ("distance.validation_fraction=1", "distance.validation_fraction=1.0"),
    ("distance.test_fraction=-0.1", "distance.test_fraction=-0.1"),
    (
        "distance.validation_fraction=0.5 distance.test_fraction=0.5",
        "distance.test_fraction=0.5",
    ),
    ("distance.max_fail=0", "distance.max_fail=0"),
    ("distance.fit_from=0", "distance.fit_from=0"),
    ("distance.fit_from=301", "distance.fit_from=301"),
    ("distance.odometry.walk_fraction=0", "distance.odometry.walk_fraction=0.0"),
    ("distance.odometry.walk_fraction=1.5", "distance.odometry.walk_fraction=1.5"),
    ("distance.odometry.nominal_stride_m=0", "distance.odometry.nominal_stride_m=0.0"),
    ("env.walk.stride_m=0", "env.walk.stride_m=0.0"),
    ("env.walk.substeps=0", "env.walk.substeps=0"),
    ("env.walk.growth_factor=0", "env.walk.growth_factor=0.0"),
    ("env.stimuli.resolution=5000", "env.stimuli.resolution=5000"),
    ("movement.price_per_trial=-0.1", "movement.price_per_trial=-0.1"),
    ("movement.price_per_cm=inf", "movement.price_per_cm=inf"),
    ("movement.route=planned distance.queue_size=1", "distance.queue_size=1"),
    ("perturbation.start_fraction=1.5", "perturbation.start_fraction=1.5"),
    ("perturbation.blur_sigma=inf", "perturbation.blur_sigma=inf"),
    ("curriculum.advance_below_deg=0", "curriculum.advance_below_deg=0.0"),
    ("curriculum.min_trials=0", "curriculum.min_trials=0"),
    # lists: empty, out of order, out of range
    ("curriculum.lateral_positions=[]", "curriculum.lateral_positions=[]"),
    ("curriculum.lateral_positions=[0.1,0.05]", "curriculum.lateral_positions=[0.1,0.05]"),
    ("curriculum.lateral_positions=[0.05,0.05]", "curriculum.lateral_positions=[0.05,0.05]"),
    ("curriculum.lateral_positions=[0,0.05]", "curriculum.lateral_positions=[0.0,0.05]"),
    ("curriculum.lateral_positions=[-0.05]", "curriculum.lateral_positions=[-0.05]"),
    ("curriculum.stages=[]", "curriculum.stages=[]"),
    ("curriculum=staged curriculum.stages=[[0.3]]", "curriculum.stages[0]=[0.3]"),
    ("curriculum=staged curriculum.stages=[[0.05]]", "curriculum.stages=[[0.05]]"),
    ("policy.actions=[0.1]", "policy.actions=[0.1]"),
    ("policy.actions=[0.1,0.1]", "policy.actions=[0.1,0.1]"),
    ("policy.actions=[0.1,0.5]", "policy.actions=[0.1,0.5]"),
    ("policy.actions=[0.1,nan]", "policy.actions=[0.1,nan]"),
    ("coder.scales=[]", "coder.scales=[]"),
    ("coder.scales=[fine,fine]", "coder.scales=[fine,fine]"),
    ("coder.scales=[medium]", "coder.scales=[medium]"),
    ("perturbation.rotation_axis=[0,0,0]", "perturbation.rotation_axis=[0,0,0]"),
    ("perturbation.rotation_axis=[1,0]", "perturbation.rotation_axis=[1,0]"),
    # choices the components do not know
    ("policy.feature_norm=l2", "policy.feature_norm=l2"),
    ("coder.normalisation=both", "coder.normalisation=both"),
    ("coder.robot_updates=sum", "coder.robot_updates=sum"),
    ("policy.robot_updates=in_turn", "policy.robot_updates=in_turn"),
    ("distance.input_scaling=per_row", "distance.input_scaling=per_row"),
    ("distance.targets=oracle", "distance.targets=oracle"),
    ("train.distance_readout=peak", "train.distance_readout=peak"),
    ("perturbation.rotation_axis=sideways", "perturbation.rotation_axis=sideways"),
    ("env.stimuli.source=flickr", "env.stimuli.source=flickr"),
    ("env.stimuli.split=test", "env.stimuli.split=test"),
    ("env.stimuli.kind=stripes", "env.stimuli.kind=stripes"),
    ("env.stimuli.source=dir", "env.stimuli.dir=null"),
    ("env.stimuli.source=procedural env.stimuli.dir=/tmp", "env.stimuli.dir=/tmp"),
    ("device=tpu", "device=tpu"),
    ("device=cpu:0", "device=cpu:0"),
    ("device=cuda:x", "device=cuda:x"),
    ("coder=medium", "coder=medium"),
    ("curriculum=single_6", "curriculum=single_6"),
    # settings that do not exist, and cross-field rules
    ("+foo.bar=1", "foo.bar=1"),
    ("+train.presentaions=5", "train.presentaions=5"),
    ("distance.lm.learning_rate=1", "distance.lm.learning_rate=1"),
    ("perturbation=rotate_blur perturbation.start_fraction=null", "perturbation.start_fraction"),
    ("perturbation.start_fraction=0.5", "perturbation.start_fraction=0.5"),
    ("env.pan_reset=maybe", "env.pan_reset=maybe"),
    ("seed=0,1", "seed=0,1"),
    ("foo=[", "foo=["),
]


@pytest.mark.parametrize("overrides, named", BAD_VALUES, ids=[c[0] for c in BAD_VALUES])
def test_bad_values_are_named_in_one_line(overrides, named):
    line = check_command_line(overrides.split())
    assert line is not None and line.startswith(named), line
    assert "\n" not in line and len(line) < 300, line


@pytest.mark.parametrize("override, named", COMMAND_LINES, ids=[c[0] for c in COMMAND_LINES])
def test_each_bad_command_line_is_named_in_one_line_before_anything_is_written(
    tmp_path, override, named
):
    images = _images_that_are_text(tmp_path / "images")
    override, named = override.format(images=images), named.format(images=images)
    line = check_command_line([override, f"hydra.run.dir={tmp_path / 'run'}"])
    assert line is not None and line.startswith(named), line
    assert "\n" not in line, line  # one line, however long the list of choices it gives
    assert sorted(p.name for p in tmp_path.iterdir()) == ["images"]


def test_the_stimulus_checks_alone_name_the_value():
    """parallax-eval checks the held-out textures it is given with these (validate_stimuli)."""
    from parallax.config import ConfigError, compose, validate_stimuli

    validate_stimuli(compose(["env.stimuli.source=procedural"]))
    with pytest.raises(ConfigError, match=r"^env\.stimuli\.kind=plaid: must be one of"):
        validate_stimuli(compose(["env.stimuli.kind=plaid"]))


def test_a_good_command_line_passes_the_checks():
    assert check_command_line(["curriculum=multi_5_10", "distance.y=2", "seed=3"]) is None
    assert check_command_line(["-m", "seed=0,1,2", "distance.y=1,2"]) is None
    assert check_command_line(["--help"]) is None  # Hydra's own flags are Hydra's


def test_a_sweep_with_a_typo_runs_no_job(tmp_path):
    sweep = tmp_path / "sweep"
    proc = _parallax_train(["-m", "seed=0,abc", f"hydra.sweep.dir={sweep}"], tmp_path)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith(PREFIX + "seed=abc: ")
    assert not sweep.exists()


def test_a_bad_job_of_a_sweep_fails_alone(tmp_path, tiny_overrides):
    sweep = tmp_path / "sweep"
    overrides = [o for o in tiny_overrides if not o.startswith("train.presentations")]
    proc = _parallax_train(
        [
            "-m",
            *overrides,
            "train.presentations=1",
            "distance.y=-1,1",
            f"hydra.sweep.dir={sweep}",
            "hydra.sweep.subdir=${hydra.job.num}",
        ],
        tmp_path,
    )
    assert proc.returncode != 0
    assert "distance.y=-1.0: must be a finite number > 0" in proc.stderr
    assert "Traceback" not in proc.stderr
    # the bad job stopped before the trainer wrote anything: only Hydra's own files are there
    assert {p.name for p in (sweep / "0").iterdir()} <= {".hydra", "train.log"}
    assert (sweep / "1" / "summary.json").is_file()


def test_a_finished_run_without_its_checkpoint_is_not_trained_over(tmp_path, tiny_overrides):
    """A committed record (summary.json and metrics, no checkpoint) must not be overwritten by a
    fresh run into the same directory."""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    record = {"summary.json": '{"mae": 0.1}\n', "metrics.jsonl": '{"presentation": 1}\n'}
    for name, text in record.items():
        (run_dir / name).write_text(text)
    proc = _parallax_train([*tiny_overrides, f"hydra.run.dir={run_dir}"], tmp_path)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith(PREFIX + f"hydra.run.dir={run_dir}"), lines
    assert {name: (run_dir / name).read_text() for name in record} == record
    assert not (run_dir / "checkpoint.pt").exists() and not (run_dir / "tb").exists()
