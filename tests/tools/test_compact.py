"""Compressed run records (`python -m parallax.tools.report.compact`): every reader takes a
compressed metrics.jsonl or eval.json as the plain one, and a report made from compacted runs is
the one made from the plain runs, byte for byte."""

from __future__ import annotations

import gzip
import json
import lzma
import os

import numpy as np
import pytest

from parallax.config import compose
from parallax.tools.report.build import build_report
from parallax.tools.report.compact import compact, compress, main
from parallax.tools.report.figures import eye_records
from parallax.tools.report.runs import eval_files, load_run, read_metrics, read_record
from tests.tools.test_report import write_eval, write_run

PACK = {".gz": lambda data: gzip.compress(data, mtime=0), ".xz": lzma.compress}


@pytest.mark.parametrize("suffix", [".gz", ".xz"])
def test_read_metrics_reads_a_compressed_record_as_the_plain_one(tmp_path, suffix):
    lines = [
        {"presentation": 1, "mae": 0.5, "lm_loss": float("nan"), "pans": [[0.1, -0.25]]},
        {"presentation": 2, "mae": 0.25, "mae_per_position": {"5": 0.1}, "distances": [3.3]},
    ]
    text = "".join(json.dumps(line) + "\n" for line in lines) + '{"presentation": 3, "ma'
    plain, packed = tmp_path / "plain", tmp_path / "packed"
    plain.mkdir()
    packed.mkdir()
    (plain / "metrics.jsonl").write_text(text)
    (packed / f"metrics.jsonl{suffix}").write_bytes(PACK[suffix](text.encode()))
    records = read_metrics(plain)
    assert len(records) == 2  # the torn last line is skipped in both
    assert json.dumps(read_metrics(packed)) == json.dumps(records)  # NaN included
    assert read_record(packed / "metrics.jsonl") == text


def _runs(root, rng):
    cfg = compose(["experiment=recipe_multi_5_20_weighted", "train.presentations=10"])
    for seed in range(2):
        run = root / f"experiment=recipe_multi_5_20_weighted,seed={seed}"
        write_run(run, cfg, seed, rng)
        write_eval(run, rng, 5, False, sub="eval_before")
        write_eval(run, rng, 10, True)
    unfinished = root / "experiment=recipe_multi_5_20_weighted,seed=2"
    write_run(unfinished, cfg, 2, rng)
    (unfinished / "summary.json").unlink()
    return sorted(root.iterdir())


def _read(run):
    loaded = load_run(run)
    return json.dumps([loaded.summary, loaded.evals, loaded.problem, read_metrics(run)])


def test_a_report_from_compacted_runs_is_the_plain_runs_report(tmp_path):
    root = tmp_path / "runs"
    runs = _runs(root, np.random.default_rng(3))
    read_plain = [_read(run) for run in runs]
    plain_texts = {p: p.read_text() for p in root.rglob("*") if p.suffix in (".json", ".jsonl")}
    report_plain, _ = build_report([root], tmp_path / "plain", tables="paper")
    os.utime(runs[0] / "eval.json", (1_000_000_000, 1_000_000_000))

    runs_done, records, saved = compact([root])
    assert (runs_done, records) == (2, 6) and saved > 0
    finished = runs[:2]
    for run in finished:
        assert sorted(p.name for p in run.rglob("*") if p.is_file()) == [
            "config.yaml",
            "eval.json.xz",
            "eval.json.xz",
            "metrics.jsonl.xz",
            "summary.json",
        ]
        assert eval_files(run) == [run / "eval.json", run / "eval_before" / "eval.json"]
    # the unfinished run keeps its plain log (the trainer resumes from it)
    assert (runs[2] / "metrics.jsonl").is_file()
    assert (runs[0] / "eval.json.xz").stat().st_mtime == 1_000_000_000  # the eval's time, kept
    for path, text in plain_texts.items():
        assert read_record(path) == text
    assert [_read(run) for run in runs] == read_plain

    report_packed, _ = build_report([root], tmp_path / "packed", tables="paper")
    assert report_packed == report_plain
    for name in ("README.md", "results.json"):
        assert (tmp_path / "packed" / name).read_bytes() == (tmp_path / "plain" / name).read_bytes()

    # again: nothing to do; the same record always compresses to the same bytes
    packed = (runs[1] / "metrics.jsonl.xz").read_bytes()
    assert compact([root])[1] == 0
    assert compress(plain_texts[runs[1] / "metrics.jsonl"].encode(), ".xz") == packed


