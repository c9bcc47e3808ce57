"""`parallax-bench`: where the time of one environment step goes, and how far it is from the limit.

Prints a readable table and writes JSON of
- median times per component (the world's render and step, the retina, the encoding of both
  scales and the dictionary update, the policy's act + update, one Levenberg–Marquardt epoch),
  from the component benchmarks beside this file (coding, policy, distance, envs);
- end-to-end environment steps per second (robot-iterations per second) for B = 1 and B = 16
  robots in lockstep, on the CPU (and CUDA when present);
- the roofline of this machine for one step of the coder: its floating-point work and memory
  traffic divided by the measured matmul throughput and memory bandwidth;
- where the whole step's time goes on the CPU: the process's CPU time per robot-iteration, which
  thread spent it, how many cores it kept busy, and the rate if every core were busy (what
  scheduling could give);
- the step's ceiling on this machine: the coder at its roofline bound, every frame at the CPU
  cost of a render measured alone, and every core busy — the most any schedule can give.

Everything is measured in the same run, so ratios are comparable even on a shared machine;
medians, never means. ``--threads`` sets torch's intra-op threads; the step also runs the world
on the GL thread and the coder's second scale on a helper thread whatever it is
(docs/performance.md).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import torch

from parallax.config import compose
from parallax.tools.bench.limits import (
    ceiling_steps_per_second,
    coder_bound_ms,
    coder_work_per_frame,
    cuda_components,
    machine_limits,
    render_cpu_ms_per_frame,
    usable_cores,
)
from parallax.tools.bench.timing import (
    cpu_seconds_by_role,
    describe_machine,
    machine,
    seconds_between,
)
from parallax.writable import file_problem


# --- end to end ----------------------------------------------------------------------------------
def settings(also: Sequence[str]) -> list[list[str]]:
    """The end-to-end cases' extra overrides: none (the plain case), then each of ``also``."""
    return [[], *([override] for override in also)]


def case_name(robots: int, extra: Sequence[str]) -> str:
    """The report's key of an end-to-end case: ``B=16``, or ``B=16 env.robots_per_turn=0``."""
    return " ".join([f"B={robots}", *extra])


