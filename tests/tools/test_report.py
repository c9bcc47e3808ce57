"""`parallax-report`: grouping over seeds, failed jobs, the paper's Tables 2–5, ablation tables.

Most tests write run directories the way the trainer does (the real composed config as
config.yaml, summary.json in `Trainer.summary`'s format) with random numbers, and check the
report's numbers against statistics computed here from those files. One test reads real (tiny)
training runs end to end.
"""

from __future__ import annotations

import json
import re
import shutil
import statistics
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from parallax.config import compose
from parallax.metrics import position_label
from parallax.tools.report import paper_results as paper
from parallax.tools.report.build import build_report
from parallax.tools.report.cli import main
from parallax.tools.report.groups import mean_sd
from parallax.tools.report.tables import weighting_verdict

RANGES = paper.DISTANCE_RANGES


def _phase(rng: np.random.Generator, labels: list[str], presentations: int) -> dict:
    mae_per_position = {k: float(rng.uniform(0.05, 0.6)) for k in labels}
    return {
        "presentations": presentations,
        "trials": presentations * len(labels),
        "mae": float(np.mean(list(mae_per_position.values()))),
        "mae_per_position": mae_per_position,
        "last_trials": {
            k: {
                "mean": float(rng.uniform(0.05, 0.6)),
                "var": float(rng.uniform(0.01, 0.2)),
                "trials": 100,
            }
            for k in labels
        },
        "distance_error": {r: float(rng.uniform(0.5, 8.0)) for r in RANGES},
    }