def test_a_plain_record_beside_a_compressed_one_is_the_newer(tmp_path, capsys):
    root = tmp_path / "runs"
    run = _runs(root, np.random.default_rng(5))[0]
    compact([root])
    newer = {"presentations": 10, "perturbed": True, "note": "evaluated again"}
    (run / "eval.json").write_text(json.dumps(newer))  # parallax-eval writes plain files
    assert load_run(run).evals[0]["note"] == "evaluated again"
    main([str(root), "--format", "gz"])  # converts, and the new eval replaces the old one
    assert "2 runs finished or diverged: 6 records compressed (gz)" in capsys.readouterr().out
    assert sorted(p.name for p in run.iterdir() if "eval" in p.name) == [
        "eval.json.gz",
        "eval_before",
    ]
    assert json.loads(read_record(run / "eval.json"))["note"] == "evaluated again"
    assert (
        gzip.decompress((run / "metrics.jsonl.gz").read_bytes())
        == read_record(run / "metrics.jsonl").encode()
    )


def test_compact_names_a_path_that_holds_no_run(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "missing")])
    assert exc.value.code == 2
    assert "missing does not exist" in capsys.readouterr().err


def test_thinning_keeps_what_the_reports_read_and_drops_the_vectors(tmp_path):
    from parallax.tools.report.compact import READ_BY_REPORTS

    runs = _runs(tmp_path, np.random.default_rng(0))
    before = read_metrics(runs[0])
    assert all(set(line) <= set(READ_BY_REPORTS) for line in before)
    with_vectors = [{**line, "pans": [[0.1, 0.2]], "lm_loss": 0.5} for line in before]
    (runs[0] / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in with_vectors))
    compact([runs[0]], keep="reports")
    assert not (runs[0] / "metrics.jsonl").exists()  # compressed, as without thinning
    thinned = read_metrics(runs[0])
    assert [line.keys() for line in thinned] == [line.keys() for line in before]
    assert thinned != before  # the random figures had 17 digits
    for kept, line in zip(thinned, before, strict=True):
        assert kept["mae"] == pytest.approx(line["mae"], rel=5e-7)
        assert len(repr(kept["mae"]).lstrip("0.").replace(".", "")) <= 7
    compact([runs[0]], keep="reports")  # a thinned record thins to itself
    assert read_metrics(runs[0]) == thinned


