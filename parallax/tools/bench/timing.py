"""Timing for the benchmarks (`parallax-bench` and each sub-package's ``benchmark.run``).

Operations are timed in turn, round after round, so that all of them see the same machine
load; medians, not means, because a shared machine's noise comes in bursts.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


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
