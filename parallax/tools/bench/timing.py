"""Timing for the benchmarks (`parallax-bench` and each sub-package's ``benchmark.run``).

Operations are timed in turn, round after round, so that all of them see the same machine
load; medians, not means, because a shared machine's noise comes in bursts. The CPU time of a
whole step is split by thread (:func:`cpu_seconds_by_role`): which part of the step runs where.
"""

from __future__ import annotations

import os
import platform
import statistics
import threading
import time
from collections.abc import Callable
from pathlib import Path

import torch


def machine_name(device: torch.device | None = None) -> str:
    """The GPU's name for a CUDA device, else the CPU's model name (Linux; else the platform's
    processor string, which may be empty)."""
    if device is not None and device.type == "cuda":
        return torch.cuda.get_device_name(device)
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor()


def machine() -> dict:
    """What a speed report was measured on: rates move several-fold between CPUs (and their
    vector width, which also picks the compiled kernels), and with the load already there."""
    return {
        "cpu": machine_name(),
        "cores": os.cpu_count(),
        "vector_capability": torch.backends.cpu.get_cpu_capability(),
        "load_average_before": os.getloadavg()[0],
    }


def describe_machine(report: dict) -> str:
    """One line naming the machine of a speed report, or saying that the report names none."""
    found = report.get("machine")
    if not found:
        return "measured on a machine the report does not name"
    return (
        f"measured on {found['cpu'] or 'an unnamed CPU'} ({found['cores']} cores, "
        f"{found['vector_capability']}), load average {found['load_average_before']:.2f} before"
    )


def interleaved_medians_ms(
    operations: dict[str, Callable[[], object]], repeats: int, warmup: int = 3
) -> dict[str, float]:
    """Median milliseconds of each operation over ``repeats`` interleaved rounds."""
    for _ in range(warmup):
        for operation in operations.values():
            operation()
    samples: dict[str, list[float]] = {name: [] for name in operations}
    for _ in range(repeats):
        for name, operation in operations.items():
            start = time.perf_counter()
            operation()
            samples[name].append((time.perf_counter() - start) * 1e3)
    return {name: statistics.median(values) for name, values in samples.items()}


#: The threads of a step by the part of it they run (docs/performance.md, "How a step is
#: scheduled"), matched on the thread's name: Python's for threads it started, else the system's.
THREAD_ROLES = (
    ("MainThread", "main"),  # retina and the first scale, the policy, the records
    ("parallax-scale", "coder helper"),  # the second scale, the dictionary step
    ("parallax-gl", "GL thread"),  # the worlds' steps and their draw calls
    ("llvmpipe", "rasteriser"),  # Mesa's rasteriser threads
)


def thread_role(name: str) -> str:
    """The role of a thread called ``name``: the first of :data:`THREAD_ROLES` it starts with."""
    return next((role for prefix, role in THREAD_ROLES if name.startswith(prefix)), "other")


def cpu_seconds_by_role() -> dict[str, float]:
    """CPU seconds (user + system) each role's threads of this process have used so far, read
    from /proc (Linux); empty where there is no /proc/self/task."""
    tasks = Path("/proc/self/task")
    if not tasks.is_dir():
        return {}
    names = {str(thread.native_id): thread.name for thread in threading.enumerate()}
    tick = os.sysconf("SC_CLK_TCK")
    seconds: dict[str, float] = {}
    for task in tasks.iterdir():
        try:
            stat = (task / "stat").read_text()
            name = names.get(task.name) or (task / "comm").read_text().strip()
        except OSError:  # the thread ended meanwhile
            continue
        fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "
        role = thread_role(name)
        seconds[role] = seconds.get(role, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return seconds


def seconds_between(before: dict[str, float], after: dict[str, float]) -> dict[str, float]:
    """What each role used between two :func:`cpu_seconds_by_role` readings (a thread that
    ended in between takes its time with it)."""
    return {role: after[role] - before.get(role, 0.0) for role in after}
