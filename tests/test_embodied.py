"""Distance from the robot's own body, end to end on the shrunk configs: a supervised run logs no
walk and saves no walker; walking never changes what the eye does; an odometry run logs its
walks (None for a robot that stayed), its growth spurt and its first fit at distance.fit_from;
parallax-replay reproduces a walking run and replays a supervised one as an odometry run;
resuming gives the numbers of an uninterrupted run; bad env.walk / odometry values are refused
naming the key (in-process; parallax-train in tests/config/test_bad_input.py)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from parallax import checkpoint
from parallax.config import ConfigError, changed_settings, compose, load_run_config, validate
from parallax.distance import distance_error_by_range
from parallax.metrics import finite_or_none
from parallax.tools.replay import ReplayError, main, parse_sweep, replay
from parallax.trainer import Trainer
from tests.conftest import TINY, train_tiny_run

WALK_KEYS = {"walk_strides", "reach_strides", "odometry_error_pct", "true_stride_m"}
#: What a record says about the distance learner rather than the eye.
DISTANCE_KEYS = WALK_KEYS | {"distance_error"}
TEN = ["train.presentations=10"]
#: The odometry run of these tests: half the presentations walk, strides slip, the body grows
#: 10 % from presentation 6 on, fits start with two targets in the queue (c = 3).
WALKING = TEN + [
    "distance.targets=odometry",
    "distance.odometry.walk_fraction=0.5",
    "env.walk.stride_slip=0.05",
    "env.walk.growth_factor=1.1",
    "env.walk.growth_start_fraction=0.5",
    "distance.fit_from=2",
]
#: An odometry learner on every presentation: what a supervised run replays as below.
ODOMETRY = ["distance.targets=odometry", "env.walk.stride_slip=0.02"]


def _records(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


def _summary(run: Path) -> dict:
    return json.loads((run / "summary.json").read_text())


def _eye(record: dict) -> dict:
    return {k: v for k, v in record.items() if k not in DISTANCE_KEYS and not k.startswith("lm_")}


@pytest.fixture(scope="module")
def supervised_run(tmp_path_factory):
    return train_tiny_run(tmp_path_factory.mktemp("supervised"), TEN)


@pytest.fixture(scope="module")
def odometry_run(tmp_path_factory):
    return train_tiny_run(tmp_path_factory.mktemp("odometry"), TEN + ODOMETRY)


@pytest.fixture(scope="module")
def walking_run(tmp_path_factory):
    return train_tiny_run(tmp_path_factory.mktemp("walking"), WALKING)


# -- (a) the supervisor's runs do not walk; walking never changes the eye --------------------------
def test_a_supervised_run_logs_no_walk_and_saves_no_walker(supervised_run):
    records = _records(supervised_run)
    assert len(records) == 10
    assert all(not (WALK_KEYS & set(r)) for r in records)
    state = checkpoint.load(supervised_run / "checkpoint.pt")
    assert "walkers" not in state["experiment"]
    assert load_run_config(supervised_run).distance.targets == "supervisor"


def test_an_odometry_run_saves_its_walkers(odometry_run, walking_run):
    for run, grown in ((odometry_run, False), (walking_run, True)):
        walkers = checkpoint.load(run / "checkpoint.pt")["experiment"]["walkers"]
        assert len(walkers) == 1 and walkers[0]["grown"] is grown


@pytest.mark.parametrize("which", ["odometry_run", "walking_run"])
def test_walking_never_changes_what_the_eye_does(supervised_run, which, request):
    walked = request.getfixturevalue(which)
    supervised, odometry = _records(supervised_run), _records(walked)
    assert len(supervised) == len(odometry) == 10
    for plain, walking in zip(supervised, odometry):
        assert walking["pans"] == plain["pans"]
        assert walking["best_pans"] == plain["best_pans"]
        assert walking["mae"] == plain["mae"]
        assert _eye(walking) == _eye(plain), plain["presentation"]
    assert _summary(walked)["mae_per_position"] == _summary(supervised_run)["mae_per_position"]
    # … while the distance learner did learn something else
    assert json.dumps(_summary(walked)["distance_error"]) != json.dumps(
        _summary(supervised_run)["distance_error"]
    )


# -- (b) what an odometry run logs -----------------------------------------------------------------
def test_walks_are_logged_with_none_for_a_robot_that_stayed(walking_run):
    records = _records(walking_run)
    counted = [r["walk_strides"][0] for r in records]
    assert None in counted and any(n is not None for n in counted)
    for record in records:
        (n,), (reach,), (error,) = (
            record["walk_strides"],
            record["reach_strides"],
            record["odometry_error_pct"],
        )
        assert (n is None) == (error is None)
        assert reach > 0
        if n is not None:
            assert abs(n - reach) < 0.1 * reach  # 5 % slip per stride, ~100 strides
            believed, walked = n * 0.05, reach * record["true_stride_m"]
            assert error == pytest.approx(100.0 * (believed / walked - 1.0), rel=1e-9)


def test_the_growth_spurt_comes_at_its_presentation(walking_run):
    records = _records(walking_run)
    strides = [r["true_stride_m"] for r in records]
    # growth_start_fraction 0.5 of 10 presentations: presentations 6–10 walk with grown strides
    assert strides[:5] == [0.05] * 5
    assert strides[5:] == pytest.approx([0.055] * 5, rel=1e-12)
    # the slip-free count follows the body: reach × true stride is the panel less a fixed reach
    offsets = [r["distances"][0] - r["reach_strides"][0] * r["true_stride_m"] for r in records]
    assert max(offsets) - min(offsets) < 1e-9 and 0 < offsets[0] < 0.1
    # after the spurt the robot believes it walked 1/1.1 of what it did
    grown = [r["odometry_error_pct"][0] for r in records[5:] if r["walk_strides"][0] is not None]
    assert grown and all(abs(e - 100 * (1 / 1.1 - 1)) < 2.0 for e in grown)


def test_the_first_fit_comes_with_the_fit_from_th_walk(walking_run):
    records = _records(walking_run)
    walks = 0
    first_fit = None
    for index, record in enumerate(records):
        walks += record["walk_strides"][0] is not None
        if walks >= 2 and first_fit is None:
            first_fit = index
    assert first_fit is not None and first_fit < 9, "the run must fit and then predict"
    assert records[first_fit]["lm_trained"] == 1.0
    assert all(r.get("lm_trained", 0.0) == 0.0 for r in records[:first_fit])
    # predictions (the online error) start with the presentation after the first fit
    assert all(r["distance_error"] == {} for r in records[: first_fit + 1])
    assert all(r["distance_error"] for r in records[first_fit + 1 :])


def test_the_online_error_is_scored_against_the_slip_free_walk(walking_run):
    records = _records(walking_run)
    pairs = checkpoint.load(walking_run / "checkpoint.pt")["dist"]["pairs"]
    predicted = [r for r in records if r["learnt_distance"]][-len(pairs) :]
    assert len(pairs) == sum(1 for r in records if r["distance_error"])
    truths = [pair[1] for pair in pairs]
    assert truths == pytest.approx([r["reach_strides"][0] * 0.05 for r in predicted], rel=1e-12)
    # each pair also holds the panel's distance, for the ranges
    assert [pair[2] for pair in pairs] == [r["distances"][0] for r in predicted]
    estimates = [pair[0] for pair in pairs]
    total = _summary(walking_run)["distance_error"]["total"]
    assert total == pytest.approx(distance_error_by_range(estimates, truths)["total"])


def test_the_online_ranges_are_the_panels_distances_as_in_parallax_eval(walking_run):
    records = _records(walking_run)
    pairs = checkpoint.load(walking_run / "checkpoint.pt")["dist"]["pairs"]
    predicted = [r for r in records if r["learnt_distance"]][-len(pairs) :]
    estimates, truths = [pair[0] for pair in pairs], [pair[1] for pair in pairs]
    panels = [r["distances"][0] for r in predicted]
    expected = distance_error_by_range(estimates, truths, at=panels)
    # summary.json is strict JSON: a range without panels is null there
    assert _summary(walking_run)["distance_error"] == finite_or_none(expected)


def test_tensorboard_shows_the_walks(walking_run, supervised_run):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    def scalars(run):
        events = EventAccumulator(str(run / "tb"), size_guidance={"scalars": 0}).Reload()
        return events, set(events.Tags()["scalars"])

    events, tags = scalars(walking_run)
    assert {"walk/walks", "walk/true_stride_m", "walk/strides", "walk/odometry_error_pct"} <= tags
    assert [e.value for e in events.Scalars("walk/walks")] == [
        float(r["walk_strides"][0] is not None) for r in _records(walking_run)
    ]
    assert not {t for t in scalars(supervised_run)[1] if t.startswith("walk/")}


# -- (c) parallax-replay -----------------------------------------------------------------------
def test_replay_of_a_walking_run_is_exact(walking_run):
    trained = _summary(walking_run)
    replayed = replay(walking_run)["summary"]
    assert trained["distance_error"].get("total") is not None
    assert finite_or_none(replayed["distance_error"]) == trained["distance_error"]
    # the walk's settings are the replay's: no slip, other counts, another learner
    still = replay(walking_run, ["env.walk.stride_slip=0"])["summary"]
    assert json.dumps(still["distance_error"]) != json.dumps(trained["distance_error"])


def test_a_supervised_run_replays_as_the_odometry_run_of_its_seed(supervised_run, odometry_run):
    result = replay(supervised_run, ODOMETRY)
    assert result["config"].distance.targets == "odometry"
    assert result["config"].env.walk.stride_slip == 0.02
    trained = _summary(odometry_run)["distance_error"]
    assert trained.get("total") is not None
    assert finite_or_none(result["summary"]["distance_error"]) == trained


def test_replay_takes_walk_overrides_only(supervised_run, tmp_path, capsys):
    assert parse_sweep(["env.walk.stride_slip=0,0.05", "distance.targets=odometry"]) == [
        ["env.walk.stride_slip=0", "distance.targets=odometry"],
        ["env.walk.stride_slip=0.05", "distance.targets=odometry"],
    ]
    with pytest.raises(ReplayError, match="env.trial_length=3"):
        parse_sweep(["env.trial_length=3"])
    with pytest.raises(ReplayError, match="env.robots=2"):
        parse_sweep(["env.robots=2"])
    with pytest.raises(SystemExit) as stop:
        main([str(supervised_run), "--out", str(tmp_path / "out"), "env.trial_length=3"])
    assert stop.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and "env.trial_length=3" in lines[0]
    assert not (tmp_path / "out").exists()


def test_replay_of_a_walking_run_rescores_its_eval_unchanged(walking_run, tmp_path):
    from parallax.tools.evaluate import evaluate

    run = Path(shutil.copytree(walking_run, tmp_path / "run"))
    evaluated = evaluate(run, distances=[3.0, 6.5, 10.0], between=[])
    assert evaluated["distance"]["trials"] == 3 and evaluated["distance"]["mae_m"] > 0
    rescored = replay(run)["evals"]["eval.json"]["distance"]
    assert rescored["mae_m"] == pytest.approx(evaluated["distance"]["mae_m"], rel=1e-9)
    assert json.dumps(rescored) == json.dumps(evaluated["distance"])


# -- (d) resuming ------------------------------------------------------------------------------
def _fit(overrides: list[str], run_dir: Path) -> dict:
    trainer = Trainer(compose(TINY + overrides), run_dir)
    try:
        return trainer.fit()
    finally:
        trainer.exp.close()


def test_a_resumed_walking_run_matches_the_uninterrupted_one(walking_run, tmp_path):
    part = tmp_path / "part"
    # 5 presentations with the spurt at presentation 5 (never reached), then all 10 with the
    # spurt at 0.5 × 10 = 5: the spurt's presentation stays, so the CLI would resume it too
    first = [o for o in WALKING if not o.startswith("env.walk.growth_start_fraction")]
    first = [o for o in first if o != "train.presentations=10"]
    first += ["train.presentations=5", "env.walk.growth_start_fraction=1.0"]
    _fit(first, part)
    assert changed_settings(load_run_config(part), compose(TINY + WALKING)) == []
    resumed = _fit(WALKING, part)
    full, again = _records(walking_run), _records(part)
    assert [r["walk_strides"] for r in again] == [r["walk_strides"] for r in full]
    assert [r["true_stride_m"] for r in again] == [r["true_stride_m"] for r in full]
    assert json.dumps(resumed["distance_error"]) == json.dumps(
        _summary(walking_run)["distance_error"]
    )
    assert (part / "metrics.jsonl").read_text() == (walking_run / "metrics.jsonl").read_text()


def test_a_resume_that_would_move_the_spurt_is_named():
    saved = compose(TINY + WALKING[1:] + ["train.presentations=5"])
    longer = compose(TINY + WALKING)
    assert changed_settings(saved, longer) == [
        "the growth spurt's presentation (env.walk.growth_start_fraction × "
        "train.presentations): 2 → 5"
    ]


# -- (e) configuration ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "overrides, key",
    [
        (["env.walk.stride_m=0"], "env.walk.stride_m"),
        (["env.walk.stride_m=-0.05"], "env.walk.stride_m"),
        (["env.walk.stride_slip=0.6"], "env.walk.stride_slip"),
        (["env.walk.stride_slip=-0.1"], "env.walk.stride_slip"),
        (["env.walk.substeps=0"], "env.walk.substeps"),
        (["env.walk.growth_factor=0"], "env.walk.growth_factor"),
        (
            ["distance.targets=odometry", "env.walk.growth_start_fraction=1.5"],
            "env.walk.growth_start_fraction",
        ),
        (["env.walk.growth_start_fraction=0.5"], "env.walk.growth_start_fraction"),
        (["distance.odometry.walk_fraction=0"], "distance.odometry.walk_fraction"),
        (["distance.odometry.walk_fraction=1.5"], "distance.odometry.walk_fraction"),
        (["distance.odometry.nominal_stride_m=0"], "distance.odometry.nominal_stride_m"),
        (["distance.fit_from=1000"], "distance.fit_from"),
        (["distance.fit_from=0"], "distance.fit_from"),
        (["distance.targets=nonsense"], "distance.targets"),
    ],
    ids=lambda value: " ".join(value) if isinstance(value, list) else value,
)
def test_validate_names_the_walk_and_odometry_key(overrides, key):
    with pytest.raises(ConfigError) as info:
        validate(compose(overrides))
    assert info.value.key == key


def test_the_walking_settings_of_these_tests_validate():
    validate(compose(TINY + WALKING))
    validate(compose(["distance.targets=odometry", "distance.fit_from=300"]))
    validate(compose(["experiment=embodied_growth"]))
