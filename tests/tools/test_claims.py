"""python -m parallax.tools.report.claims: the paper's claims with verdicts, on synthetic run
records whose differences are known (reproduced, reversed, the same numbers, robust or not), with
and without the scale ablation's runs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from parallax.config.schema import Config
from parallax.tools.report import claims as cl
from parallax.tools.report.claim_texts import LEARNT_TRIALS

POSITIONS = {
    "multi_5_20_weighted": [l / 100 for l in range(5, 21)],
    "multi_5_10": [l / 100 for l in range(5, 11)],
    **{f"single_{cm}": [int(cm) / 100] for cm in ("5", "7", "10", "13", "15", "20")},
}
GRID = [3.0 + 0.5 * k for k in range(15)]  # 3.0 … 10.0 m


def _eval(
    folder, presentations: int, perturbed: bool, errors: list[float], split: str = "heldout"
) -> None:
    """A parallax-eval result: the greedy eye on held-out photographs, or (``split`` "train")
    the eye as trained, whose errors are its sampled trials' (distance_sampled)."""
    folder.mkdir(parents=True, exist_ok=True)
    key = "distance_sampled" if split == "train" else "distance"
    evaluation = {
        "presentations": presentations,
        "perturbed": perturbed,
        "stimuli_overrides": [],
        "stimuli": {"source": "skimage", "split": split, "seed": 0},
        "textures_per_distance": 1,
        "robots": 16,
        "mae": {"greedy": 0.1},
        key: {"per_distance": {f"{d:.2f}": e for d, e in zip(GRID, errors)}},
    }
    (folder / "eval.json").write_text(json.dumps(evaluation))


def _run(
    folder,
    experiment,
    seed,
    rng,
    *,
    eye=0.1,
    eye_after=None,
    online=5.0,
    held_out=None,
    held_out_after=None,
    learnt=None,
    scales=("coarse", "fine"),
    weighting=True,
    replayed=None,
):
    """A finished run of 10 presentations (perturbed from the 6th; 10 robots, so that the
    20-trial window of the time to learn fills in two) with the given figures, each seed's
    numbers jittered a little so that the intervals are not degenerate."""
    lateral = POSITIONS[experiment.split("_", 1)[1]]
    labels = [f"{l * 100:g}" for l in lateral]
    cfg = OmegaConf.structured(Config)
    cfg.seed, cfg.env.robots, cfg.metrics.summary_trials = seed, 10, LEARNT_TRIALS
    cfg.curriculum.lateral_positions = lateral
    cfg.perturbation.start_fraction, cfg.train.presentations = 0.5, 10
    cfg.coder.scales, cfg.distance.weighting = list(scales), weighting
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    if replayed is None:
        (folder / ".hydra").mkdir()
        overrides = [f"experiment={experiment}", f"seed={seed}"] + [
            f"coder={scales[0]}" for _ in [0] if len(scales) == 1
        ]
        (folder / ".hydra" / "overrides.yaml").write_text(OmegaConf.to_yaml(overrides))

    def trials(mean):
        return {p: {"mean": mean + 0.01 * rng.random(), "var": 0.0, "trials": 100} for p in labels}

    after = eye if eye_after is None else eye_after
    summary = {
        "presentations": 10,
        "last_trials": trials(after),
        "distance_error": {"total": online + 0.1 * rng.random()},
        "before_perturbation": {
            "last_trials": trials(eye),
            "distance_error": {"total": online + 0.1 * rng.random()},
        },
    }
    if replayed is not None:
        summary |= {
            "replayed_from": str(replayed),
            "replay_overrides": ["distance.weighting=false"],
        }
    (folder / "summary.json").write_text(json.dumps(summary))
    if held_out is not None:
        after_errors = held_out if held_out_after is None else held_out_after
        _eval(folder / "eval_before", 5, False, list(held_out))
        _eval(folder, 10, True, list(after_errors))
        # the eye as trained: the same errors a tenth higher, on the training photographs
        _eval(folder / "eval_before_trained", 5, False, list(held_out * 1.1), split="train")
        _eval(folder / "eval_trained", 10, True, list(after_errors * 1.1), split="train")
    # the recent eye error falls below 0.2° at each position's presentation in ``learnt``
    learnt = learnt or {}
    records = [
        {
            "presentation": k,
            "steps": 30 * k,
            "perturbed": k > 5,
            "mae_recent_per_position": {p: 0.1 if k >= learnt.get(p, 2) else 1.0 for p in labels},
        }
        for k in range(1, 11)
    ]
    (folder / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))


@pytest.fixture
def records(tmp_path):
    """Both families: ours reproduces claims 1–5 clearly, the paper family's weighting changes
    nothing and its eye is not robust; no scale-ablation runs."""
    rng = np.random.default_rng(0)
    root = tmp_path / "runs"
    for prefix in ("paper", "recipe"):
        ours = prefix == "recipe"
        for seed in (0, 1, 2):
            noise = 0.05 * rng.random(len(GRID))
            weighted = 1.0 + noise
            source = root / prefix / f"experiment={prefix}_multi_5_20_weighted,seed={seed}"
            _run(source, f"{prefix}_multi_5_20_weighted", seed, rng, online=1.0,
                 held_out=weighted, held_out_after=weighted * 0.9, eye=0.1,
                 eye_after=0.1 if ours else 0.3,
                 learnt={"5": 2, "6": 2, "7": 2, "18": 4, "19": 4, "20": 4})  # fmt: skip
            unweighted = weighted + (0.5 if ours else 0.0)
            _run(root / f"{prefix}_replays" / f"{prefix}_multi_5_20" / f"s{seed}" / "w",
                 f"{prefix}_multi_5_20_weighted", seed, rng, held_out=unweighted,
                 held_out_after=unweighted * 0.9, weighting=False, replayed=source)  # fmt: skip
            _run(root / prefix / f"experiment={prefix}_multi_5_10,seed={seed}",
                 f"{prefix}_multi_5_10", seed, rng, held_out=2.0 + noise)  # fmt: skip
            for cm in ("5", "7", "10", "13", "15", "20"):
                _run(root / prefix / f"experiment={prefix}_single_{cm},seed={seed}",
                     f"{prefix}_single_{cm}", seed, rng, eye=0.5 if cm in ("15", "20") else 0.1,
                     online=5.0 + int(cm) / 10)  # fmt: skip
    return root


