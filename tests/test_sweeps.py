"""Sweeps with Hydra's launchers: joblib, submitit_local (with a requeue), the SLURM config and
the launch scripts.

The sweeps run the real `parallax-train -m` on the shrunken TINY config. Its overrides would make
a run-directory name longer than a file name may be, so they are left out of the name with
`override_dirname.exclude_keys` (as `train.threads` & co. are in conf/config.yaml): the job
directories are then named by the swept settings alone, e.g. `seed=0`.
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from parallax.config import CONFIG_MODULE, CONFIG_NAME, compose, register_resolvers
from parallax.tools.evaluate import build_parser
from parallax.trainer import Trainer

REPO = Path(__file__).resolve().parents[1]
LAUNCH_SCRIPTS = sorted(
    p.name for p in (REPO / "launch").glob("ablation_*.sh") if p.name != "ablation_lib.sh"
) + ["reproduce.sh"]


def _name_without(overrides: list[str]) -> str:
    keys = ["resume", "device", "train.threads", "train.checkpoint_every", "train.image_every"]
    keys += [o.split("=", 1)[0] for o in overrides]
    return "hydra.job.config.override_dirname.exclude_keys=[" + ",".join(dict.fromkeys(keys)) + "]"


def _sweep(
    sweep_dir: str, overrides: list[str], launcher: list[str], cwd: Path
) -> subprocess.Popen:
    cmd = [
        sys.executable,
        "-m",
        "parallax.train",
        "-m",
        *overrides,
        "seed=0,1",
        *launcher,
        f"hydra.sweep.dir={sweep_dir}",
        _name_without(overrides),
    ]
    return subprocess.Popen(
        cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


def _summaries(sweep_dir: Path) -> dict[str, dict]:
    return {
        p.parent.name: json.loads(p.read_text()) for p in sorted(sweep_dir.glob("*/summary.json"))
    }


def _reference_metrics(overrides: list[str], run_dir: Path) -> str:
    trainer = Trainer(compose(overrides), run_dir)
    try:
        trainer.fit()
    finally:
        trainer.exp.close()
    return (run_dir / "metrics.jsonl").read_text()


# --- launchers -----------------------------------------------------------------------------


def _hydra_config(overrides: list[str]):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    register_resolvers()
    GlobalHydra.instance().clear()
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        return hydra_compose(config_name=CONFIG_NAME, overrides=overrides, return_hydra_config=True)


def test_slurm_launcher_config_and_a_local_site_file_make_the_sbatch_script(tmp_path, monkeypatch):
    """hydra/launcher=slurm composes; the real launcher hands its settings to submitit, which
    accepts them and writes them into the sbatch header (no cluster needed: srun is faked, and
    the array is captured instead of submitted)."""
    import submitit
    from hydra.core.hydra_config import HydraConfig
    from hydra.utils import instantiate

    site = tmp_path / "site" / "hydra" / "launcher"
    site.mkdir(parents=True)
    (site / "local_test.yaml").write_text(
        "defaults:\n  - slurm\n  - _self_\npartition: cpu_test\naccount: proj\n"
    )
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    (fake_bin / "srun").write_text("#!/bin/sh\nexit 1\n")
    (fake_bin / "srun").chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake_bin}{os.pathsep}{os.environ['PATH']}")

    plain = _hydra_config(["hydra/launcher=slurm", f"hydra.sweep.dir={tmp_path / 'sweep'}"])
    assert plain.hydra.launcher._target_.endswith("SlurmLauncher")
    assert plain.hydra.launcher.cpus_per_task == 1 and plain.hydra.launcher.partition is None

    cfg = _hydra_config(
        [
            f"hydra.searchpath=[file://{tmp_path / 'site'}]",
            "hydra/launcher=local_test",
            f"hydra.sweep.dir={tmp_path / 'sweep'}",
        ]
    )
    HydraConfig.instance().set_config(cfg)
    launcher = instantiate(cfg.hydra.launcher)
    launcher.config = cfg
    captured = {}

    def capture_array(executor, function, *arguments):
        captured["executor"], captured["jobs"] = executor, len(arguments[0])
        return []

    monkeypatch.setattr(submitit.AutoExecutor, "map_array", capture_array)
    launcher.launch([["seed=0"], ["seed=1"]], initial_job_idx=0)
    slurm = captured["executor"]._executor
    assert captured["jobs"] == 2 and slurm.max_num_timeout == 5
    sbatch = slurm._make_submission_file_text("python -m submitit.core._submit x", "uid")
    for line in (
        "--partition=cpu_test",
        "--account=proj",
        "--cpus-per-task=1",
        "--mem=4GB",
        "--time=240",
        "--signal=USR2@120",
    ):
        assert f"#SBATCH {line}" in sbatch
    assert str(tmp_path / "sweep" / ".submitit") in sbatch


# --- sweeps ----------------------------------------------------------------------------------


def test_joblib_sweep_runs_two_jobs(tmp_path, tiny_overrides):
    sweep_dir = tmp_path / "sweep"
    proc = _sweep(
        str(sweep_dir),
        tiny_overrides,
        ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"],
        tmp_path,
    )
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out[-3000:]
    summaries = _summaries(sweep_dir)
    assert sorted(summaries) == ["seed=0", "seed=1"]
    assert [summaries[k]["seed"] for k in ("seed=0", "seed=1")] == [0, 1]
    assert all(s["presentations"] == 6 for s in summaries.values())
    assert summaries["seed=0"]["mae_per_position"] != summaries["seed=1"]["mae_per_position"]
    # each job's lines carry its run's name; its train.log has them as the terminal had
    for name in ("seed=0", "seed=1"):
        assert f"[{name}] [parallax] presentation 6/6 " in out
        log = (sweep_dir / name / "train.log").read_text()
        assert "[parallax] presentation 6/6 " in log and f"[{name}]" not in log
        assert "parallax — the schema's defaults (no experiment), curriculum" in log
    # and the sweep sums up at its end
    tail = out.rstrip().splitlines()[-3:]
    assert tail[0] == f"[sweep] {sweep_dir}: 2 jobs, 2 finished, 0 not"
    assert tail[1].startswith("[sweep]   seed=0: 6 presentations, MAE ")


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


@pytest.mark.slow
@pytest.mark.skipif(
    not Path("/proc/self/stat").exists(), reason="finds the submitit task through /proc"
)
def test_submitit_local_sweep_survives_a_requeue(tmp_path, tiny_overrides):
    """Two jobs with submitit_local; job seed=0 is preempted (USR2, as SLURM does) half-way.
    submitit requeues it with the sweep directory already resolved — the `${now:…}` in its name
    is not evaluated again — and the trainer resumes from the checkpoint: the requeued run's log
    equals an uninterrupted run's, and the sweep has one dated folder."""
    overrides = [
        o
        for o in tiny_overrides
        if not o.startswith(("train.presentations", "train.checkpoint_every"))
    ]
    overrides += ["train.presentations=16", "train.checkpoint_every=1"]
    root = tmp_path / "multirun"
    proc = _sweep(
        str(root) + "/${now:%H-%M-%S-%f}", overrides, ["hydra/launcher=submitit_local"], tmp_path
    )
    preempted = None
    deadline = time.time() + 300
    while proc.poll() is None and preempted is None and time.time() < deadline:
        metrics = list(root.glob("*/seed=0/metrics.jsonl"))
        if metrics and len(metrics[0].read_text().splitlines()) >= 4:
            for log in root.glob("*/.submitit/*/*_0_log.out"):
                if "seed=0" in log.read_text() and log.parent.name.isdigit():
                    tasks = _children(int(log.parent.name))
                    for task in tasks:
                        os.kill(task, signal.SIGUSR2)
                    preempted = log if tasks else None
        time.sleep(0.02)
    out, _ = proc.communicate(timeout=600)
    assert preempted is not None, "job seed=0 ended before it could be preempted; make it longer"
    assert proc.returncode == 0, out[-3000:]
    assert "Requeued job" in preempted.read_text()

    sweeps = [p for p in root.iterdir() if p.is_dir()]
    assert len(sweeps) == 1, sweeps
    summaries = _summaries(sweeps[0])
    assert sorted(summaries) == ["seed=0", "seed=1"] and summaries["seed=0"]["presentations"] == 16
    reference = _reference_metrics(overrides + ["seed=0"], tmp_path / "uninterrupted")
    assert (sweeps[0] / "seed=0" / "metrics.jsonl").read_text() == reference


