"""parallax-bench runs end to end and reports every part; it asserts no speed (shared machine)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
import torch

from parallax.config import compose
from parallax.tools.bench import cli as bench


def test_coder_work_counts_the_paper_patches():
    cfg = compose()
    both = bench.coder_work_per_frame(cfg)
    coarse = bench.coder_work_per_frame(compose(["coder.scales=[coarse]"]))
    fine = bench.coder_work_per_frame(compose(["coder.scales=[fine]"]))
    assert both["flops"] == coarse["flops"] + fine["flops"]
    N, K, k = 288, 200, 10
    # 529 coarse patches (23×23 after ×8), 289 fine ones (17×17 after ×2)
    assert (
        coarse["flops"]
        == 2 * 529 * K * N + 2 * N * N * K + 2 * k * 529 * N + 4 * 529 * k * K + 2 * 529 * k
    )
    assert fine["flops"] < coarse["flops"]
    # the Gram matrix is made once per lockstep: 16 robots cost less than 16 single frames
    assert coarse["shared_flops"] == 2 * N * N * K
    limits = {"matmul_gflops": 100.0, "copy_gbps": 1e6}  # compute-bound
    one, sixteen = bench.coder_bound_ms(both, limits, 1), bench.coder_bound_ms(both, limits, 16)
    assert one == pytest.approx(both["flops"] / 1e8)
    assert sixteen == pytest.approx(
        (16 * (both["flops"] - both["shared_flops"]) + both["shared_flops"]) / 1e8
    )
    assert sixteen < 16 * one


def test_ceiling_is_every_core_busy_with_the_coder_at_its_bound():
    # one robot: 1 ms of render and a 2 ms coder bound on 2 cores → 2 / 3 ms
    assert bench.ceiling_steps_per_second(1.0, 2.0, robots=1, cores=2) == pytest.approx(2000 / 3)
    # 16 robots share one coder bound for the lockstep; twice the cores, twice the ceiling
    sixteen = bench.ceiling_steps_per_second(1.0, 20.0, robots=16, cores=2)
    assert sixteen == pytest.approx(2 * 16 / 36 * 1e3)
    assert bench.ceiling_steps_per_second(1.0, 20.0, robots=16, cores=4) == pytest.approx(
        2 * sixteen
    )
    assert bench.usable_cores() >= 1


def test_bench_main_prints_a_table_and_json(tmp_path, capsys, tiny_overrides):
    out = tmp_path / "bench.json"
    # the shrunken world, coder and learner: this test reads the report's shape, not its speed
    shrunken = [o for o in tiny_overrides if o.startswith(("env.", "coder.", "distance."))]
    # trials long enough that the threads' clocks, in whole ticks, can tell their sum apart
    shrunken.append("env.trial_length=20")
    bench.main(
        ["--no-components", "--robots", "1", "2", "1", "--presentations", "1", "--json", str(out)]
        + shrunken
    )
    printed = capsys.readouterr().out
    assert "[end to end]" in printed and "[roofline cpu]" in printed
    report = json.loads(out.read_text())
    # which machine, and under what load: rates differ several-fold between CPUs
    found = report["machine"]
    assert found["cores"] == os.cpu_count() and found["load_average_before"] >= 0
    assert found["vector_capability"] == torch.backends.cpu.get_cpu_capability()
    assert f"{found['cores']} cores, {found['vector_capability']}" in printed.splitlines()[0]
    # each B once, however often it was asked for; the cases take turns in one process
    assert list(report["end_to_end"]["cpu"]) == ["B=1", "B=2"]
    assert report["end_to_end"]["cpu"]["B=1"]["steps_per_second"] > 0
    assert report["end_to_end"]["cpu"]["B=2"]["steps_per_second"] > 0
    # the trainer's whole step, with the distance learner fitting a full queue at every s
    assert report["end_to_end"]["cpu"]["B=1"]["trainer_steps_per_second"] > 0
    cpu = report["roofline"]["cpu"]
    assert cpu["coder_bound_ms_per_frame"] > 0
    assert report["end_to_end"]["cpu"]["B=1"]["coder_bound_ms"] == cpu["coder_bound_ms_per_frame"]
    assert cpu["matmul_gflops"] > 0 and cpu["copy_gbps"] > 0
    # where the CPU went: never more cores busy than the machine has, so the rate with every
    # core busy is at least the measured one (one presentation: no medians in between)
    one = report["end_to_end"]["cpu"]["B=1"]
    assert 0 < one["busy_cores"] <= report["ceiling"]["cpu"]["cores"] * 1.01
    assert one["steps_per_second_all_cores_busy"] >= one["steps_per_second"] * 0.99
    assert one["steps_per_second_min"] == one["steps_per_second"] == one["steps_per_second_max"]
    # which thread spent it: the step's own thread and the GL thread's worlds at least, and
    # together about the process's CPU time (the threads' clocks tick in 1/100 s)
    by_thread = one["cpu_ms_per_robot_iteration_by_thread"]
    assert by_thread["main"] > 0 and by_thread["GL thread"] > 0
    # each thread's reading is whole ticks, so it may be one tick off over the presentation
    cfg = compose(["curriculum=multi_5_10", *shrunken])
    steps = len(cfg.curriculum.lateral_positions) * cfg.env.trial_length
    tick_ms = 1e3 / os.sysconf("SC_CLK_TCK") / steps
    assert sum(by_thread.values()) == pytest.approx(
        one["cpu_ms_per_robot_iteration"], rel=0.25, abs=(len(by_thread) + 1) * tick_ms
    )
    assert "CPU per robot-iteration by thread" in printed
    # where the loop's thread spent a lockstep iteration: the rest is what its waits leave of
    # the iteration, so it is positive only if the waits were not counted twice
    loop = one["loop_thread_ms_per_lockstep"]
    assert list(loop) == ["frames", "dictionary_step", "encoding", "policy_and_rest"]
    assert loop["encoding"] > 0 and loop["policy_and_rest"] > 0
    assert "the loop's thread per lockstep iteration" in printed
    ceiling = report["ceiling"]["cpu"]
    assert ceiling["render_cpu_ms_per_frame"] > 0
    assert ceiling["B=1"]["steps_per_second"] == pytest.approx(
        bench.ceiling_steps_per_second(
            ceiling["render_cpu_ms_per_frame"], cpu["coder_bound_ms_per_frame"], 1, ceiling["cores"]
        )
    )
    assert "[ceiling cpu]" in printed and "cores busy" in printed


@pytest.mark.parametrize(
    "name", ["cpu_2core.json", "cpu_2core_turns.json", "cpu_2core_fovea.json", "gpu_h100.json"]
)
def test_show_prints_a_committed_report_without_measuring(name, capsys):
    """docs/performance.md quotes these files; --show prints their tables."""
    path = Path(__file__).resolve().parents[2] / "docs" / "results" / "bench" / name
    bench.main(["--show", str(path)])
    printed = capsys.readouterr().out
    assert "[end to end]" in printed and "[roofline cpu]" in printed
    report = json.loads(path.read_text())
    for dev, by_b in report["end_to_end"].items():
        for b, case in by_b.items():
            assert f"{dev} {b:<6} {case['steps_per_second']:>8.1f} steps/s" in printed


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads Linux's /proc")
def test_threads_are_told_apart_by_the_part_of_the_step_they_run():
    from parallax.tools.bench.timing import cpu_seconds_by_role, seconds_between, thread_role

    assert thread_role("MainThread") == "main"
    assert thread_role("parallax-scale_0") == "coder helper"
    assert thread_role("parallax-gl") == "GL thread"
    assert thread_role("llvmpipe-1") == "rasteriser"
    assert thread_role("pt_main_thread") == "other"
    before = cpu_seconds_by_role()
    deadline = time.thread_time() + 0.1
    while time.thread_time() < deadline:  # 0.1 s of this thread's CPU
        pass
    spent = seconds_between(before, cpu_seconds_by_role())
    assert 0.05 <= spent["main"] <= 0.5


def test_also_adds_a_case_for_every_b_measured_in_the_same_run(tmp_path, capsys, tiny_overrides):
    out = tmp_path / "bench.json"
    # the shrunken world, coder and learner: this test reads the report's shape, not its speed
    shrunken = [o for o in tiny_overrides if o.startswith(("env.", "coder.", "distance."))]
    bench.main(
        [
            "--no-components",
            "--robots",
            "2",
            "--presentations",
            "1",
            "--also",
            "env.robots_per_turn=1",
            "--json",
            str(out),
            *shrunken,
        ]
    )
    printed = capsys.readouterr().out
    report = json.loads(out.read_text())
    assert report["also"] == ["env.robots_per_turn=1"]
    cases = report["end_to_end"]["cpu"]
    assert list(cases) == ["B=2", "B=2 env.robots_per_turn=1"]
    # the bound of a lockstep of two robots, whichever setting the case adds
    work = bench.coder_work_per_frame(compose(["curriculum=multi_5_10", *shrunken]))
    for name, case in cases.items():
        assert case["robots"] == 2 and case["steps_per_second"] > 0
        assert case["coder_bound_ms"] == bench.coder_bound_ms(work, report["roofline"]["cpu"], 2)
        assert report["ceiling"]["cpu"][name]["measured_over_ceiling"] > 0
        assert f"cpu {name:<6} {case['steps_per_second']:>8.1f} steps/s" in printed


def test_a_bad_also_override_exits_2_naming_it_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "bench.json"
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["--no-components", "--also", "env.robots_per_turn=-1", "--json", str(out)])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert "env.robots_per_turn" in error and "-1" in error
    assert not out.exists()


def test_the_estimate_counts_the_runs_reproduce_trains_and_divides_by_the_rate(tmp_path, capsys):
    from parallax.tools.bench import estimate

    report = tmp_path / "bench.json"
    two = {"processes": 2, "steps_per_second": 400.0}
    report.write_text(json.dumps({"processes": {"this code": {"two": two}}}))
    estimate.main([str(report), "paper"])
    lines = capsys.readouterr().out.splitlines()
    # the paper family: 8 files trained (the unweighted 5–20 cm one is replayed), the 5–20 cm
    # weighted file with 5 seeds and the others with 3
    runs = estimate.trained("paper")
    assert len(runs) == 8 and "paper_multi_5_20" not in runs
    total = sum(estimate.robot_iterations(n) * (5 if "5_20" in n else 3) for n in runs)
    assert (
        lines[0]
        == f"paper: 26 runs of 8 experiment files, {total / 1e6:.2f} million robot-iterations"
    )
    assert lines[1].endswith(f"→ {total / 400 / 3600:.1f} hours")
    assert lines[2] == "  the rates measured on a machine the report does not name"
    named = {"cpu": "Some CPU", "cores": 2, "vector_capability": "AVX2", "load_average_before": 1.5}
    report.write_text(json.dumps({"machine": named, "processes": {"this code": {"two": two}}}))
    estimate.main([str(report), "paper"])
    assert capsys.readouterr().out.splitlines()[2] == (
        "  the rates measured on Some CPU (2 cores, AVX2), load average 1.50 before"
    )
    with pytest.raises(SystemExit) as exit_info:
        estimate.main([str(report), "nosuchfamily"])
    assert exit_info.value.code == 2 and "nosuchfamily" in capsys.readouterr().err


def test_compare_needs_processes_and_a_commit(capsys):
    for arguments in (["--compare", "HEAD"], ["--processes", "1", "--compare", "no-such-rev"]):
        with pytest.raises(SystemExit) as exit_info:
            bench.main(arguments)
        assert exit_info.value.code == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.slow
def test_processes_run_one_robot_alone_and_two_side_by_side(tmp_path, capsys, tiny_overrides):
    out = tmp_path / "bench.json"
    bench.main(
        ["--only-processes", "--processes", "1", "--presentations", "1", "--json", str(out)]
        + [o for o in tiny_overrides if o.startswith(("env.", "coder."))]
    )
    cases = json.loads(out.read_text())["processes"]["this code"]
    assert cases["alone"]["processes"] == 1 and cases["two"]["processes"] == 2
    for case in cases.values():
        assert case["steps_per_second"] > 0 and case["cpu_ms_per_robot_iteration"] > 0
    assert "2 side by side" in capsys.readouterr().out