def _claim(result, number):
    return next(c for c in result["claims"] if c["number"] == number)


def _verdicts(claim, family):
    return [row["families"][family]["verdict"] for row in claim["comparisons"]]


def test_known_differences_get_their_verdicts(records):
    result = cl.claims(records)
    assert _claim(result, 1)["verdict"]["ours"].startswith("reproduced")
    weighting = _claim(result, 2)
    assert set(_verdicts(weighting, "ours")) == {"reproduced"}
    # the eye as trained: its own evaluations, the unweighted side 0.5 × 1.1 higher
    trained = [row for row in weighting["comparisons"] if "eye as trained" in row["comparison"]]
    assert len(trained) == 4
    before_total = trained[1]["families"]["ours"]
    assert before_total["b"] - before_total["a"] == pytest.approx(0.55)
    assert '--out "$RUN/eval_before_trained" --robots 16 --split train --between' in (
        cl.markdown(result)
    )
    # the paper family's weighting changes nothing: the same numbers, said so, never "reproduced"
    for row in weighting["comparisons"]:
        assert "same numbers" in row["families"]["paper_family"]["why"]
    robust = _claim(result, 3)
    assert robust["verdict"]["ours"].startswith("reproduced")
    # the paper family's eye error triples after the perturbation: far past the margin
    assert _verdicts(robust, "paper_family")[0] == "reversed"
    assert _claim(result, 4)["verdict"]["ours"].startswith("reproduced")
    small_first = _claim(result, 5)
    assert _verdicts(small_first, "ours")[0] == "reproduced"
    first = small_first["comparisons"][0]["families"]["ours"]
    assert first["a"] == pytest.approx(2.0) and first["b"] == pytest.approx(4.0)


def test_missing_scale_runs_are_said_missing_with_the_command_that_makes_them(records, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    cl.main(["--records", str(records), "--out", str(out)])
    data = json.loads((out / "claims.json").read_text())
    scales = _claim(data, 6)
    assert scales["verdict"] == {"paper_family": "runs missing", "ours": "runs missing"}
    assert (
        "bash launch/ablation_scales.sh  # trains and evaluates the runs below"
        in scales["commands"]
    )
    assert any("coder=fine" in c and c.startswith("parallax-train") for c in scales["commands"])
    text = (out / "claims.md").read_text()
    row = next(line for line in text.splitlines() if line.startswith("| [6]"))
    assert row.endswith("| runs missing | runs missing |")


def test_scale_runs_are_read_when_present(records, tmp_path):
    rng = np.random.default_rng(1)
    for seed in (0, 1, 2):
        for scale in ("coarse", "fine"):
            _run(records / "ablation_scales" / f"coder={scale},experiment=recipe,seed={seed}",
                 "recipe_multi_5_20_weighted", seed, rng, eye=0.6, scales=(scale,),
                 held_out=3.0 + rng.random(len(GRID)))  # fmt: skip
    result = cl.claims(records)
    scales = _claim(result, 6)
    assert scales["verdict"]["ours"].startswith("reproduced")
    assert scales["verdict"]["paper_family"] == "runs missing"
    assert all(row["families"]["ours"]["seeds"] == [0, 1, 2] for row in scales["comparisons"])


def test_a_run_with_settings_beyond_its_experiment_stands_for_no_set_up(records):
    # singles trained with another network: `parallax-train experiment=paper_single_5` gives
    # their eye (the distance learner never acts on it) but not their distance errors; singles
    # of another eye stand for nothing
    def launched_with(override, family):
        for folder in (records / family).glob(f"experiment={family}_single_*"):
            overrides = folder / ".hydra" / "overrides.yaml"
            listed = OmegaConf.to_container(OmegaConf.load(overrides))
            overrides.write_text(OmegaConf.to_yaml([override, *listed]))

    before = cl.claims(records)
    launched_with("distance.warm_start=true", "paper")
    launched_with("policy.discount=1.0", "recipe")
    result = cl.claims(records)
    assert _claim(result, 4)["verdict"] == {
        "paper_family": _claim(before, 4)["verdict"]["paper_family"],  # the eye: still read
        "ours": "runs missing",
    }
    assert _claim(before, 1)["verdict"]["paper_family"] != "runs missing"
    assert _claim(result, 1)["verdict"]["paper_family"] == "runs missing"  # distance vs singles


def test_the_readme_list_is_written_between_its_markers(records, tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\n{cl.README_BEGIN}\nold\n{cl.README_END}\ntail\n")
    cl.main(["--records", str(records), "--out", str(tmp_path), "--readme", str(readme)])
    lines = readme.read_text().splitlines()
    listed = [line for line in lines if line.startswith("- [")]
    assert len(listed) == 6 and "old" not in lines and lines[-1] == "tail"
    assert "ours runs missing." in listed[-1]


def test_no_records_folder_is_one_clear_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        cl.main(["--records", str(tmp_path / "nowhere"), "--out", str(tmp_path)])
    assert stop.value.code == 2
    assert capsys.readouterr().err.count("\n") == 1
