"""A robot that plans its route (movement.route=planned), end to end with the shrunk configs of
tests/conftest.py: what metrics.jsonl, the summary and the checkpoint record for sweeps and
planned routes; that the sweeps are the presentations the explore stream chose and a list run is
untouched by the movement settings; that a routed presentation visits the positions its callback
chose and, with the frozen greedy eye and no start jitter, sees the pans of a full sweep (the
claim that a route's trials are the sweep's); resuming; parallax-eval's route block (the routes
the robot runs, also with jittered starts) and replay; and the configuration checks of the
movement settings."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from parallax import checkpoint
from parallax.config import ConfigError, compose, load_run_config, validate
from parallax.distance.metrics import distance_error_by_range
from parallax.distance.planner import MovementPlanner
from parallax.experiment import Experiment
from parallax.metrics import DistanceErrorTracker, finite_or_none, position_label
from parallax.parts import seeds_for
from parallax.readouts import READOUTS
from parallax.readouts.best_reward import BestReward
from parallax.routes import SWEEP, Chosen, planned_route
from tests.conftest import TINY, train_tiny_run

LATERAL = [0.05, 0.1, 0.15, 0.2]
LATERAL_CM = [100.0 * l for l in LATERAL]
TRIAL_LENGTH = 4  # TINY's env.trial_length
QUEUE = 4
PRESENTATIONS = 14
#: A planned run: the queue fills with the first 4 sweeps, then a quarter of the presentations
#: sweep (movement.explore's default) and the others follow the planner. The trials start from
#: pan 0 after presentation 10, so that parallax-eval's trials do too (as in the shipped
#: planned_multi_5_20_weighted).
PLANNED = [
    "movement.route=planned",
    "curriculum.lateral_positions=[0.05,0.1,0.15,0.2]",
    f"distance.queue_size={QUEUE}",
    f"train.presentations={PRESENTATIONS}",
    "movement.price_per_trial=0.5",
    "train.start_jitter_presentations=10",
]
ROUTE_KEYS = {"route", "trials", "travel_cm", "route_estimate", "route_distance_error"}


def _records(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]


def _summary(run_dir: Path) -> dict:
    summary = json.loads((run_dir / "summary.json").read_text())
    summary.pop("timing")  # wall-clock values
    return summary


@pytest.fixture(scope="module")
def planned_run(tmp_path_factory):
    return train_tiny_run(tmp_path_factory.mktemp("planned"), PLANNED)


@pytest.fixture(scope="module")
def resumed_run(tmp_path_factory):
    """The planned run stopped after 7 presentations (mid-way through the planned ones) and
    resumed to 14."""
    run_dir = tmp_path_factory.mktemp("resumed")
    train_tiny_run(run_dir, PLANNED + ["train.presentations=7"])
    assert len(_records(run_dir)) == 7
    return train_tiny_run(run_dir, PLANNED)


@pytest.fixture(scope="module")
def records(planned_run):
    return _records(planned_run)


# --- (a) what a planned run records ----------------------------------------------------------
def test_the_run_both_sweeps_and_follows_the_planner(records):
    routes = [r["route"] for r in records]
    assert len(records) == PRESENTATIONS
    assert routes[:QUEUE] == [None] * QUEUE  # the planner's queue fills first
    planned = [r for r in routes if r is not None]
    assert planned and len(planned) < PRESENTATIONS - QUEUE  # some sweeps after the queue filled
    assert any(len(r) < len(LATERAL) for r in planned)


def test_a_sweep_is_logged_with_route_null_and_every_position(records):
    for r in (r for r in records if r["route"] is None):
        assert r["trials"] == len(LATERAL)
        assert r["travel_cm"] == pytest.approx(2 * max(LATERAL_CM))
        assert "route_estimate" not in r
        for key in ("pans", "best_pans", "start_pans"):
            assert np.isfinite(np.array(r[key], dtype=float)).all(), key


def test_a_planned_route_logs_its_positions_and_nan_elsewhere(records):
    for r in (r for r in records if r["route"] is not None):
        route = r["route"]
        assert all(isinstance(k, int) and 0 <= k < len(LATERAL) for k in route)
        assert len(set(route)) == len(route) == r["trials"]
        assert r["travel_cm"] == pytest.approx(2 * max(LATERAL_CM[k] for k in route))
        visited = np.isin(np.arange(len(LATERAL)), route)
        for key in ("pans", "best_pans", "start_pans"):
            values = np.array(r[key], dtype=float)[0]
            assert np.isfinite(values[visited]).all(), key
            assert np.isnan(values[~visited]).all(), key


def test_the_steps_grow_by_the_trials_times_the_trial_length(records):
    steps = [0] + [r["steps"] for r in records]
    for r, before, after in zip(records, steps, steps[1:]):
        assert after - before == r["trials"] * TRIAL_LENGTH


def test_the_eye_tracker_counts_the_visits(planned_run, records):
    summary = _summary(planned_run)
    visits = dict.fromkeys(range(len(LATERAL)), 0)
    for r in records:
        for k in range(len(LATERAL)) if r["route"] is None else r["route"]:
            visits[k] += 1
    assert summary["trials"] == sum(r["trials"] for r in records) == sum(visits.values())
    counts = {label: v["trials"] for label, v in summary["last_trials"].items()}
    assert counts == {position_label(LATERAL[k]): n for k, n in visits.items()}
    assert len(set(counts.values())) > 1  # the routes did not visit every position alike


def test_each_route_is_the_planners_on_the_queue_of_the_sweeps_before_it(records):
    # the planner's queue at each presentation: the last c sweeps before it, newest first; it
    # reads s as the run's train.distance_readout (best_reward: best_pans)
    planner = MovementPlanner(LATERAL, queue_size=QUEUE, price_per_trial=0.5)
    planned = 0
    for r in records:
        s = np.array(r["best_pans"][0], dtype=float)
        if r["route"] is None:
            planner.observe(s, r["distances"][0])
            continue
        planned += 1
        route, estimate = planner.plan(s)  # it reads only the pans at the positions it visits
        assert r["route"] == route
        assert r["route_estimate"] == pytest.approx(estimate, rel=1e-12)
    assert planned > 0


def test_the_route_error_scores_the_planned_estimates_only(planned_run, records):
    tracker = DistanceErrorTracker()
    for r in records:
        if r["route"] is not None:
            tracker.record(r["route_estimate"], r["distances"][0])
        assert json.dumps(r["route_distance_error"]) == json.dumps(tracker.by_range())
    # summary.json is strict JSON: a range no panel fell in is null there
    assert json.dumps(_summary(planned_run)["route_distance_error"]) == json.dumps(
        finite_or_none(tracker.by_range())
    )


def test_the_checkpoint_holds_the_planners_queue_of_the_last_sweeps(planned_run, records):
    state = checkpoint.load(planned_run / checkpoint.CHECKPOINT_NAME)["experiment"]
    sweeps = [r for r in records if r["route"] is None][::-1][:QUEUE]  # newest first
    np.testing.assert_array_equal(
        state["planner"]["distances"], [r["distances"][0] for r in sweeps]
    )
    np.testing.assert_array_equal(state["planner"]["inputs"], [r["best_pans"][0] for r in sweeps])
    assert "explore" in state


def _scalar_tags(run_dir: Path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run_dir / "tb"), size_guidance={"scalars": 0}).Reload()
    return events, set(events.Tags()["scalars"])


def test_tensorboard_shows_where_the_robot_went(planned_run, records):
    events, tags = _scalar_tags(planned_run)
    assert {"movement/sweep", "movement/trials", "movement/travel_cm"} <= tags
    assert "movement/route_error_pct_total" in tags
    assert [e.value for e in events.Scalars("movement/sweep")] == [
        float(r["route"] is None) for r in records
    ]
    assert [e.value for e in events.Scalars("movement/trials")] == [r["trials"] for r in records]
    assert [e.step for e in events.Scalars("movement/trials")] == [r["steps"] for r in records]


# --- (b) the explore stream, and list runs ---------------------------------------------------
def test_the_sweeps_are_the_presentations_the_explore_stream_chose(records):
    cfg = compose(TINY + PLANNED)
    robots, explore = int(cfg.env.robots), float(cfg.movement.explore)
    stream = np.random.RandomState(seeds_for(int(cfg.seed), robots + 5)[robots + 4] % 2**32)
    sweeps = 0
    for r in records:
        draw = stream.random_sample()  # drawn every presentation, the queue full or not
        chosen = sweeps < QUEUE or draw < explore
        assert (r["route"] is None) == chosen, r["presentation"]
        sweeps += chosen


def test_the_routes_follow_the_seed(planned_run, resumed_run, tmp_path):
    routes = [r["route"] for r in _records(planned_run)]
    assert [r["route"] for r in _records(resumed_run)] == routes  # the same seed
    other = train_tiny_run(tmp_path / "seed1", PLANNED + ["seed=1"])
    assert [r["route"] for r in _records(other)] != routes


def test_a_list_run_ignores_the_movement_settings(tmp_path):
    plain = train_tiny_run(tmp_path / "plain")
    listed = train_tiny_run(
        tmp_path / "list",
        [
            "movement.route=list",
            "movement.price_per_trial=0.7",
            "movement.price_per_cm=0.2",
            "movement.explore=0.5",
        ],
    )
    text = (listed / "metrics.jsonl").read_text()
    assert text == (plain / "metrics.jsonl").read_text()
    assert not ROUTE_KEYS & set().union(*(r.keys() for r in _records(listed)))
    assert _summary(listed) == _summary(plain)
    assert "route_distance_error" not in _summary(listed)
    state = checkpoint.load(listed / checkpoint.CHECKPOINT_NAME)["experiment"]
    assert "planner" not in state and "explore" not in state
    assert not {tag for tag in _scalar_tags(listed)[1] if tag.startswith("movement/")}


# --- (c) a routed presentation -----------------------------------------------------------------
ROUTED = TINY + [
    "curriculum.lateral_positions=[0.05,0.1,0.15,0.2]",
    "env.initial_pan_jitter_deg=0",
    "env.trial_length=10",
]


@pytest.fixture(scope="module")
def learnt():
    """An experiment whose eye learnt for two presentations (an untrained greedy eye does not
    move), and its state to start each check from."""
    exp = Experiment(compose(ROUTED))
    try:
        for _ in range(2):
            exp.run_presentation(learn=True)
        yield exp, copy.deepcopy(exp.state_dict())
    finally:
        exp.close()


def _scripted(order, calls=None):
    def route(visited, so_far):
        if calls is not None:
            calls.append((list(visited), so_far.pans.copy()))
        return order[len(visited)] if len(visited) < len(order) else None

    return Chosen(route)


def _frozen(exp, state, texture, distance, route=SWEEP):
    exp.load_state_dict(copy.deepcopy(state))
    exp.envs[0].task.set_next_stimulus(texture_index=texture, distance=distance)
    return exp.run_presentation(learn=False, greedy=True, route=route)


def test_a_route_visits_the_chosen_positions_in_order(learnt, monkeypatch):
    exp, state = learnt
    task = exp.envs[0].task
    moves = []
    start_route, visit_next = task.start_route, task.visit_next
    monkeypatch.setattr(task, "start_route", lambda l: (moves.append(l), start_route(l))[1])
    monkeypatch.setattr(task, "visit_next", lambda l: (moves.append(l), visit_next(l))[1])
    calls = []
    pres = _frozen(exp, state, 1, 6.0, _scripted([3, 0], calls))
    assert pres.route == [3, 0]
    assert moves == [LATERAL[3], LATERAL[0]]
    assert [visited for visited, _ in calls] == [[], [3], [3, 0]]
    # each call saw the pans of the trials done so far, NaN elsewhere
    assert np.isnan(calls[0][1]).all()
    assert np.isfinite(calls[1][1][0, 3]) and np.isnan(calls[1][1][0, [0, 1, 2]]).all()
    assert pres.steps == 2 * 10
    assert np.isnan(pres.pans[0, [1, 2]]).all() and np.isfinite(pres.pans[0, [0, 3]]).all()
    assert pres.distances.tolist() == [6.0] and pres.textures.tolist() == [1]


@pytest.mark.parametrize(
    "order, texture, distance", [([3, 0], 1, 6.0), ([2], 3, 3.0), ([1, 3, 0], 4, 9.0)], ids=str
)
def test_a_greedy_route_sees_the_pans_of_the_full_sweep(learnt, order, texture, distance):
    exp, state = learnt
    sweep = _frozen(exp, state, texture, distance)
    routed = _frozen(exp, state, texture, distance, _scripted(order))
    assert routed.route == order and sweep.route is None
    assert np.isfinite(sweep.pans).all() and np.ptp(sweep.read(BestReward)) > 0  # it moved
    for key in ("pans", "targets", "start_pans"):
        np.testing.assert_array_equal(
            getattr(routed, key)[0, order], getattr(sweep, key)[0, order], err_msg=key
        )
    for readout in READOUTS.values():
        np.testing.assert_array_equal(
            routed.read(readout)[0, order], sweep.read(readout)[0, order], err_msg=readout.name
        )
    assert routed.distances.tolist() == sweep.distances.tolist() == [distance]


def test_a_reversed_route_sees_the_pans_of_the_sweep_everywhere(learnt):
    # stimuli where, from this state, a route through L backwards reaches a position with other
    # pans than the sweep (with policy.eval() set, every one of them agrees)
    exp, state = learnt
    order = [3, 2, 1, 0]
    for texture, distance in ((3, 4.0), (3, 6.0), (4, 7.0), (5, 10.0)):
        sweep = _frozen(exp, state, texture, distance)
        routed = _frozen(exp, state, texture, distance, _scripted(order))
        assert routed.route == order
        np.testing.assert_array_equal(routed.pans, sweep.pans)
        np.testing.assert_array_equal(routed.read(BestReward), sweep.read(BestReward))


def test_a_frozen_presentation_leaves_the_policy_as_it_was(learnt):
    exp, state = learnt
    exp.load_state_dict(copy.deepcopy(state))
    before = copy.deepcopy(exp.policy.state_dict())
    exp.run_presentation(learn=False, greedy=True)
    after = exp.policy.state_dict()
    changed = [k for k, v in before.items() if hasattr(v, "shape") and not (v == after[k]).all()]
    assert changed == []


def test_a_route_must_visit_a_position_and_none_twice(learnt):
    exp, state = learnt
    with pytest.raises(ValueError, match="at least one"):
        _frozen(exp, state, 0, 5.0, Chosen(lambda visited, so_far: None))
    with pytest.raises(ValueError, match="twice"):
        _frozen(exp, state, 0, 5.0, _scripted([2, 2]))


def test_visit_next_needs_a_route_and_a_trials_last_iteration(learnt):
    exp, state = learnt
    exp.load_state_dict(copy.deepcopy(state))
    env, task = exp.envs[0], exp.envs[0].task
    env.reset()  # a sweep of L
    with pytest.raises(RuntimeError, match="needs a route"):
        task.visit_next(LATERAL[1])
    task.start_route(LATERAL[2])
    timestep = env.reset()
    assert float(timestep.observation["lateral_position"]) == LATERAL[2]
    with pytest.raises(RuntimeError, match="last iteration"):
        task.visit_next(LATERAL[1])  # at iteration 0
    for _ in range(task.trial_length - 1):
        timestep = env.step(0.0)
    assert int(timestep.observation["iteration"]) == task.trial_length - 1
    task.visit_next(LATERAL[0])
    timestep = env.step(0.0)
    assert float(timestep.observation["lateral_position"]) == LATERAL[0]
    assert int(timestep.observation["iteration"]) == 0
    # a route never ends by itself, even past its last position's trial
    for _ in range(task.trial_length - 1):
        timestep = env.step(0.0)
        assert not timestep.last()


# --- (d) resuming --------------------------------------------------------------------------------
def test_a_resumed_planned_run_is_the_uninterrupted_run(planned_run, resumed_run):
    assert (resumed_run / "metrics.jsonl").read_text() == (
        planned_run / "metrics.jsonl"
    ).read_text()
    assert json.dumps(_summary(resumed_run)) == json.dumps(_summary(planned_run))


# --- (e) parallax-eval and replay ----------------------------------------------------------------
EVAL_DISTANCES = [3.0, 6.0, 9.0]


@pytest.fixture(scope="module")
def evaluated(planned_run):
    from parallax.tools.evaluate import evaluate

    return evaluate(planned_run, distances=EVAL_DISTANCES, between=[])


def test_the_movement_analysis_reports_robots_that_planned_while_they_learnt(
    planned_run, evaluated, tmp_path
) -> None:
    from parallax.tools.analysis import movement

    out = tmp_path / "movement"
    argv = [str(planned_run), "--out", str(out), "--prices", "0", "1e6", "--trained"]
    assert movement.main([*argv, str(planned_run)]) == 0
    results = json.loads((out / "movement.json").read_text())
    (own,) = results["trained"]
    assert own["route"]["by_range"] == evaluated["route"]["by_range"]
    # the curve over the price: the run's own planner queue and eye, at each price
    (curve,) = results["trained_curves"]
    assert [p["price_per_trial"] for p in curve["planner"]] == [0.0, 1e6]
    assert curve["planner"][1]["eye_movements"] == TRIAL_LENGTH  # a price no error can pay
    page = (out / "README.md").read_text()
    movements = own["route"]["eye_movements"]
    assert f"{own['route']['by_range']['total']:.2f} % distance error with {movements:.0f}" in page
    assert f"{movements / (len(LATERAL) * TRIAL_LENGTH):.0%} of the fixed 5-20 cm list" in page


def _checkpoint_planner(run_dir: Path) -> MovementPlanner:
    state = checkpoint.load(run_dir / checkpoint.CHECKPOINT_NAME)["experiment"]
    planner = MovementPlanner(LATERAL, queue_size=QUEUE, price_per_trial=0.5)
    planner.load_state_dict(state["planner"])
    return planner


def test_parallax_eval_reports_the_planned_route(planned_run, evaluated):
    from parallax.tools.evaluate import format_eval

    route = evaluated["route"]
    assert evaluated["start_jitter"] is False
    assert route["presentations"] == len(EVAL_DISTANCES)
    assert TRIAL_LENGTH <= route["eye_movements"] <= len(LATERAL) * TRIAL_LENGTH
    assert set(route["by_range"]) == {"3-4.9", "5-6.9", "7-10", "total"}
    assert route["price_per_trial"] == 0.5 and route["price_per_cm"] == 0.0
    assert set(route["trials_by_distance"]) == {f"{d:.2f}" for d in EVAL_DISTANCES}
    # the block is the planner of the checkpoint on the greedy eye's samples
    planner = _checkpoint_planner(planned_run)
    samples = evaluated["greedy_samples"]["grid"]
    plans = [planner.plan(np.array(s, dtype=float)) for s in samples["pans"]]
    assert route["routes"] == [visited for visited, _ in plans]
    expected = distance_error_by_range([e for _, e in plans], samples["distances"])
    assert json.dumps(route["by_range"]) == json.dumps(expected)
    trials = np.mean([len(visited) for visited, _ in plans])
    assert route["eye_movements"] == pytest.approx(trials * TRIAL_LENGTH)
    saved = json.loads((planned_run / "eval.json").read_text())
    assert saved["route"]["routes"] == route["routes"]
    assert "planned route: distance error" in format_eval(evaluated)


def _routes_run(run_dir: Path, jittered: bool) -> tuple[list, dict]:
    """The routes the robot runs on parallax-eval's held-out presentations, as the eval runs its
    sweeps: from the checkpoint's state, on the final list, unperturbed, the greedy eye; and
    the errors of their estimates by range."""
    exp = Experiment(load_run_config(run_dir), stimuli_split="heldout")
    try:
        exp.load_state_dict(checkpoint.load(run_dir / checkpoint.CHECKPOINT_NAME)["experiment"])
        exp.set_stage(len(exp.stages) - 1)
        exp.set_perturbation(False)
        exp.set_start_jitter(jittered)
        textures = exp.envs[0].task.num_textures
        routes, estimates = [], []
        for i, d in enumerate(EVAL_DISTANCES):
            exp.envs[0].task.set_next_stimulus(texture_index=i % textures, distance=d)
            route = planned_route(exp.planner, BestReward)
            pres = exp.run_presentation(learn=False, greedy=True, route=route)
            routes.append(pres.route)
            estimates.append(exp.planner.estimate(pres.route, pres.read(BestReward)[0, pres.route]))
    finally:
        exp.close()
    return routes, distance_error_by_range(estimates, EVAL_DISTANCES)


def test_parallax_evals_routes_are_those_the_robot_runs(planned_run, evaluated):
    routes, by_range = _routes_run(planned_run, jittered=False)
    assert routes == evaluated["route"]["routes"]
    assert json.dumps(evaluated["route"]["by_range"]) == json.dumps(by_range)


def test_parallax_evals_routes_with_jittered_starts_are_those_the_robot_runs(planned_run, tmp_path):
    from parallax.tools.evaluate import evaluate

    result = evaluate(
        planned_run, distances=EVAL_DISTANCES, between=[], start_jitter="on", out=tmp_path
    )
    assert result["start_jitter"] is True
    routes, by_range = _routes_run(planned_run, jittered=True)
    assert routes == result["route"]["routes"]
    assert json.dumps(result["route"]["by_range"]) == json.dumps(by_range)


def test_replay_reproduces_a_planned_runs_distance_error(planned_run, evaluated):
    from parallax.tools.replay import replay

    trained = _summary(planned_run)
    assert trained["distance_error"], "the network must have made online predictions"
    result = replay(planned_run)
    assert finite_or_none(result["summary"]["distance_error"]) == trained["distance_error"]
    # and the eval's distances, rescored by the replayed network on the eval's samples
    (rescored,) = result["evals"].values()
    assert json.dumps(rescored["distance"]) == json.dumps(evaluated["distance"])


# --- (f) the configuration checks ----------------------------------------------------------------
@pytest.mark.parametrize(
    "overrides, key",
    [
        (["movement.route=nonsense"], "movement.route"),
        (["movement.explore=0"], "movement.explore"),
        (["movement.explore=1.5"], "movement.explore"),
        (["movement.price_per_trial=-1"], "movement.price_per_trial"),
        (["movement.price_per_cm=-0.5"], "movement.price_per_cm"),
        (["movement.route=planned", "env.robots=2"], "env.robots"),
        (["movement.route=planned", "distance.targets=odometry"], "distance.targets"),
        (["movement.route=planned", "curriculum=staged"], "curriculum.stages"),
    ],
    ids=lambda value: " ".join(value) if isinstance(value, list) else value,
)
def test_validate_names_the_movement_key(overrides, key):
    with pytest.raises(ConfigError) as info:
        validate(compose(overrides))
    assert info.value.key == key


def test_the_movement_settings_of_these_tests_validate():
    validate(compose(TINY + PLANNED))
    validate(compose(["experiment=planned_multi_5_20_weighted"]))
    validate(compose(["movement.route=planned", "movement.explore=1"]))
    # the checks of a planned route apply to planned routes only
    validate(compose(["env.robots=2", "distance.targets=odometry", "curriculum=staged"]))