def end_to_end(
    robots: Sequence[int],
    presentations: int,
    device: str,
    overrides: list[str],
    also: Sequence[str] = (),
) -> dict[str, dict[str, float]]:
    """Robot-iterations per second of the whole loop for each B in ``robots``, twice: the
    experiment's presentation alone (render → retina → encode → policy → dictionary update) and
    the trainer's whole step, which adds the distance learner's online prediction and fit (§3.5)
    and the metrics. The learner's queue is filled with synthetic vectors first, so that every s
    triggers a fit of full size.

    Each override in ``also`` adds a case for every B with that override, so that two settings
    (``env.robots_per_turn=0`` against the default, say) compare in one run. The cases take turns,
    one presentation each per round, so that every case sees the same machine: on a shared
    machine the speed moves by tens of per cent within minutes."""
    import tempfile

    import numpy as np

    from parallax.tools.analysis.synthetic_pans import paper_regression
    from parallax.trainer import Trainer

    with contextlib.ExitStack() as stack:
        cases = {}  # name → (B, its trainer)
        for extra, b in ((extra, b) for extra in settings(also) for b in robots):
            trainer = Trainer(
                compose([f"env.robots={b}", f"device={device}", *overrides, *extra]),
                stack.enter_context(tempfile.TemporaryDirectory()),
            )
            stack.callback(trainer.exp.close)
            learner = trainer.exp.distance
            pans, distances = paper_regression(
                learner.queue.capacity,
                np.random.default_rng(0),
                lateral_positions_m=trainer.exp.lateral_positions,
            )
            learner.observe_batch(pans, distances)  # the first, long fit happens here, untimed
            trainer.step_presentation(keep_view=False)  # warm-up: first calls allocate and compile
            cases[case_name(b, extra)] = b, trainer
        samples = {
            name: {
                "rates": [],
                "step_ms": [],
                "trainer_rates": [],
                "cpu_ms": [],
                "by_thread": [],
                "loop": [],
            }
            for name in cases
        }
        for _ in range(presentations):
            for name, (b, trainer) in cases.items():
                timed = samples[name]
                threads = cpu_seconds_by_role()
                t, cpu = time.perf_counter(), time.process_time()
                pres = trainer.exp.run_presentation()
                dt, cpu = time.perf_counter() - t, time.process_time() - cpu
                threads = seconds_between(threads, cpu_seconds_by_role())
                timed["rates"].append(pres.steps * b / dt)
                timed["step_ms"].append(dt / pres.steps * 1e3)
                timed["cpu_ms"].append(cpu / (pres.steps * b) * 1e3)
                timed["by_thread"].append(
                    {role: s / (pres.steps * b) * 1e3 for role, s in threads.items()}
                )
                # the loop's own thread, per lockstep iteration: its waits, and the rest of its
                # time (the policy's turn and the bookkeeping)
                loop = {wait: s / pres.steps * 1e3 for wait, s in pres.waits.items()}
                loop["policy_and_rest"] = dt / pres.steps * 1e3 - sum(loop.values())
                timed["loop"].append(loop)
                t = time.perf_counter()
                pres, _ = trainer.step_presentation(keep_view=False)
                timed["trainer_rates"].append(pres.steps * b / (time.perf_counter() - t))
    cores = usable_cores()
    results = {}
    for name, timed in samples.items():
        rates, cpu_ms = timed["rates"], timed["cpu_ms"]
        cpu_per_iteration = statistics.median(cpu_ms)
        results[name] = {
            "robots": cases[name][0],
            "steps_per_second": statistics.median(rates),
            "lockstep_ms": statistics.median(timed["step_ms"]),
            "steps_per_second_min": min(rates),
            "steps_per_second_max": max(rates),
            "trainer_steps_per_second": statistics.median(timed["trainer_rates"]),
            # CPU time of every thread of the process (GL, Mesa's rasterisers, the coder's helper)
            "cpu_ms_per_robot_iteration": cpu_per_iteration,
            "busy_cores": statistics.median(rate * c / 1e3 for rate, c in zip(rates, cpu_ms)),
            "cores": cores,
            # the same work with every core busy all the time: what scheduling could still give
            "steps_per_second_all_cores_busy": cores / cpu_per_iteration * 1e3,
            # which thread spent it (parallax.tools.bench.timing.THREAD_ROLES); Linux only
            "cpu_ms_per_robot_iteration_by_thread": {
                role: statistics.median(p.get(role, 0.0) for p in timed["by_thread"])
                for role in dict.fromkeys(r for p in timed["by_thread"] for r in p)
            },
            # where the loop's thread spent a lockstep iteration (parallax.lockstep.WAITS and the
            # rest), ms
            "loop_thread_ms_per_lockstep": {
                part: statistics.median(p[part] for p in timed["loop"]) for part in timed["loop"][0]
            },
        }
    return results