def write_run(run_dir: Path, cfg, seed: int, rng: np.random.Generator) -> dict:
    """A finished run directory in the trainer's format; returns its summary."""
    cfg = cfg.copy()
    cfg.seed = seed
    run_dir.mkdir(parents=True)
    (run_dir / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    labels = [position_label(l) for l in cfg.curriculum.lateral_positions]
    total = int(cfg.train.presentations)
    start = cfg.perturbation.start_fraction
    switch = None if start is None else int(round(float(start) * total))
    summary = {
        "curriculum": cfg.curriculum.name,
        "lateral_positions_cm": labels,
        "seed": seed,
        "robots": 1,
        "steps": total * len(labels) * 30,
        **_phase(rng, labels, total),
        "before_perturbation": None if switch is None else _phase(rng, labels, switch),
        "timing": {"wall_time_s": float(rng.uniform(10, 20)), "steps_per_second": 100.0},
    }
    (run_dir / "summary.json").write_text(json.dumps(summary))
    with (run_dir / "metrics.jsonl").open("w") as log:
        for p in range(1, total + 1):
            record = {
                "presentation": p,
                "steps": p * len(labels) * 30,
                "perturbed": switch is not None and p >= switch,
                "mae": float(rng.uniform(0.1, 1.0)),
                "mae_per_position": {k: float(rng.uniform(0.1, 1.0)) for k in labels},
            }
            log.write(json.dumps(record) + "\n")
    return summary


def write_eval(
    run_dir: Path,
    rng: np.random.Generator,
    presentations: int,
    perturbed: bool,
    sub: str | None = None,
) -> dict:
    distances = [3.0, 4.0, 5.5, 7.0, 9.9]
    per_distance = {f"{d:.2f}": float(rng.uniform(0.5, 6)) for d in distances}
    result = {
        "presentations": presentations,
        "perturbed": perturbed,
        "mae": {"greedy": float(rng.uniform(0.1, 0.3)), "sampled": float(rng.uniform(0.2, 0.4))},
        "distance": {
            "by_range": {r: float(rng.uniform(0.5, 6)) for r in RANGES},
            "per_distance": per_distance,
        },
        "distance_between_grid": {
            "by_range": {r: float(rng.uniform(0.5, 6)) for r in RANGES},
            "per_distance": {"3.05": 2.0, "7.33": 3.0},
        },
    }
    out = run_dir / sub if sub else run_dir
    out.mkdir(exist_ok=True)
    (out / "eval.json").write_text(json.dumps(result))
    return result


def cell_text(values: list[float], digits: int = 2) -> str:
    return f"{statistics.fmean(values):.{digits}f} ± {statistics.stdev(values):.{digits}f}"


def table_block(markdown: str, heading: str) -> str:
    """The Markdown table that follows the caption starting with `heading`."""
    start = markdown.index(heading)
    lines = markdown[start:].splitlines()
    rows = [line for line in lines[1:] if line.startswith("|")]
    first = next(i for i, line in enumerate(lines) if line.startswith("|"))
    end = next((i for i in range(first, len(lines)) if not lines[i].startswith("|")), len(lines))
    return "\n".join(lines[first:end]) if rows else ""


def row_of(table: str, first_cell: str) -> list[str]:
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == first_cell:
            return cells
    raise AssertionError(f"no row {first_cell!r} in\n{table}")


@pytest.fixture(scope="module")
def paper_sweep(tmp_path_factory) -> dict:
    """All nine paper experiments × 3 seeds, as a multirun directory."""
    root = tmp_path_factory.mktemp("reproduce")
    rng = np.random.default_rng(7)
    summaries: dict[str, list[dict]] = {}
    evals: dict[str, list[tuple[dict, dict]]] = {}
    names = [f"paper_single_{l}" for l in paper.TABLE_POSITIONS_CM] + [
        "paper_multi_5_10",
        "paper_multi_5_20",
        "paper_multi_5_20_weighted",
    ]
    for name in names:
        cfg = compose([f"experiment={name}", "train.presentations=10"])
        for seed in range(3):
            run_dir = root / f"experiment={name},seed={seed}"
            summaries.setdefault(name, []).append(write_run(run_dir, cfg, seed, rng))
            if name == "paper_multi_5_20_weighted":  # evaluated before (checkpoint at 5) and after
                before = write_eval(run_dir, rng, 5, False, sub="eval_before")
                after = write_eval(run_dir, rng, 10, True)
                evals.setdefault(name, []).append((before, after))
    return {"root": root, "summaries": summaries, "evals": evals}


def test_paper_tables_put_ours_beside_the_published_numbers(paper_sweep, tmp_path):
    out = tmp_path / "report"
    markdown, results = build_report([paper_sweep["root"]], out, tables="paper")
    summaries = paper_sweep["summaries"]

    table2 = table_block(markdown, "**Table 2**")
    for position in paper.TABLE_POSITIONS_CM:
        row = row_of(table2, position)
        single = [
            s["before_perturbation"]["last_trials"][position]["mean"]
            for s in summaries[f"paper_single_{position}"]
        ]
        assert row[1].startswith(cell_text(single)) and "n=3" in row[1]
        theirs = paper.TABLE2[paper.SINGLE][position]
        assert row[2] == f"{theirs[0]:.2f} ({theirs[1]:.2f})"
        assert row[1].endswith("✓" if round(statistics.fmean(single), 2) <= theirs[0] else "✗")
    # 13 cm is not in the 5–10 cm list: the paper has "-" and so do we
    assert row_of(table2, "13")[3:5] == ["not run", "-"]
    # Mult. 5–20: weighted and unweighted groups both fit; the weighted (the paper's model) is shown
    mult = [
        s["before_perturbation"]["last_trials"]["15"]["mean"]
        for s in summaries["paper_multi_5_20_weighted"]
    ]
    assert row_of(table2, "15")[5].startswith(cell_text(mult))
    assert "5-20" in markdown and "not shown" in markdown

    table3 = table_block(markdown, "**Table 3**")
    after = [s["last_trials"]["20"]["mean"] for s in summaries["paper_single_20"]]
    assert row_of(table3, "20")[1].startswith(cell_text(after))
    assert row_of(table3, "20")[2] == "{:.2f} ({:.2f})".format(*paper.TABLE3[paper.SINGLE]["20"])

    # Table 4: the weighted 5–20 runs have an eval of their before-perturbation checkpoint, the
    # unweighted ones have none → every row shows the trainer's online errors (like with like),
    # and the table says so.
    table4 = table_block(markdown, "**Table 4**")
    weighted = row_of(table4, paper.WEIGHTING_5_20)
    weighted_online = [
        s["before_perturbation"]["distance_error"] for s in summaries["paper_multi_5_20_weighted"]
    ]
    for i, r in enumerate(RANGES):
        assert weighted[3 + i].startswith(cell_text([e[r] for e in weighted_online]))
        assert f"({paper.TABLE4[paper.WEIGHTING_5_20][r]:.2f})" in weighted[3 + i]
    assert "online" in weighted[-1]
    unweighted = row_of(table4, paper.NO_WEIGHTING_5_20)
    online = [
        s["before_perturbation"]["distance_error"]["total"] for s in summaries["paper_multi_5_20"]
    ]
    assert unweighted[6].startswith(cell_text(online)) and "online" in unweighted[-1]
    verdict = weighting_verdict(
        statistics.fmean([e["total"] for e in weighted_online]), statistics.fmean(online)
    )
    assert f"is {verdict} without weighting" in markdown

    # with the unweighted row out of the picture, the weighted row's evals are used
    only_weighted = tmp_path / "only_weighted"
    for run in paper_sweep["root"].iterdir():
        if "paper_multi_5_20_weighted" in run.name:
            shutil.copytree(run, only_weighted / run.name)
    alone, _ = build_report([only_weighted], tmp_path / "alone", tables="paper")
    before_evals = [
        b["distance"]["by_range"] for b, _ in paper_sweep["evals"]["paper_multi_5_20_weighted"]
    ]
    row = row_of(table_block(alone, "**Table 4**"), paper.WEIGHTING_5_20)
    assert row[3 + RANGES.index("total")].startswith(cell_text([e["total"] for e in before_evals]))
    assert "held-out" in row[-1]
    table5 = table_block(alone, "**Table 5**")
    after_evals = [
        a["distance"]["by_range"]["7-10"]
        for _, a in paper_sweep["evals"]["paper_multi_5_20_weighted"]
    ]
    assert row_of(table5, paper.WEIGHTING_5_20)[5].startswith(cell_text(after_evals))

    # the small JSON holds the same numbers, the figures exist
    saved = json.loads((out / "results.json").read_text())
    total = saved["paper"]["table4"]["rows"][paper.WEIGHTING_5_20]["ours"]["total"]
    assert total["n"] == 3 and total["mean"] == pytest.approx(
        statistics.fmean(e["total"] for e in weighted_online)
    )
    assert saved["paper"]["table2"]["cells"][paper.SINGLE]["5"]["paper"] == {
        "mean": 0.18,
        "var": 0.10,
    }
    assert (out / "README.md").read_text() == markdown
    for png in saved["figures"]:
        assert (out / png).stat().st_size > 1000
    assert {"distance_before.png", "distance_after.png"} <= set(saved["figures"])
    assert "## Held-out textures and distances between the grid points" in markdown


def test_prefer_decides_which_of_two_fitting_groups_fills_the_paper_tables(tmp_path, capsys):
    # two weighted 5–20 cm groups, the paper's y and another, three seeds each, with evals
    rng = np.random.default_rng(11)
    root = tmp_path / "runs"
    totals: dict[str, list[float]] = {}
    for y in ("1.0", "0.1"):
        cfg = compose(
            ["experiment=paper_multi_5_20_weighted", "train.presentations=10", f"distance.y={y}"]
        )
        for seed in range(3):
            run_dir = root / f"y={y},seed={seed}"
            write_run(run_dir, cfg, seed, rng)
            before = write_eval(run_dir, rng, 5, False, sub="eval_before")
            write_eval(run_dir, rng, 10, True)
            totals.setdefault(y, []).append(before["distance"]["by_range"]["total"])
    total_column = 3 + RANGES.index("total")
    for y in ("1.0", "0.1"):
        markdown, _ = build_report([root], None, tables="paper", prefer=[f"distance.y={y}"])
        row = row_of(table_block(markdown, "**Table 4**"), paper.WEIGHTING_5_20)
        assert row[total_column].startswith(cell_text(totals[y]))
        assert "the one with the most of the settings asked for (--prefer)" in markdown
    with pytest.raises(SystemExit) as exc:
        main([str(root), "--prefer", "distance.y=0.3"])
    assert exc.value.code == 2
    # found only once the runs are read: after the header that says which runs
    header, error = capsys.readouterr().err.strip().splitlines()[-2:]
    assert header.startswith("[parallax-report]   output: the Markdown only")
    assert error == (
        "parallax-report: error: --prefer distance.y=0.3: no group of runs has that setting"
    )
    with pytest.raises(SystemExit):
        main([str(root), "--prefer", "distance.y"])
    assert "expected KEY=VALUE" in capsys.readouterr().err


def test_ablation_tables_failed_jobs_and_duplicates(tmp_path):
    rng = np.random.default_rng(3)
    sweep, other_sweep = tmp_path / "multirun" / "y", tmp_path / "multirun" / "again"
    base = compose(["train.presentations=8"])
    distances: dict[tuple, list[float]] = {}
    maes: dict[tuple, list[float]] = {}
    for weighting, y in [(True, 0.5), (True, 1.0), (True, 2.0), (False, 1.0)]:
        cfg = base.copy()
        cfg.distance.weighting, cfg.distance.y = weighting, y
        for seed in (0, 1):
            summary = write_run(sweep / f"w={weighting},y={y},seed={seed}", cfg, seed, rng)
            distances.setdefault((weighting, y), []).append(summary["distance_error"]["total"])
            maes.setdefault((weighting, y), []).append(summary["last_trials"]["20"]["mean"])
    # the same job in another sweep (as the baseline of several ablations would be): counted once
    shutil.copytree(sweep / "w=True,y=0.5,seed=0", other_sweep / "w=True,y=0.5,seed=0")
    # a job killed during training and one that failed before the trainer started
    killed = sweep / "w=True,y=4.0,seed=0"
    shutil.copytree(sweep / "w=True,y=2.0,seed=1", killed)
    (killed / "summary.json").unlink()
    refused = sweep / "w=True,y=-1,seed=0"
    (refused / ".hydra").mkdir(parents=True)
    (refused / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(base))
    (refused / ".hydra" / "overrides.yaml").write_text("- distance.y=-1\n- seed=0\n")

    out = tmp_path / "docs"
    markdown, results = build_report(
        [sweep, other_sweep], out, name="ablations.md", tables="ablation"
    )

    y_table = table_block(markdown, "**Ablation: `distance.y`**")
    assert [row_of(y_table, v)[0] for v in ("0.5", "1.0 (baseline)", "2.0")]
    for y in (0.5, 1.0, 2.0):
        row = row_of(y_table, f"{y}" + (" (baseline)" if y == 1.0 else ""))
        assert row[2] == "2"
        header = [c.strip() for c in y_table.splitlines()[0].strip("|").split("|")]
        assert row[header.index("dist. total")] == cell_text(distances[(True, y)])
        assert row[header.index("last-100 20 cm")] == cell_text(maes[(True, y)], 3)
    assert "False" not in y_table  # the unweighted runs differ in another setting
    weighting_table = table_block(markdown, "**Ablation: `distance.weighting`**")
    assert len(weighting_table.splitlines()) == 2 + 2
    assert row_of(weighting_table, "False")[-1] == "online, training textures"

    failed = markdown[markdown.index("## Failed or unfinished jobs") :]
    assert "w=True,y=4.0,seed=0" in failed and "failed or unfinished" in failed
    assert "w=True,y=-1,seed=0" in failed and "distance.y=-1 seed=0" in failed
    assert "Duplicates left out" in markdown and "again" in markdown
    assert len(results["failed"]) == 2 and len(results["duplicates"]) == 1
    assert (out / "ablations.md").is_file() and (out / "ablations.json").is_file()
    assert (out / "ablations_ablation_distance.y.png").is_file()


def test_report_reads_real_training_runs(tmp_path, tiny_overrides):
    """Three tiny real runs (one lateral position, the perturbation half-way) and a killed one."""
    from parallax.trainer import Trainer

    sweep = tmp_path / "multirun"
    overrides = tiny_overrides + ["curriculum.lateral_positions=[0.05]", "perturbation=rotate_blur"]
    summaries = []
    for seed in range(3):
        trainer = Trainer(compose(overrides + [f"seed={seed}"]), sweep / f"seed={seed}")
        try:
            summaries.append(trainer.fit())
        finally:
            trainer.exp.close()
    killed = sweep / "seed=3"
    shutil.copytree(sweep / "seed=0", killed)
    (killed / "summary.json").unlink()

    markdown, results = build_report([sweep], tmp_path / "out")
    assert [g["n"] for g in results["groups"]] == [3]
    row = row_of(table_block(markdown, "**Table 2**"), "5")
    before = [s["before_perturbation"]["last_trials"]["5"]["mean"] for s in summaries]
    assert row[1].startswith(cell_text(before)) and row[2] == "0.18 (0.10)"
    after = [s["last_trials"]["5"]["mean"] for s in summaries]
    assert row_of(table_block(markdown, "**Table 3**"), "5")[1].startswith(cell_text(after))
    assert re.search(
        r"seed=3 \| failed or unfinished: no summary.json; 6 of 6 presentations logged", markdown
    )
    assert (tmp_path / "out" / "mae_g01.png").is_file()


def test_bad_paths_fail_with_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "nowhere")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "nowhere does not exist" in err
    (tmp_path / "empty" / "sub").mkdir(parents=True)
    with pytest.raises(SystemExit):
        main([str(tmp_path / "empty")])
    err = capsys.readouterr().err.strip()
    assert "empty is not a run or multirun directory" in err and err.count("\n") == 0


