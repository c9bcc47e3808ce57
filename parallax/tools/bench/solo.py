"""One single-robot run's loop in a process of its own, for `parallax-bench --processes`.

The paper's runs are single-robot runs, several at a time on one machine, each a process of its
own; :mod:`parallax.tools.bench.processes` starts this file once per process and has it run
presentations of the paper's loop (:meth:`parallax.experiment.Experiment.run_presentation`).

Usage: ``python solo.py THREADS [OVERRIDE ...]``. After one untimed presentation it prints
``ready``; then each line it reads is a number of presentations to run, answered with one JSON
line (robot-iterations, wall-clock start and end, CPU seconds of the process and, on Linux, of
each thread by role); ``quit`` ends it. It runs as a file rather than a module, and uses only
what every revision of the package has (``parallax.config.compose`` and
``parallax.experiment.Experiment``), so that ``parallax-bench --compare REV`` can run it on the
code of another revision.
"""

from __future__ import annotations

import json
import sys
import time


def main(argv: list[str]) -> None:
    import torch

    torch.set_num_threads(int(argv[0]))
    from parallax.config import compose
    from parallax.experiment import Experiment

    try:
        from parallax.tools.bench.timing import cpu_seconds_by_role
    except ImportError:  # a revision without it: the process's total only

        def cpu_seconds_by_role() -> dict[str, float]:
            return {}

    experiment = Experiment(compose(["env.robots=1", *argv[1:]]))
    try:
        experiment.run_presentation()  # warm-up: first calls allocate and build the kernels
        print("ready", flush=True)
        for line in sys.stdin:
            if line.strip() == "quit":
                break
            threads = cpu_seconds_by_role()
            started, cpu = time.time(), time.process_time()
            steps = sum(experiment.run_presentation().steps for _ in range(int(line)))
            ended, cpu = time.time(), time.process_time() - cpu
            after = cpu_seconds_by_role()
            by_role = {role: s - threads.get(role, 0.0) for role, s in after.items()}
            answer = {"steps": steps, "start": started, "end": ended, "cpu_s": cpu}
            print(json.dumps({**answer, "cpu_s_by_thread": by_role}), flush=True)
    finally:
        experiment.close()


if __name__ == "__main__":
    main(sys.argv[1:])