# --- launch scripts ----------------------------------------------------------------------------


def _dry_run(script: str, tmp_path: Path, *args: str, **settings: str) -> list[str]:
    """The commands a launch script prints with PARALLAX_DRY_RUN=1, sweeping below tmp_path
    (``args``: its arguments; ``settings``: more of its environment variables)."""
    env = {
        **os.environ,
        "PARALLAX_DRY_RUN": "1",
        "SWEEP_ROOT": str(tmp_path),
        "RECORD_ROOT": str(tmp_path),
        **settings,
    }
    result = subprocess.run(
        ["bash", str(REPO / "launch" / script), *args],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout.splitlines()


@pytest.fixture(scope="module")
def reproduction_dry_run(tmp_path_factory) -> tuple[Path, list[str]]:
    """launch/reproduce.sh's commands with one extra override, printed once for the tests that
    read them (it composes every experiment file, tens of seconds)."""
    root = tmp_path_factory.mktemp("reproduce")
    # without the wall-time estimate, which composes every file again (tests/tools/test_bench.py)
    return root, _dry_run("reproduce.sh", root, "train.presentations=7", BENCH_REPORT="")


@pytest.mark.parametrize("script", LAUNCH_SCRIPTS)
def test_launch_scripts_parse_and_pass_extra_overrides(script, tmp_path, request):
    path = REPO / "launch" / script
    subprocess.run(["bash", "-n", str(path)], check=True)
    if script == "reproduce.sh":
        tmp_path, lines = request.getfixturevalue("reproduction_dry_run")
    else:
        lines = _dry_run(script, tmp_path, "train.presentations=7")
    sweeps = [l for l in lines if l.startswith("parallax-train -m ")]
    assert sweeps, lines
    for line in sweeps:
        assert "hydra/launcher=joblib" in line and "hydra.launcher.n_jobs=2" in line
        assert "seed=0\\,1\\,2" in line and line.rstrip().endswith("train.presentations=7")
        assert f"hydra.sweep.dir={tmp_path}/" in line
    report = [l for l in lines if l.startswith("parallax-report ")]
    # reproduce.sh: one report per family with the paper's tables, recipe, paper and unsourced
    # (its own test below)
    assert len(report) == (3 if script == "reproduce.sh" else 1)
    assert all("--out docs/results" in line for line in report)


def test_the_reproduction_trains_each_eye_once_and_replays_the_distance_only_files(
    reproduction_dry_run,
):
    _, lines = reproduction_dry_run
    trained = " ".join(l for l in lines if l.startswith("parallax-train -m "))
    replayed = [l for l in lines if l.startswith("parallax-replay ")]
    # the rows without weighting, and the recipe less a distance-side improvement, are replays
    for name in (
        "recipe_multi_5_20",
        "paper_multi_5_20",
        "unsourced_multi_5_20",
        "without_lm_weight_decay",
    ):
        assert f"experiment={name}\\," not in trained and f"\\,{name}\\," not in trained
        assert any(f"_replays/{name} " in l for l in replayed), name
    assert "without_reward_change" in trained and "recipe_multi_5_20_weighted" in trained
    # the replays' records keep their learner's keys only, the trained runs' what replays read
    compacted = [shlex.split(l) for l in lines if "parallax.tools.report.compact" in l]
    keeps = {words[-1]: words[words.index("--keep") + 1] for words in compacted}
    assert keeps and all(keeps[f] == "distance" for f in keeps if f.endswith("_replays"))
    assert {"replay", "distance"} <= set(keeps.values())
    # five seeds for the 5–20 cm headline rows, three elsewhere
    headline = [l for l in lines if l.startswith("parallax-train -m ") and "0\\,1\\,2\\,3\\,4" in l]
    assert len(headline) == 3 and all("multi_5_20_weighted seed=" in l for l in headline)
    # a family's <family>_algorithm.yaml is the settings its files include, not an experiment
    assert "_algorithm" not in trained
    evals = [l for l in lines if l.startswith("parallax-eval ")]
    assert evals and all("--robots 16" in l for l in evals)
    # every printed eval is a command line that parallax-eval's own parser takes
    parsed = [build_parser().parse_intermixed_args(shlex.split(l)[1:]) for l in evals]
    settings = [s for args in parsed for s in args.stimuli]
    assert "env.stimuli.source=procedural" in settings
    assert any(s.startswith("env.stimuli.dir=") for s in settings)
    assert all(args.robots == 16 for args in parsed)
    # greedy on held-out textures, but the paper's probable scoring: the eye as trained (its
    # learning policy on the training photographs), before and after, multi-position models only
    trained_eye = [
        (line, args) for line, args in zip(evals, parsed, strict=True) if not args.greedy_only
    ]
    assert trained_eye and all(a.split == "train" and a.stimuli == [] for _, a in trained_eye)
    assert all("/eval_trained" in l or "/eval_before_trained" in l for l, _ in trained_eye)
    assert not any("single" in l or "without" in l for l, _ in trained_eye)
    assert all(a.split == "heldout" for a in parsed if a.greedy_only)
    # the three-column comparison, then the claims read from the same records
    compare = [l for l in lines if l.startswith("python -m parallax.tools.report.compare ")]
    assert len(compare) == 1 and lines[-1].startswith("python -m parallax.tools.report.claims ")
    # the middle column is the paper family's, its open settings from its lineage
    assert "/paper.json " in compare[0] and "--middle paper" in compare[0]
    assert any(l.startswith("python -m parallax.tools.report.leave_one_out ") for l in lines)


def test_the_reproduction_does_not_train_a_finished_run_again(tmp_path):
    """A run with a summary.json is a record (committed without its checkpoint): only the seeds
    without one are trained, and a record made with other overrides does not count."""
    for folder, overrides in {
        "done": ["experiment=recipe_multi_5_20_weighted", "seed=3"],
        "smoke": ["experiment=recipe_multi_5_20_weighted", "seed=4", "train.presentations=7"],
        "unfinished": ["experiment=recipe_multi_5_20_weighted", "seed=0"],
    }.items():
        (tmp_path / "recipe" / folder / ".hydra").mkdir(parents=True)
        (tmp_path / "recipe" / folder / ".hydra" / "overrides.yaml").write_text(
            "".join(f"- {o}\n" for o in overrides)
        )
    for folder, seed in (("done", 3), ("smoke", 4)):
        (tmp_path / "recipe" / folder / "summary.json").write_text("{}")
        (tmp_path / "recipe" / folder / "config.yaml").write_text(f"seed: {seed}\n")
        (tmp_path / "recipe" / folder / "checkpoint.pt").write_bytes(b"")
    # the dry run also estimates the family's wall time from a bench report's process cases
    report = tmp_path / "bench.json"
    two = {"processes": 2, "steps_per_second": 400.0}
    report.write_text(json.dumps({"processes": {"this code": {"two": two}}}))
    lines = _dry_run(
        "reproduce.sh", tmp_path, "recipe", BENCH_REPORT=str(report), HEADLINE_SEEDS="3,0,1,2,4"
    )
    # the first headline seed's model is committed, no other's
    kept = [l for l in lines if l.startswith("cp ")]
    assert len(kept) == 1 and f"{tmp_path}/recipe/done/checkpoint.pt" in kept[0], kept
    assert kept[0].rstrip().endswith("checkpoints/recipe_multi_5_20_weighted_seed3/")
    trained = [l for l in lines if "parallax-train" in l]
    headline = [l for l in trained if "experiment=recipe_multi_5_20_weighted " in l]
    assert len(headline) == 1 and headline[0].rstrip().endswith("seed=0\\,1\\,2\\,4"), trained
    assert len(trained) == 2  # the other recipe files, all three seeds
    assert any(l.startswith("recipe: ") and "robot-iterations" in l for l in lines), lines
    assert any("400.0 robot-iterations/s in all" in l and l.endswith("hours") for l in lines)


def test_experiments_keeps_a_family_to_the_files_it_names(tmp_path):
    """EXPERIMENTS: the 5–20 cm rows of the paper family alone, trained, evaluated and replayed;
    no single-position file is trained. A name of no file of the family is refused."""
    lines = _dry_run(
        "reproduce.sh",
        tmp_path,
        "paper",
        BENCH_REPORT="",
        EXPERIMENTS="paper_multi_5_20_weighted,paper_multi_5_20",
    )
    trained = [line for line in lines if "parallax-train" in line]
    assert len(trained) == 1 and "experiment=paper_multi_5_20_weighted " in trained[0], trained
    assert any(l.startswith("parallax-replay") and "paper_multi_5_20 " in l for l in lines)
    assert not any("paper_multi_5_10" in l or "paper_single" in l for l in trained)
    assert not any("paper_multi_5_10" in l for l in lines if l.startswith("parallax-eval"))
    env = {**os.environ, "PARALLAX_DRY_RUN": "1", "RECORD_ROOT": str(tmp_path)}
    env.update(SWEEP_ROOT=str(tmp_path), BENCH_REPORT="", EXPERIMENTS="recipe_single_5")
    result = subprocess.run(
        ["bash", str(REPO / "launch" / "reproduce.sh"), "paper"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and "among EXPERIMENTS=recipe_single_5" in result.stderr


@pytest.mark.slow
def test_a_bad_job_fails_alone_in_a_joblib_sweep(tmp_path, tiny_overrides):
    """One job with an invalid value must not take the launcher's other jobs down with it."""
    sweep_dir = tmp_path / "sweep"
    overrides = [o for o in tiny_overrides if not o.startswith("distance.queue_size")]
    cmd = [
        sys.executable,
        "-m",
        "parallax.train",
        "-m",
        *overrides,
        "distance.queue_size=3,0",
        "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=2",
        f"hydra.sweep.dir={sweep_dir}",
        _name_without(overrides),
    ]
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert proc.returncode != 0  # the sweep reports the failure …
    assert "distance.queue_size" in proc.stdout + proc.stderr
    summaries = _summaries(sweep_dir)  # … but the valid job ran to its end
    assert list(summaries) == ["distance.queue_size=3"]
    assert summaries["distance.queue_size=3"]["presentations"] == 6
    assert f"[sweep] {sweep_dir}: 2 jobs, 1 finished, 1 not" in proc.stdout
    assert "[sweep]   distance.queue_size=0: failed before training started" in proc.stdout


@pytest.mark.parametrize("script", ["ablation_y.sh", "ablation_queue.sh"])
def test_distance_ablations_replay_their_source_runs(script, tmp_path):
    """y and c only change the distance learner: the scripts replay logged eye movements."""
    trained = _dry_run(script, tmp_path)
    replays = [l for l in trained if l.startswith("parallax-replay ")]
    assert replays and all(f"{tmp_path}/ablation_distance_source --out" in l for l in replays), (
        trained
    )
    assert all("--until-perturbation" in l for l in replays)
    assert all(
        "--rescore eval_before_textures5 --rescore eval_before_trained" in l for l in replays
    )
    # scored on five held-out photographs per grid distance by the source's model before its
    # perturbation
    (scoring,) = [l for l in trained if l.startswith("parallax-eval ")]
    assert "--checkpoint checkpoint_before_perturbation.pt" in scoring and "--textures 5" in scoring
    assert trained.index(scoring) < trained.index(replays[0])
    # the replays are records, committed with their learner's keys only
    assert all(f"--out {tmp_path}/ablation_" in l for l in replays)
    compacted = [l for l in trained if "parallax.tools.report.compact" in l]
    assert compacted == [f"python -m parallax.tools.report.compact --keep distance {tmp_path}/"
                         f"ablation_{script.split('_')[1].split('.')[0]} "]  # fmt: skip
    (tmp_path / "runs" / "a").mkdir(parents=True)
    (tmp_path / "runs" / "b").mkdir()
    (tmp_path / "runs" / "a" / "config.yaml").write_text("distance:\n  queue_size: 100\n")
    lines = _dry_run(script, tmp_path, SOURCE=f"{tmp_path}/runs/*")
    assert not [l for l in lines if l.startswith("parallax-train")], lines
    assert all(
        f"{tmp_path}/runs/a {tmp_path}/runs/b --out" in l
        for l in lines
        if l.startswith("parallax-replay")
    )
    if script == "ablation_queue.sh":  # each c against the c the source runs were trained with
        (paired,) = [shlex.split(l) for l in lines if "paired_ablation" in l]
        assert paired[paired.index("--baseline") + 1] == "100"


def test_a_model_is_evaluated_again_only_when_its_checkpoint_is_newer_than_its_eval(tmp_path):
    """The evaluations' choice: a compacted eval.json counts as the plain one, and a committed
    model (its date is the checkout's) is evaluated only where its evaluation is missing."""
    run, committed = tmp_path / "run", tmp_path / "checkpoints" / "a_seed0"
    (run / "eval_before").mkdir(parents=True)
    committed.mkdir(parents=True)

    def needs(model: Path, checkpoint: str, out: Path) -> bool:
        command = f"source {REPO}/launch/ablation_lib.sh; px_needs_eval {model} {checkpoint} {out}"
        env = {**os.environ, "PARALLAX_DRY_RUN": "1"}
        return subprocess.run(["bash", "-c", command], env=env).returncode == 0

    assert not needs(run, "checkpoint.pt", run)  # no model
    (run / "checkpoint.pt").write_bytes(b"")
    assert needs(run, "checkpoint.pt", run)  # no eval
    (run / "eval.json.xz").write_bytes(b"")
    os.utime(run / "checkpoint.pt", (1_000_000_000, 1_000_000_000))
    assert not needs(run, "checkpoint.pt", run)  # evaluated, compacted
    os.utime(run / "checkpoint.pt", (2_000_000_000, 2_000_000_000))
    assert needs(run, "checkpoint.pt", run)  # trained further since
    assert needs(run, "checkpoint.pt", run / "eval_before")
    (committed / "checkpoint.pt").write_bytes(b"")  # newer than the run's eval, but committed
    assert not needs(committed, "checkpoint.pt", run)
    assert needs(committed, "checkpoint.pt", run / "eval_before")


def test_the_distance_ablations_score_each_source_with_its_own_or_its_committed_model(tmp_path):
    runs, committed = tmp_path / "runs", tmp_path / "report" / "checkpoints"
    for name in ("experiment=a,seed=3", "experiment=b,seed=1", "experiment=c,seed=0", "d"):
        (runs / name / ".hydra").mkdir(parents=True)
        (runs / name / "summary.json").write_text("{}")
        if name != "d":  # a committed model is found from the run's launch settings
            experiment, seed = (part.split("=")[1] for part in name.split(","))
            (runs / name / ".hydra" / "overrides.yaml").write_text(f"- experiment={experiment}\n")
            (runs / name / "config.yaml").write_text(f"seed: {seed}\n")
    (committed / "a_seed3").mkdir(parents=True)  # a's model only among the committed ones
    (committed / "a_seed3" / "checkpoint_before_perturbation.pt").write_bytes(b"")
    for name in ("experiment=b,seed=1", "experiment=c,seed=0"):  # models of their own
        (runs / name / "checkpoint_before_perturbation.pt").write_bytes(b"")
    scored = runs / "experiment=c,seed=0" / "eval_before_textures5"
    scored.mkdir()
    (scored / "eval.json.xz").write_bytes(b"")  # c is scored already (newer than its model)
    os.utime(runs / "experiment=c,seed=0" / "checkpoint_before_perturbation.pt", (1, 1))
    command = (
        f'source {REPO}/launch/ablation_lib.sh; parallax-eval() {{ echo "EVAL $1 $*"; }}; '
        f"distance_sources=({runs}); px_score_sources"
    )
    env = {**os.environ, "REPORT_ROOT": str(tmp_path / "report")}
    env.pop("PARALLAX_DRY_RUN", None)
    result = subprocess.run(["bash", "-c", command], env=env, capture_output=True, text=True)
    evals = sorted(l.split()[1] for l in result.stdout.splitlines() if l.startswith("EVAL "))
    assert evals == [str(committed / "a_seed3"), str(runs / "experiment=b,seed=1")]
    # d has no model anywhere and no scoring: said, and the status says it failed
    assert result.returncode == 1 and f"{runs / 'd'}: no model before its perturbation" in (
        result.stderr
    )


def test_the_ablations_script_trains_scales_and_replays_the_reproduction(tmp_path):
    lines = _dry_run("ablations.sh", tmp_path)
    trained = [l for l in lines if l.startswith("parallax-train -m ")]
    # each family at its own budget: no run length imposed
    assert len(trained) == 1 and "coder=coarse\\,fine " in trained[0]
    assert "experiment=paper_multi_5_10\\,recipe_multi_5_20_weighted" in trained[0]
    assert "train.presentations" not in trained[0]
    # y (weighted at each y, and unweighted) and c, on each family's 5–20 cm weighted runs
    replays = [l for l in lines if l.startswith("parallax-replay ")]
    assert len(replays) == 6
    assert sum(f"{tmp_path}/paper/" in l for l in replays) == 3
    assert sum(f"{tmp_path}/recipe/" in l for l in replays) == 3
    assert all("distance.y=0.25\\,0.5\\,1\\,2\\,4" in l for l in replays if "y=" in l)
    assert len([l for l in lines if l.startswith("parallax-report ")]) == 5
    # every setting against its baseline, paired: both scales, no weighting, the runs' own c
    paired = [l for l in lines if "parallax.tools.report.paired_ablation" in l]
    baselines = sorted(shlex.split(l)[shlex.split(l).index("--baseline") + 1] for l in paired)
    assert baselines == sorted(
        ['["coarse", "fine"]'] * 2
        + ["<distance.queue_size of the source runs>"] * 2
        + ["distance.weighting=false, distance.y=1.0"] * 2
    )
    assert lines[-1] == "python -m parallax.tools.report.ablations docs/results "


def test_the_fovea_study_trains_both_set_ups_and_pairs_them_with_the_familys_runs(tmp_path):
    lines = _dry_run("fovea_study.sh", tmp_path, "train.presentations=7")
    (trained,) = [l for l in lines if l.startswith("parallax-train -m ")]
    assert "experiment=paper_single_5\\,paper_multi_5_10 env.fovea_px=150 " in trained
    assert f"hydra.sweep.dir={tmp_path}/fovea " in trained
    assert "seed=0\\,1\\,2" in trained and trained.rstrip().endswith("train.presentations=7")
    paired = [shlex.split(l) for l in lines if "parallax.tools.report.paired_ablation" in l]
    assert [p[p.index("--factor") + 1 : p.index("--factor") + 4] for p in paired] == [
        ["env.fovea_px", "--baseline", "null"]
    ] * 2
    assert [p[3:5] for p in paired] == [
        [f"{tmp_path}/fovea/<runs of {name}>", f"{tmp_path}/paper/<runs of {name}>"]
        for name in ("paper_single_5", "paper_multi_5_10")
    ]


def test_the_sensitivity_study_switches_one_setting_per_sweep(tmp_path):
    lines = _dry_run("sensitivity.sh", tmp_path, "train.presentations=7")
    sweeps = [l for l in lines if l.startswith("parallax-train -m ")]
    switches = [
        next(
            (
                w
                for w in l.split()
                if w.startswith(("+open_setting=", "step_sizes=", "dictionary_rate="))
            ),
            None,
        )
        for l in sweeps
    ]
    assert switches == [
        None,
        "+open_setting=xi_1",
        "+open_setting=projection",
        "+open_setting=normalised_features",
        "+open_setting=reset_step_learnt",
        "+open_setting=pan_kept",
        "step_sizes=origin",
        "step_sizes=chong",
        "step_sizes=lukas",
        "dictionary_rate=origin",
        "dictionary_rate=lukas",
        "dictionary_rate=alex_p",
    ]
    for line in sweeps:
        both = "sensitivity_single_5\\,sensitivity_multi_5_10"
        one_position = "reset_step_learnt" in line or "pan_kept" in line
        setups = "sensitivity_multi_5_10" if one_position else both
        assert f"experiment={setups} " in line
        assert "seed=0\\,1\\,2" in line and line.rstrip().endswith("train.presentations=7")
    replays = [l for l in lines if l.startswith("parallax-replay ")]
    assert [r.rstrip().split("--out ")[1].split(" ", 1)[1] for r in replays] == [
        "open_setting=plain_lm\\,matlab_network",
        "distance.warm_start=false",
        "distance.input_scaling=none distance.warm_start=true\\,false",
    ]
    replay = replays[0]
    # the records as committed: the switches' thinned to what the table reads, the lineage's
    # keeping the eye-movement vectors that its replays (just after) read, the replays' their
    # distance learner's (after the last replay)
    compacted = [l for l in lines if "parallax.tools.report.compact" in l]
    assert [l.split()[3:5] for l in compacted] == [
        ["--keep", "reports"],
        ["--keep", "replay"],
        ["--keep", "distance"],
    ]
    assert "switch" in compacted[0] and "lineage" in compacted[1]
    assert lines.index(compacted[1]) < lines.index(replay)
    assert compacted[2].rstrip().endswith("sensitivity_replays")
    assert lines.index(compacted[2]) > max(lines.index(r) for r in replays)
    (table,) = [l for l in lines if "parallax.tools.analysis.sensitivity" in l]
    assert "--override=train.presentations=7" in table


def test_the_continuous_script_trains_the_seeds_the_pairing_and_the_speed_curve(tmp_path):
    from parallax.envs.sweep import fastest_followable_speed_m, sweep_iterations

    lines = _dry_run("continuous.sh", tmp_path, "train.threads=1")
    trained = [l for l in lines if l.startswith("parallax-train")]
    assert (
        "seed=0\\,1\\,2" in trained[0] and "experiment=continuous_multi_5_20_weighted" in trained[0]
    )
    assert "coder.pairing=consecutive" in trained[1]
    speeds = [shlex.split(l) for l in trained[2:]]
    fastest = fastest_followable_speed_m(0.2, "constant", 3.0)
    for words in speeds:
        speed = float(next(w for w in words if w.startswith("env.sweep.speed_m="))[18:])
        runs = int(next(w for w in words if w.startswith("train.presentations="))[20:])
        # every run of the curve is as long as the experiment's own, and followable at 3 m
        assert abs(runs * sweep_iterations(0.2, speed) - 640 * 101) < 101
        assert speed <= fastest
    assert all(l.rstrip().endswith("train.threads=1") for l in trained)
    (report,) = [l for l in lines if "parallax.tools.report.continuous" in l]
    assert "--markdown" in report
