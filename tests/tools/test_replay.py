"""parallax-replay: the distance learner re-run on a run's logged eye-movement vectors s must be
exactly the run's own distance learner (same seed, same settings), and must respond to y/c."""

from __future__ import annotations

import json

import pytest
from omegaconf import OmegaConf

from parallax.config import load_run_config, run_name
from parallax.metrics import finite_or_none
from parallax.tools.replay import ReplayError, main, parse_sweep, replay

#: 8 presentations, queue c = 3, weighting on, perturbation from presentation 4; the paper's
#: readout (each trial's last pan), so that a test can replay it with the other one
PERTURBED = [
    "train.presentations=8",
    "distance.weighting=true",
    "distance.y=1.0",
    "perturbation=rotate_blur",
    "perturbation.start_fraction=0.5",
    "train.distance_readout=last",
]


@pytest.fixture(scope="module")
def perturbed_run(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(tmp_path_factory.mktemp("run"), PERTURBED)


def test_replay_as_trained_is_bit_identical(perturbed_run):
    trained = json.loads((perturbed_run / "summary.json").read_text())
    result = replay(perturbed_run)["summary"]
    assert trained["distance_error"], "the tiny run must have made online predictions"
    # empty ranges are NaN in memory and null in the strict JSON of summary.json
    assert finite_or_none(result["distance_error"]) == trained["distance_error"]
    assert (
        finite_or_none(result["before_perturbation"]["distance_error"])
        == trained["before_perturbation"]["distance_error"]
    )
    assert result["mae_per_position"] == trained["mae_per_position"]


def test_replay_with_other_settings_changes_the_learner(perturbed_run):
    trained = json.loads((perturbed_run / "summary.json").read_text())
    other = replay(perturbed_run, ["distance.y=8", "distance.weighting=true"])
    assert other["config"].distance.y == 8
    bigger = replay(perturbed_run, ["distance.queue_size=4"])["summary"]
    # a larger queue fills one presentation later: one prediction fewer in the online window
    assert json.dumps(bigger["distance_error"]) != json.dumps(trained["distance_error"])


def test_the_best_reward_readout_trains_and_replays_exactly(perturbed_run, tmp_path):
    # train.distance_readout=best_reward (beyond the paper): the learner is fed each trial's
    # best-encoded pan. The eye never depends on the learner, so replaying the last-pan run with
    # the other readout must give exactly the run trained with it.
    from tests.conftest import train_tiny_run

    best_run = train_tiny_run(tmp_path / "best", PERTURBED + ["train.distance_readout=best_reward"])
    trained = json.loads((best_run / "summary.json").read_text())
    last = json.loads((perturbed_run / "summary.json").read_text())
    assert trained["mae_per_position"] == last["mae_per_position"]  # the same eye
    assert json.dumps(trained["distance_error"]) != json.dumps(last["distance_error"])
    replayed = replay(perturbed_run, ["train.distance_readout=best_reward"])["summary"]
    assert finite_or_none(replayed["distance_error"]) == trained["distance_error"]
    records = [json.loads(line) for line in (best_run / "metrics.jsonl").read_text().splitlines()]
    assert all(len(r["best_pans"][0]) == len(r["pans"][0]) for r in records)
    with pytest.raises(
        ReplayError, match="train.distance_readout must be one of last, best_reward, got 'peak'"
    ):
        replay(perturbed_run, ["train.distance_readout=peak"])


def test_a_replay_writes_the_record_that_training_with_its_settings_writes(perturbed_run, tmp_path):
    # the replay's metrics.jsonl: the source's lines with the replayed learner's part, byte for
    # byte the lines of a run trained with those settings (the eye is the same)
    from parallax.tools.replay import write_replay
    from tests.conftest import train_tiny_run

    settings = ["distance.input_scaling=none", "distance.warm_start=false"]
    other = train_tiny_run(tmp_path / "other", PERTURBED + settings)
    write_replay(replay(perturbed_run, settings), tmp_path / "replayed")
    trained = (other / "metrics.jsonl").read_text()
    assert (tmp_path / "replayed" / "metrics.jsonl").read_text() == trained
    assert trained != (perturbed_run / "metrics.jsonl").read_text()
    write_replay(replay(perturbed_run), tmp_path / "as_trained")
    assert (tmp_path / "as_trained" / "metrics.jsonl").read_text() == (
        perturbed_run / "metrics.jsonl"
    ).read_text()
    # cut at the perturbation: the lines before it
    cut = replay(perturbed_run, until_perturbation=True)["metrics"]
    assert [line["presentation"] for line in cut] == [1, 2, 3, 4]


def test_a_replay_as_launched_is_the_run_its_launch_trains(perturbed_run, tmp_path, capsys):
    # a run trained with a distance setting its launch no longer has, replayed with the one the
    # launch composes: the launch's own run folder, record and overrides
    from tests.conftest import TINY, train_tiny_run

    launch = TINY + PERTURBED
    source = train_tiny_run(tmp_path / "source", launch + ["distance.input_scaling=none"])
    (source / ".hydra").mkdir()
    listed = launch + ["distance.input_scaling=none"]
    (source / ".hydra" / "overrides.yaml").write_text(OmegaConf.to_yaml(listed))
    out = tmp_path / "landed"
    main([str(source), "--out", str(out), "--as-launched", "distance.input_scaling=global"])
    (landed,) = [p for p in out.iterdir() if p.is_dir()]
    kept = OmegaConf.to_container(OmegaConf.load(landed / ".hydra" / "overrides.yaml"))
    assert "distance.input_scaling=none" not in kept and set(kept) <= set(launch)
    assert landed.name == run_name(",".join(sorted(kept)))
    assert (landed / "metrics.jsonl").read_text() == (perturbed_run / "metrics.jsonl").read_text()
    assert "replayed_from" not in json.loads((landed / "summary.json").read_text())
    # a replay that no launch of the source gives is refused, and nothing is written
    with pytest.raises(SystemExit) as stop:
        main([str(source), "--out", str(tmp_path / "no"), "--as-launched", "distance.y=2.0"])
    assert stop.value.code == 2 and not (tmp_path / "no").exists()
    assert "composes other settings" in capsys.readouterr().err
    # so is a source whose launch cannot be read
    (source / ".hydra" / "overrides.yaml").write_text("- [unclosed\n")
    with pytest.raises(SystemExit) as stop:
        main([str(source), "--out", str(tmp_path / "no"), "--as-launched", "distance.y=2.0"])
    assert stop.value.code == 2 and not (tmp_path / "no").exists()
    assert "no readable .hydra/overrides.yaml" in capsys.readouterr().err


def test_until_perturbation_is_the_unperturbed_run(perturbed_run):
    trained = json.loads((perturbed_run / "summary.json").read_text())
    cut = replay(perturbed_run, until_perturbation=True)
    before = trained["before_perturbation"]
    assert cut["summary"]["presentations"] == before["presentations"] == 4
    assert finite_or_none(cut["summary"]["distance_error"]) == before["distance_error"]
    assert cut["summary"]["mae_per_position"] == before["mae_per_position"]
    assert (
        cut["config"].train.presentations == 4 and cut["config"].perturbation.start_fraction is None
    )
    assert cut["config"].perturbation.camera_rotation_deg == 0.0


def test_cli_writes_run_like_folders(perturbed_run, tmp_path, capsys):
    main([str(perturbed_run), "--out", str(tmp_path / "out"), "distance.queue_size=3,4"])
    written = sorted(p.parent.name for p in (tmp_path / "out").rglob("summary.json"))
    assert written == ["distance.queue_size=3", "distance.queue_size=4"]
    cfg = load_run_config(next((tmp_path / "out").rglob("distance.queue_size=4")))
    assert cfg.distance.queue_size == 4
    printed = capsys.readouterr()
    assert "distance error" in printed.out
    # what it does and on what, and where each replay went (stderr, beside the results)
    err = printed.err.splitlines()
    assert (
        err[0]
        == "[parallax-replay] the distance learner re-run on the eye movements of 1 finished run"
    )
    assert "[parallax-replay]   overrides: distance.queue_size=3 | distance.queue_size=4" in err
    out = (tmp_path / "out").resolve()
    assert f"[parallax-replay] wrote {out / perturbed_run.name / 'distance.queue_size=4'}" in err
    # parallax-report reads the replays as runs and tables the factor that varies
    from parallax.tools.report.build import build_report

    text, data = build_report([tmp_path / "out"], out=tmp_path / "report", tables="ablation")
    assert "distance.queue_size" in text


def test_bad_overrides_are_refused_with_the_value():
    with pytest.raises(ReplayError, match="coder.atoms=4"):
        parse_sweep(["coder.atoms=4"])
    with pytest.raises(ReplayError, match="'distance.y' is neither an existing directory"):
        parse_sweep(["distance.y"])
    with pytest.raises(ReplayError, match="train.presentations=4"):
        parse_sweep(["train.presentations=4"])
    # the readout only picks which logged pan builds s, so the command line sweeps it too
    assert parse_sweep(["train.distance_readout=best_reward,last"]) == [
        ["train.distance_readout=best_reward"],
        ["train.distance_readout=last"],
    ]
    assert parse_sweep(["distance.y=1,2", "distance.weighting=false"]) == [
        ["distance.y=1", "distance.weighting=false"],
        ["distance.y=2", "distance.weighting=false"],
    ]


def test_run_directories_named_with_equals_signs_are_paths(perturbed_run, tmp_path):
    named = tmp_path / "distance.y=1,seed=0"
    named.symlink_to(perturbed_run, target_is_directory=True)
    main([str(named), "--out", str(tmp_path / "out"), "--until-perturbation", "distance.y=2"])
    assert len(list((tmp_path / "out").rglob("summary.json"))) == 1


def test_a_folder_without_runs_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([str(tmp_path), "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no finished run" in err[0]


def test_a_run_config_that_does_not_match_the_schema_is_refused(perturbed_run, tmp_path, capsys):
    stale = tmp_path / "stale"
    stale.mkdir()
    for name in ("config.yaml", "summary.json", "metrics.jsonl"):
        (stale / name).write_bytes((perturbed_run / name).read_bytes())
    with (stale / "config.yaml").open("a") as config:
        config.write("retired_setting: 1\n")
    with pytest.raises(SystemExit) as exit_info:
        main([str(stale), "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "retired_setting" in err[0]
    assert not (tmp_path / "out").exists()


def test_replayed_learners_are_scored_on_the_evals_eye_movements(perturbed_run, tmp_path):
    from parallax.tools.evaluate import evaluate

    after = evaluate(perturbed_run, distances=[4.0, 6.0], between=[5.5])
    before = evaluate(
        perturbed_run,
        distances=[4.0, 6.0],
        between=[5.5],
        out=perturbed_run / "eval_before",
        checkpoint_name="checkpoint_before_perturbation.pt",
    )
    assert len(after["distance"]["samples"]["pans"]) == 2
    # as trained: the replayed learners are the run's own, so the evals come back unchanged
    same = replay(perturbed_run)["evals"]
    assert json.dumps(same["eval.json"]["distance"]) == json.dumps(after["distance"])
    assert json.dumps(same["eval_before/eval.json"]["distance_between_grid"]) == json.dumps(
        before["distance_between_grid"]
    )
    # cut at the perturbation, the before-eval becomes the run's final eval
    main(
        [
            str(perturbed_run),
            "--out",
            str(tmp_path / "out"),
            "--until-perturbation",
            "distance.queue_size=3",
        ]
    )
    (written,) = list((tmp_path / "out").rglob("eval.json"))
    assert written.parent.name == "distance.queue_size=3"
    assert json.loads(written.read_text())["distance"]["by_range"] == pytest.approx(
        before["distance"]["by_range"], nan_ok=True
    )
    from parallax.tools.report.runs import load_run

    assert load_run(written.parent).final_eval() is not None
    # what was scored, a total each: online, then every rescored eval (held-out grid)
    from parallax.tools.replay import replay_totals

    totals = replay_totals(replay(perturbed_run))
    assert list(totals) == ["online", "eval.json", "eval_before/eval.json"]
    assert totals["eval.json"] == pytest.approx(after["distance"]["by_range"]["total"], nan_ok=True)


def test_a_cut_replay_keeps_each_before_eval_apart(perturbed_run, tmp_path):
    # each eval of the model before the perturbation (photographs of another kind, more per
    # distance) becomes the same eval of the cut replay's final model, none overwriting another
    import shutil

    from parallax.tools.evaluate import evaluate
    from parallax.tools.replay import final_eval_path

    assert final_eval_path("eval_before/eval.json") == "eval.json"
    assert final_eval_path("eval_before_textures5/eval.json") == "eval_textures5/eval.json"
    assert final_eval_path("custom/eval.json") == "custom/eval.json"
    source = tmp_path / "source"
    shutil.copytree(perturbed_run, source, ignore=shutil.ignore_patterns("eval*"))
    for folder, distances in (("eval_before", [4.0, 6.0]), ("eval_before_other", [5.0])):
        evaluate(
            source,
            distances=distances,
            out=source / folder,
            checkpoint_name="checkpoint_before_perturbation.pt",
        )
    main([str(source), "--out", str(tmp_path / "out"), "--until-perturbation"])
    run = tmp_path / "out" / "source" / "default"
    written = {str(p.relative_to(run)): json.loads(p.read_text()) for p in run.rglob("eval.json")}
    assert {k: len(e["distance"]["per_distance"]) for k, e in written.items()} == {
        "eval.json": 2,
        "eval_other/eval.json": 1,
    }
    # --rescore: only the evaluations named (an ablation's scoring), the others left out
    main([str(source), "--out", str(tmp_path / "some"), "--until-perturbation"]
         + ["--rescore", "eval_before_other", "distance.y=2"])  # fmt: skip
    run = tmp_path / "some" / "source" / "distance.y=2"
    assert [str(p.relative_to(run)) for p in run.rglob("eval.json")] == ["eval_other/eval.json"]


def test_an_eval_is_rescored_with_the_other_readout(perturbed_run, tmp_path):
    """The eval keeps s read out both ways, so a replay that changes the readout scores that
    readout's pans; as trained, it scores the eval's own."""
    import numpy as np

    from parallax.tools.evaluate import evaluate

    result = evaluate(perturbed_run, distances=[4.0, 6.0], between=[5.5], out=tmp_path / "ev")
    by_readout = result["greedy_samples_by_readout"]
    assert by_readout["last"]["grid"]["pans"] == result["greedy_samples"]["grid"]["pans"]
    last = np.array(by_readout["last"]["grid"]["pans"])
    best = np.array(by_readout["best_reward"]["grid"]["pans"])
    assert last.shape == best.shape == (2, len(result["lateral_positions_cm"]))
    (perturbed_run / "eval_readout").mkdir(exist_ok=True)
    (perturbed_run / "eval_readout" / "eval.json").write_text(json.dumps(result))
    try:
        rescored = replay(perturbed_run, ["train.distance_readout=best_reward"])["evals"]
        again = rescored["eval_readout/eval.json"]
        assert again["readout"] == "best_reward" and again["eye_readout"] == "last"
        assert again["distance"]["samples"]["pans"] == best.tolist()
    finally:
        (perturbed_run / "eval_readout" / "eval.json").unlink()
        (perturbed_run / "eval_readout").rmdir()


def test_frozen_robots_in_lockstep_give_the_same_greedy_eye(perturbed_run, tmp_path):
    from parallax.tools.evaluate import evaluate

    # from pan 0: a jittered start pan comes from each robot's own stream
    common = {"distances": [4.0, 6.0, 8.0], "between": [], "start_jitter": "off"}
    one = evaluate(perturbed_run, out=tmp_path / "one", **common)
    three = evaluate(perturbed_run, out=tmp_path / "three", robots=3, **common)
    assert three["robots"] == 3 and one["robots"] == 1
    assert three["greedy_samples"] == one["greedy_samples"]
    assert three["mae_per_position"]["greedy"] == one["mae_per_position"]["greedy"]
    with pytest.raises(ValueError, match="--robots must be at least 1, got 0"):
        evaluate(perturbed_run, distances=[4.0], out=tmp_path / "none", robots=0)
    assert not (tmp_path / "none").exists()


def test_the_cli_prints_each_runs_totals_and_their_spread(perturbed_run, tmp_path, capsys):
    from parallax.tools.evaluate import evaluate

    if not (perturbed_run / "eval.json").is_file():
        evaluate(perturbed_run, distances=[4.0, 6.0], between=[5.5])
    twin = tmp_path / "twin"  # the same run under a second name: two sources, equal totals
    twin.symlink_to(perturbed_run, target_is_directory=True)
    main([str(perturbed_run), str(twin), "--out", str(tmp_path / "out"), "distance.queue_size=3"])
    lines = capsys.readouterr().out.splitlines()
    per_run = [line for line in lines if ": distance error online " in line]
    assert len(per_run) == 2 and per_run[0].split(": ", 1)[1] == per_run[1].split(": ", 1)[1]
    assert "eval.json" in per_run[0]
    (spread,) = [line for line in lines if "mean ± sd over runs" in line]
    assert spread.startswith("[replay] distance.queue_size=3, mean ± sd over runs: online ")
    assert "± 0.00 % (n=2)" in spread


def test_evals_without_a_ready_learner_still_give_their_eye_movements():
    from parallax.tools.replay import _eval_samples

    kept = {"pans": [[0.1, 0.2]], "distances": [4.0]}
    assert _eval_samples({"greedy_samples": {"grid": kept, "between": kept}}, "last") == {
        "distance": kept,
        "distance_between_grid": kept,
    }
    assert _eval_samples({"distance": {"by_range": {}, "samples": kept}}, "last") == {
        "distance": kept
    }
    assert _eval_samples({"mae": {}}, "last") == {}
    # an eval of best-encoded pans without the other readout cannot give the last pans ...
    best = {"readout": "best_reward", "greedy_samples": {"grid": kept}}
    assert _eval_samples(best, "last") == {}
    # ... one that kept both readouts can
    best["greedy_samples_by_readout"] = {"last": {"grid": {"pans": [[0.3, 0.4]]}}}
    assert _eval_samples(best, "last") == {"distance": {"pans": [[0.3, 0.4]], "distances": [4.0]}}


def test_replayed_checkpoints_hold_the_replayed_learner(perturbed_run, tmp_path):
    """As trained, the replay writes the run's own checkpoints back; with another queue size, the
    checkpoints carry that learner, and parallax-eval on them scores what the replay rescored."""
    import torch

    from parallax import checkpoint
    from parallax.tools.evaluate import evaluate

    main([str(perturbed_run), "--out", str(tmp_path / "same")])
    (same,) = [p.parent for p in (tmp_path / "same").rglob("summary.json")]
    for name in ("checkpoint.pt", "checkpoint_before_perturbation.pt"):
        original, replayed = checkpoint.load(perturbed_run / name), checkpoint.load(same / name)
        for part in ("distance", "coder", "policy"):
            for key, value in original["experiment"][part].items():
                if isinstance(value, torch.Tensor):
                    assert torch.equal(value, replayed["experiment"][part][key]), (name, part, key)

    if not (perturbed_run / "eval.json").is_file():
        evaluate(perturbed_run, distances=[4.0, 6.0], between=[5.5])
    # (the tiny run's positions are not sensitive, so y would change nothing: c does)
    main([str(perturbed_run), "--out", str(tmp_path / "other"), "distance.queue_size=4"])
    (other,) = [p.parent for p in (tmp_path / "other").rglob("summary.json")]
    rescored = json.loads((other / "eval.json").read_text())["distance"]
    fresh = evaluate(other, distances=[4.0, 6.0], between=[5.5], out=tmp_path / "fresh")["distance"]
    assert fresh["by_range"] == pytest.approx(rescored["by_range"], nan_ok=True)
    trained = evaluate(
        perturbed_run, distances=[4.0, 6.0], between=[5.5], out=tmp_path / "trained"
    )["distance"]
    assert fresh["per_distance"] != trained["per_distance"]  # c = 4 is another learner


def test_an_open_setting_of_the_distance_learner_replays_as_its_files_settings():
    items = parse_sweep(["open_setting=plain_lm", "distance.y=1,2"])
    plain_lm = [
        "distance.validation_fraction=0.0",
        "distance.test_fraction=0.0",
        "distance.epochs_per_call=10",
        "distance.initial_epochs=100",
        "distance.reset_mu=false",
    ]
    assert items == [[*plain_lm, "distance.y=1"], [*plain_lm, "distance.y=2"]]
    with pytest.raises(ReplayError, match="policy.discount"):  # it changes the eye movements
        parse_sweep(["open_setting=xi_1"])
    with pytest.raises(ReplayError, match="no conf/open_setting/nothing.yaml"):
        parse_sweep(["+open_setting=nothing"])


def test_a_record_kept_for_replay_replays_bit_identically(perturbed_run, tmp_path):
    """`compact --keep replay` drops what neither the replays nor the reports read and rounds the
    rest, but keeps s and the distances exact: every replay of it is the whole record's."""
    import shutil

    from parallax.tools.analysis.network_calls import network_calls
    from parallax.tools.report.compact import compact
    from parallax.tools.report.runs import read_metrics

    kept = tmp_path / perturbed_run.name
    shutil.copytree(perturbed_run, kept)
    # one run (its evals, which other tests may have written, compressed beside its metrics)
    assert compact([kept], keep="replay")[0] == 1
    assert (kept / "metrics.jsonl.xz").is_file() and not (kept / "metrics.jsonl").exists()
    whole, lines = read_metrics(perturbed_run), read_metrics(kept)
    assert set(lines[0]) < set(whole[0]) and "reward" not in lines[0]
    assert [line["pans"] for line in lines] == [line["pans"] for line in whole]
    for overrides in ([], ["train.distance_readout=best_reward"], ["distance.queue_size=4"]):
        a, b = replay(perturbed_run, overrides)["summary"], replay(kept, overrides)["summary"]
        assert json.dumps(b["distance_error"]) == json.dumps(a["distance_error"]), overrides
        assert json.dumps(b["before_perturbation"]) == json.dumps(a["before_perturbation"])
    # the fit statistics stay, so the network's calls read the same (the errors to 7 digits)
    for block, whole_block in zip(network_calls(kept), network_calls(perturbed_run), strict=True):
        error = pytest.approx(whole_block["distance_error"], rel=5e-7)
        eye = pytest.approx(whole_block["eye_mae"], rel=5e-7)
        assert block == {**whole_block, "distance_error": error, "eye_mae": eye}
    # thinned to what the reports read, the record has no s left to replay
    compact([kept], keep="reports")
    with pytest.raises(ReplayError, match="no eye-movement vectors"):
        replay(kept)