def run(
    repeats: int = 30,
    presentations: int = 3,
    robots: tuple[int, ...] = (1, 16),
    threads: int = 1,
    components: bool = True,
    config_overrides: Sequence[str] = (),
    also: Sequence[str] = (),
) -> dict:
    torch.set_num_threads(threads)
    report: dict = {
        "machine": machine(),  # before the measurements load it
        "threads": threads,
        "overrides": list(config_overrides),
        "also": list(also),
        "torch": torch.__version__,
        "cuda": torch.cuda.is_available(),
    }
    if components:
        from parallax.tools.bench import coding as coding_bench
        from parallax.tools.bench import distance as distance_bench
        from parallax.tools.bench import envs as envs_bench
        from parallax.tools.bench import policy as policy_bench

        report["components_ms"] = {
            "world": envs_bench.run(repeats),
            "coder": coding_bench.run(repeats),
            "policy": policy_bench.run(repeats),
            "distance": distance_bench.run(max(5, repeats // 3)),
        }
        if torch.cuda.is_available():
            report["components_ms"]["cuda"] = cuda_components(repeats)
        torch.set_num_threads(threads)  # component benchmarks may change it
    # A short multi-position curriculum: 6 positions × 30 iterations per presentation.
    overrides = ["curriculum=multi_5_10", f"train.threads={threads}", *config_overrides]
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    report["end_to_end"] = {
        dev: end_to_end(robots, presentations, dev, overrides, also) for dev in devices
    }
    cfg = compose(overrides)
    work = coder_work_per_frame(cfg)
    report["roofline"] = {}
    for dev in devices:
        limits = machine_limits(threads, dev)
        report["roofline"][dev] = {
            **limits,
            **work,
            "coder_bound_ms_per_frame": coder_bound_ms(work, limits, 1),
            "coder_bound_ms_B16": coder_bound_ms(work, limits, 16),
        }
    rf = report["roofline"]["cpu"]
    coder = report.get("components_ms", {}).get("coder", {})
    # What the coder runs by default, and each Gram-form implementation (compiled kernels and
    # the numpy/torch fallback) measured beside it.
    for key, name in (
        ("coder_measured_over_bound", "encode_update_both_B1_gram_ms"),
        ("coder_cpp_measured_over_bound", "encode_update_both_B1_gram_cpp_ms"),
        ("coder_torch_measured_over_bound", "encode_update_both_B1_gram_torch_ms"),
    ):
        if coder.get(name):
            rf[key] = coder[name] / rf["coder_bound_ms_per_frame"]
    if coder.get("encode_update_both_B16_gram_ms"):
        rf["coder_B16_measured_over_bound"] = (
            coder["encode_update_both_B16_gram_ms"] / rf["coder_bound_ms_B16"]
        )
    on_gpu = report.get("components_ms", {}).get("cuda", {})
    for batch in (1, 16, 64):
        if on_gpu.get(f"encode_update_both_B{batch}_ms"):
            report["roofline"]["cuda"][f"coder_B{batch}_measured_over_bound"] = on_gpu[
                f"encode_update_both_B{batch}_ms"
            ] / coder_bound_ms(work, report["roofline"]["cuda"], batch)
    for dev, by_b in report["end_to_end"].items():
        for r in by_b.values():
            r["coder_bound_ms"] = coder_bound_ms(work, report["roofline"][dev], r["robots"])
            r["step_over_coder_bound"] = r["lockstep_ms"] / r["coder_bound_ms"]
    cores, render_ms = usable_cores(), render_cpu_ms_per_frame()
    report["ceiling"] = {"cpu": {"cores": cores, "render_cpu_ms_per_frame": render_ms}}
    for b, r in report["end_to_end"]["cpu"].items():
        ceiling = ceiling_steps_per_second(render_ms, r["coder_bound_ms"], r["robots"], cores)
        report["ceiling"]["cpu"][b] = {
            "steps_per_second": ceiling,
            "measured_over_ceiling": r["steps_per_second"] / ceiling,
        }
    return report


def format_report(report: dict) -> str:
    lines = [
        f"parallax-bench — torch {report['torch']}, {report['threads']} thread(s), "
        f"CUDA {'yes' if report['cuda'] else 'no'}; {describe_machine(report)}"
    ]
    for group, figures in report.get("components_ms", {}).items():
        lines.append(f"[{group}]")
        for name, value in figures.items():
            lines.append(f"  {name:<48} {value:>10.3f}")
    if "end_to_end" in report:
        lines.append(
            "[end to end] robot-iterations per second (median over presentations; "
            "the cases take turns)"
        )
    for dev, by_b in report.get("end_to_end", {}).items():
        for b, r in by_b.items():
            trainer = (
                f"   with the distance learner {r['trainer_steps_per_second']:.1f} steps/s"
                if "trainer_steps_per_second" in r
                else ""
            )
            lines.append(
                f"  {dev} {b:<6} {r['steps_per_second']:>8.1f} steps/s   "
                f"lockstep {r['lockstep_ms']:.2f} ms   "
                f"×{r['step_over_coder_bound']:.1f} of the coder bound" + trainer
            )
    for dev, by_b in report.get("end_to_end", {}).items():
        for b, r in by_b.items():
            if "cpu_ms_per_robot_iteration" in r:
                # a report may carry the core count with its ceiling only
                cores = r.get("cores", report.get("ceiling", {}).get(dev, {}).get("cores", "?"))
                lines.append(
                    f"  {dev} {b:<6} range "
                    f"{r['steps_per_second_min']:.1f}–{r['steps_per_second_max']:.1f} steps/s;  "
                    f"{r['cpu_ms_per_robot_iteration']:.2f} ms of CPU per robot-iteration, "
                    f"{r['busy_cores']:.2f} cores busy → "
                    f"{r['steps_per_second_all_cores_busy']:.1f} "
                    f"steps/s if all {cores} were"
                )
            by_thread = r.get("cpu_ms_per_robot_iteration_by_thread")
            if by_thread:
                spent = ", ".join(f"{role} {ms:.2f}" for role, ms in by_thread.items())
                lines.append(f"  {dev} {b:<6} CPU per robot-iteration by thread, ms: {spent}")
            loop = r.get("loop_thread_ms_per_lockstep")
            if loop:
                spent = ", ".join(f"{part.replace('_', ' ')} {ms:.2f}" for part, ms in loop.items())
                lines.append(
                    f"  {dev} {b:<6} the loop's thread per lockstep iteration, ms: {spent}"
                )
    for dev, rf in report.get("roofline", {}).items():
        lockstep = (
            f"; a lockstep of 16 robots {rf['coder_bound_ms_B16']:.3f} ms "
            "(the Gram matrix and dictionary reads once)"
            if "coder_bound_ms_B16" in rf
            else ""
        )
        lines.append(
            f"[roofline {dev}] matmul {rf['matmul_gflops']:.1f} GFLOP/s, "
            f"copy {rf['copy_gbps']:.1f} GB/s; coder per frame {rf['flops'] / 1e6:.1f} MFLOP, "
            f"{rf['bytes'] / 1e6:.1f} MB → bound {rf['coder_bound_ms_per_frame']:.4f} ms" + lockstep
        )
        if "coder_measured_over_bound" in rf:
            variants = [
                f"{label} ×{rf[key]:.1f}"
                for key, label in (
                    ("coder_cpp_measured_over_bound", "compiled kernels"),
                    ("coder_torch_measured_over_bound", "numpy/torch loop"),
                )
                if key in rf
            ]
            lines.append(
                f"  coder measured / bound: ×{rf['coder_measured_over_bound']:.1f}"
                + (f" ({', '.join(variants)})" if variants else "")
            )
        gpu = [
            f"B={b} ×{rf[f'coder_B{b}_measured_over_bound']:.1f}"
            for b in (1, 16, 64)
            if f"coder_B{b}_measured_over_bound" in rf
        ]
        if gpu:
            lines.append(f"  coder measured / bound, by robots in the lockstep: {', '.join(gpu)}")
    if "ceiling" in report:
        top = report["ceiling"]["cpu"]
        lines.append(
            f"[ceiling cpu] {top['cores']} cores; a left-eye frame costs "
            f"{top['render_cpu_ms_per_frame']:.2f} ms "
            "of CPU to render alone; with the coder at its roofline bound and every core busy:"
        )
        for b, c in top.items():
            if b.startswith("B="):
                lines.append(
                    f"  {b:<6} ≤ {c['steps_per_second']:.1f} robot-iterations/s "
                    f"(measured: {c['measured_over_ceiling']:.0%} of it)"
                )
    if "processes" in report:
        from parallax.tools.bench.processes import format_processes

        lines += format_processes(report["processes"])
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="parallax-bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=30, help="timed repeats per component")
    parser.add_argument(
        "--presentations", type=int, default=3, help="timed presentations per end-to-end case"
    )
    parser.add_argument(
        "--robots", type=int, nargs="+", default=[1, 16], help="B values end to end"
    )
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument(
        "--also",
        action="append",
        default=[],
        metavar="OVERRIDE",
        help="a Hydra override that adds an end-to-end case for every B, measured in turn with "
        "the others (repeatable), e.g. --also env.robots_per_turn=0",
    )
    parser.add_argument(
        "overrides",
        nargs="*",
        help="Hydra overrides of the end-to-end cases (after curriculum=multi_5_10), e.g. "
        "experiment=recipe_multi_5_20_weighted",
    )
    parser.add_argument("--no-components", action="store_true", help="end to end and roofline only")
    parser.add_argument(
        "--processes",
        type=int,
        default=0,
        metavar="ROUNDS",
        help="also single-robot runs as processes, one alone and two side by side (machine-wide "
        "robot-iterations/s), this many rounds of --presentations each",
    )
    parser.add_argument(
        "--compare",
        default=None,
        metavar="REV",
        help="with --processes: the same cases on the code of this git revision, in the same "
        "rounds",
    )
    parser.add_argument(
        "--only-processes", action="store_true", help="the process cases alone (with --processes)"
    )
    parser.add_argument("--json", default=None, help="also write the report to this file")
    parser.add_argument(
        "--show",
        default=None,
        metavar="JSON",
        help="print the tables of a report written by --json, measuring nothing",
    )
    args = parser.parse_args(argv)
    if args.show:
        print(format_report(json.loads(Path(args.show).read_text())))
        return
    if args.repeats < 1 or args.presentations < 1 or min(args.robots) < 1 or args.threads < 1:
        print(
            "parallax-bench: error: --repeats, --presentations, --robots and --threads must be ≥ 1",
            file=sys.stderr,
        )
        sys.exit(2)
    if (args.compare or args.only_processes) and args.processes < 1:
        print(
            "parallax-bench: error: --compare and --only-processes need --processes",
            file=sys.stderr,
        )
        sys.exit(2)
    if args.compare:
        from parallax.tools.bench.processes import revision_error

        error = revision_error(args.compare)
        if error:
            print(f"parallax-bench: error: {error}", file=sys.stderr)
            sys.exit(2)
    problem = file_problem(args.json) if args.json else None
    if problem:  # before the measurements, which take minutes
        print(
            f"parallax-bench: error: --json {args.json} {problem}; choose another file",
            file=sys.stderr,
        )
        sys.exit(2)
    from parallax.config.overrides import composition_error

    for extra in settings(args.also):
        error = composition_error(["curriculum=multi_5_10", *args.overrides, *extra], check=True)
        if error:
            print(f"parallax-bench: error: {error}", file=sys.stderr)
            sys.exit(2)
    robots = tuple(dict.fromkeys(args.robots))  # each B once, in the order given
    if args.only_processes:
        report = {
            "machine": machine(),
            "threads": args.threads,
            "torch": torch.__version__,
            "cuda": False,
        }
    else:
        report = run(
            args.repeats,
            args.presentations,
            robots,
            args.threads,
            not args.no_components,
            args.overrides,
            tuple(dict.fromkeys(args.also)),
        )
    if args.processes:
        from parallax.tools.bench import processes

        overrides = ["curriculum=multi_5_10", f"train.threads={args.threads}", *args.overrides]
        report["processes"] = processes.run(
            args.processes, args.presentations, args.threads, overrides, args.compare
        )
    print(format_report(report))
    text = json.dumps(report, indent=2)
    if args.json:
        Path(args.json).write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