PAPER = Path(__file__).resolve().parents[3] / "shared" / "paper.md"


@pytest.mark.skipif(not PAPER.is_file(), reason="the paper's text is not beside the repository")
def test_paper_results_are_the_papers_tables():
    """parallax/tools/report/paper_results.py against the tables of ../shared/paper.md, cell by
    cell."""
    text = PAPER.read_text()

    def lines_after(title: str) -> list[str]:
        start = text.index(title)
        return text[start : start + 1000].splitlines()

    for title, table in (
        ("Table 2: Performance", paper.TABLE2),
        ("Table 3: Performance", paper.TABLE3),
    ):
        lines = lines_after(title)
        for position in paper.TABLE_POSITIONS_CM:
            cells = next(l for l in lines if l.split("\t")[0] == position).split("\t")[1:]
            for column, cell in zip(paper.EYE_MOVEMENT_COLUMNS, cells):
                found = re.fullmatch(r"([\d.]+) \(([\d.]+)\)", cell.strip())
                assert (None if found is None else (float(found[1]), float(found[2]))) == table[
                    column
                ][position]
    for title, table in (("Table 4: Average", paper.TABLE4), ("Table 5: Average", paper.TABLE5)):
        lines = lines_after(title)
        for row, published in table.items():
            line = next(l for l in lines if l.startswith(row))
            assert [float(x) for x in re.findall(r"([\d.]+)%", line)] == [
                published[r] for r in RANGES
            ]


def test_the_weighting_verdict_reads_the_totals_as_printed():
    assert weighting_verdict(1.881, 1.62) == "not better than"
    assert weighting_verdict(1.5, 1.62) == "better than"
    # equal at the two decimals printed (the weighting undone by the network's input scaling)
    assert weighting_verdict(12.7200000001, 12.72) == "the same as"


def test_mean_sd_keeps_one_runs_columns_aligned_and_marks_no_runs():
    assert mean_sd([1.0, 3.0]) == "2.00 ± 1.41"
    assert mean_sd([0.25], 3) == "0.250 ± 0.000"
    assert mean_sd([]) == "—"