def test_a_replays_record_keeps_its_learners_keys_and_a_trained_run_is_refused(tmp_path, capsys):
    root = tmp_path / "runs"
    runs = _runs(root, np.random.default_rng(1))[:2]
    lines = [
        {**line, "pans": [[0.1, 0.2]], "lm_loss": 1 / 3, "distance_error": 2 / 3}
        for line in read_metrics(runs[0])
    ]
    for run in runs:
        (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    record = runs[0] / "metrics.jsonl"
    with pytest.raises(SystemExit) as exc:  # neither is a replay yet
        main([str(root), "--keep", "distance"])
    assert exc.value.code == 2
    assert "not a replay" in capsys.readouterr().err
    assert record.read_text() == "".join(json.dumps(r) + "\n" for r in lines)  # untouched
    source = tmp_path / "source"  # the eye the replays replayed, outside the reported folder
    source.mkdir()
    (source / "metrics.jsonl").write_text(record.read_text())
    for run in runs:
        summary = json.loads((run / "summary.json").read_text())
        (run / "summary.json").write_text(json.dumps({**summary, "replayed_from": str(source)}))
    compact([root], keep="distance")
    kept = read_metrics(runs[0])
    assert {"mae", "mae_per_position", "pans"}.isdisjoint(kept[0])
    assert kept[0]["lm_loss"] == 0.3333333 and kept[0]["distance_error"] == 0.6666667
    assert [line["presentation"] for line in kept] == [line["presentation"] for line in lines]
    # the replays' eye curve is their source's, read from it
    assert eye_records(load_run(runs[0])) == read_metrics(source)
    report, _ = build_report([root], tmp_path / "report", tables="paper")
    assert "mae_g01.png" in json.dumps(report)
    (source / "metrics.jsonl").unlink()  # a source gone is said, not a curve quietly left out
    with pytest.raises(FileNotFoundError, match="its source's, .*source, which has no metrics"):
        build_report([root], tmp_path / "report2", tables="paper")


def test_a_replays_eye_is_drawn_once_with_its_sources(tmp_path):
    root = tmp_path / "runs"
    sources = _runs(root, np.random.default_rng(2))[:2]
    unweighted = compose(["experiment=recipe_multi_5_20_weighted", "train.presentations=10"])
    unweighted.distance.weighting = False
    for k, source in enumerate(sources):  # each seed's learner replayed without the weighting
        replay = root / "replays" / source.name
        write_run(replay, unweighted, k, np.random.default_rng(k))
        summary = json.loads((replay / "summary.json").read_text())
        (replay / "summary.json").write_text(json.dumps({**summary, "replayed_from": str(source)}))
    compact([root / "replays"], keep="distance")
    build_report([root], tmp_path / "report", tables="paper")
    text = (tmp_path / "report" / "README.md").read_text()
    assert text.count("](mae_g0") == 1  # two groups, one eye
    (said,) = [line for line in text.splitlines() if "drawn there" in line]
    assert "weighting=False: the same eye movements as g0" in said  # drawn with its source


def test_replays_alone_are_compared_with_the_setting_of_the_runs_they_replay(tmp_path):
    source = tmp_path / "source"  # a recipe run: c = 100, not the shipped default
    cfg = compose(["experiment=recipe_multi_5_20_weighted", "train.presentations=10"])
    write_run(source, cfg, 0, np.random.default_rng(0))
    for c in (50, 100, 300):
        replay = tmp_path / "replays" / f"c{c}"
        cfg.distance.queue_size = c
        write_run(replay, cfg, 0, np.random.default_rng(c))
        summary = json.loads((replay / "summary.json").read_text())
        (replay / "summary.json").write_text(json.dumps({**summary, "replayed_from": str(source)}))
    assert compose([]).distance.queue_size != 100
    build_report([tmp_path / "replays"], tmp_path / "report", tables="ablation")
    text = (tmp_path / "report" / "README.md").read_text()
    assert "| 100 (baseline) |" in text and "| 300 (baseline) |" not in text
    # one eye for every c: its bars are drawn, its curves not overlaid on themselves
    assert "(ablation_distance.queue_size.png)" in text
    assert "ablation_distance.queue_size_mae.png" not in text


def test_a_single_positions_repeated_scalars_are_left_to_their_dict_and_read_back(tmp_path):
    runs = _runs(tmp_path / "runs", np.random.default_rng(2))[:2]
    single = [
        {**line, "mae": 1 / 3, "mae_per_position": {"13": 1 / 3}, "mae_recent": 0.25}
        | {"mae_recent_per_position": {"13": 0.25}}
        for line in read_metrics(runs[0])
    ]
    several = [{**line, "mae": 0.5, "mae_per_position": {"5": 0.4, "20": 0.6}} for line in single]
    for run, lines in zip(runs, (single, several), strict=True):
        (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    compact(runs, keep="reports")
    raw = [json.loads(line) for line in read_record(runs[0] / "metrics.jsonl").splitlines()]
    assert not {"mae", "mae_recent"} & set(raw[0])  # repeated in their dicts: left out
    assert [(r["mae"], r["mae_recent"]) for r in read_metrics(runs[0])] == [
        (0.3333333, 0.25)
    ] * len(single)
    kept = [json.loads(line) for line in read_record(runs[1] / "metrics.jsonl").splitlines()]
    assert all(line["mae"] == 0.5 for line in kept)  # several positions: the scalar stays


def test_rounding_reaches_the_numbers_inside_lists_and_dicts():
    from parallax.tools.report.compact import rounded

    value = {"a": [1 / 3, {"b": 2 / 3}], "n": 7, "flag": True, "name": "x", "none": None}
    assert rounded(value) == {
        "a": [0.3333333, {"b": 0.6666667}],
        "n": 7,
        "flag": True,
        "name": "x",
        "none": None,
    }


def test_keep_names_what_it_may_keep(tmp_path, capsys):
    with pytest.raises(
        ValueError, match="keep must be one of all, replay, reports, distance, got 'some'"
    ):
        compact([tmp_path], keep="some")
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path), "--keep", "some"])
    assert exc.value.code == 2
    assert "invalid choice: 'some'" in capsys.readouterr().err
