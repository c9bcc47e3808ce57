"""Single-robot runs as processes, the way the paper's runs are made (`parallax-bench --processes`).

The paper's algorithm runs one robot, and its runs go several at a time on one machine, each a
process of its own. Two cases measure that, taking turns round by round so that both see the
same machine: one process alone, and two side by side, whose machine-wide rate is all their
robot-iterations over the time from the first start to the last end. Each process runs
:mod:`parallax.tools.bench.solo`. ``--compare REV`` adds the same two cases on the code of a git
revision (checked out into a temporary worktree), in the same rounds, so that old and new code
compare within one run.
"""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

import parallax

WORKER = Path(__file__).with_name("solo.py")
#: The code this package runs from: its checkout's root.
ROOT = Path(parallax.__file__).resolve().parents[1]
#: How many processes run side by side in the second case.
SIDE_BY_SIDE = 2


class Worker:
    """One solo process on the code under ``code`` (a directory holding ``parallax``)."""

    def __init__(self, code: Path, threads: int, overrides: Sequence[str], cwd: str) -> None:
        environment = dict(os.environ)
        environment["PYTHONPATH"] = os.pathsep.join(
            [str(code), *filter(None, [os.environ.get("PYTHONPATH")])]
        )
        # The worker runs as a file through -c, so that its own directory does not lead
        # sys.path and the code under PYTHONPATH is the one imported.
        boot = (
            "import runpy, sys; sys.argv[:] = sys.argv[1:]; "
            "runpy.run_path(sys.argv[0], run_name='__main__')"
        )
        self.process = subprocess.Popen(
            [sys.executable, "-c", boot, str(WORKER), str(threads), *overrides],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=environment,
            cwd=cwd,
        )
        self._expect("ready")

    def _expect(self, word: str) -> None:
        line = self.process.stdout.readline().strip()
        if line != word:
            self.process.kill()
            raise RuntimeError(f"a benchmark process ended before it was {word} ({line!r})")

    def start(self, presentations: int) -> None:
        self.process.stdin.write(f"{presentations}\n")
        self.process.stdin.flush()

    def result(self) -> dict:
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError("a benchmark process ended in the middle of a measurement")
        return json.loads(line)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.process.stdin.write("quit\n")
            self.process.stdin.close()
        try:
            self.process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.process.kill()


@contextlib.contextmanager
def checkout(revision: str) -> Iterator[Path]:
    """The code of ``revision`` in a temporary git worktree of this checkout, removed after."""
    with tempfile.TemporaryDirectory(prefix="parallax-compare-") as parent:
        tree = Path(parent) / "code"
        git = ["git", "-C", str(ROOT)]
        added = subprocess.run(
            [*git, "worktree", "add", "--detach", str(tree), revision],
            capture_output=True,
            text=True,
        )
        if added.returncode != 0:
            message = (added.stderr.strip().splitlines() or ["git worktree add failed"])[-1]
            raise ValueError(f"cannot check out {revision!r}: {message}")
        try:
            yield tree
        finally:
            subprocess.run([*git, "worktree", "remove", "--force", str(tree)], capture_output=True)


def revision_error(revision: str) -> str | None:
    """Why ``revision`` cannot be compared with (None when it can), before anything is measured."""
    found = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", f"{revision}^{{commit}}"],
        capture_output=True,
        text=True,
    )
    if found.returncode != 0:
        return f"--compare {revision}: not a commit of the git checkout at {ROOT}"
    return None


def _summary(samples: list[list[dict]]) -> dict:
    """Medians over rounds of one case; each sample is the answers of its processes."""
    rates, cpu_ms, by_thread = [], [], []
    for answers in samples:
        steps = sum(a["steps"] for a in answers)
        span = max(a["end"] for a in answers) - min(a["start"] for a in answers)
        rates.append(steps / span)
        cpu_ms.append(sum(a["cpu_s"] for a in answers) / steps * 1e3)
        roles: dict[str, float] = {}
        for answer in answers:
            for role, seconds in answer.get("cpu_s_by_thread", {}).items():
                roles[role] = roles.get(role, 0.0) + seconds / steps * 1e3
        by_thread.append(roles)
    return {
        "processes": len(samples[0]),
        "steps_per_second": statistics.median(rates),
        "steps_per_second_min": min(rates),
        "steps_per_second_max": max(rates),
        "cpu_ms_per_robot_iteration": statistics.median(cpu_ms),
        "cpu_ms_per_robot_iteration_by_thread": {
            role: statistics.median(r.get(role, 0.0) for r in by_thread)
            for role in dict.fromkeys(role for r in by_thread for role in r)
        },
    }


def run(
    rounds: int,
    presentations: int,
    threads: int,
    overrides: Sequence[str],
    compare: str | None = None,
) -> dict:
    """The cases (this code, and ``compare``'s when given: one process alone, two side by side),
    ``rounds`` rounds of ``presentations`` presentations per process each; medians."""
    with contextlib.ExitStack() as stack:
        cwd = stack.enter_context(tempfile.TemporaryDirectory(prefix="parallax-bench-"))
        codes = {"this code": ROOT}
        if compare is not None:
            codes[compare] = stack.enter_context(checkout(compare))
        workers = {}
        for name, code in codes.items():
            workers[name] = [Worker(code, threads, overrides, cwd) for _ in range(SIDE_BY_SIDE)]
            for worker in workers[name]:
                stack.callback(worker.close)
        samples: dict[str, dict[str, list]] = {name: {"alone": [], "two": []} for name in codes}
        for _ in range(rounds):
            for name, (first, *others) in workers.items():
                first.start(presentations)
                samples[name]["alone"].append([first.result()])
                for worker in (first, *others):
                    worker.start(presentations)
                samples[name]["two"].append([w.result() for w in (first, *others)])
    return {
        name: {case: _summary(answers) for case, answers in cases.items()}
        for name, cases in samples.items()
    }


def format_processes(report: dict) -> list[str]:
    """The report's lines for its single-robot processes."""
    lines = [
        "[processes] single-robot runs as processes: machine-wide robot-iterations/s "
        "(median over rounds; the cases take turns)"
    ]
    for name, cases in report.items():
        for case, r in cases.items():
            label = "one alone" if case == "alone" else f"{r['processes']} side by side"
            spent = ", ".join(
                f"{role} {ms:.2f}" for role, ms in r["cpu_ms_per_robot_iteration_by_thread"].items()
            )
            lines.append(
                f"  {name:<10} {label:<15} {r['steps_per_second']:>7.1f} "
                f"({r['steps_per_second_min']:.1f}–{r['steps_per_second_max']:.1f})   "
                f"{r['cpu_ms_per_robot_iteration']:.2f} ms of CPU per robot-iteration"
                + (f" ({spent})" if spent else "")
            )
    names = list(report)
    if len(names) == 2:
        new, old = (report[name] for name in names)
        for case in ("alone", "two"):
            rate = new[case]["steps_per_second"] / old[case]["steps_per_second"]
            cpu = new[case]["cpu_ms_per_robot_iteration"] / old[case]["cpu_ms_per_robot_iteration"]
            lines.append(
                f"  {case:<6} this code / {names[1]}: ×{rate:.2f} the rate, "
                f"×{cpu:.2f} the CPU per robot-iteration"
            )
        lines.append(
            f"  this code's two side by side / {names[1]}'s one alone: "
            f"×{new['two']['steps_per_second'] / old['alone']['steps_per_second']:.2f}"
        )
    return lines
