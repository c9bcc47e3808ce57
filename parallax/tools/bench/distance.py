"""Speed of the distance learner (paper §3.5): one LM epoch at the paper's size, and SciPy.

Problem: c = 300 vectors of r = 16 pans (L = 5…20 cm, geometry + N(0, 0.05°) noise), the
30-unit network (541 parameters). An "epoch" is one Jacobian, the damped solves until a step
is accepted, and the candidate evaluations. SciPy's MINPACK (``least_squares(method="lm")``)
gets the same residuals and the same torch Jacobian from the same start and stops after
``SCIPY_MAX_NFEV`` residual evaluations (running it to convergence takes tens of seconds);
our LM is then timed for the same number of Jacobian evaluations as SciPy used, and both
sums of squares are reported. MINPACK sees the weight decay λ‖w‖² as P more residuals √λ·w.
It refuses fewer residuals than parameters (300 < 541), so without the decay its residual
vector is padded with zeros, which changes neither the sum of squares nor the steps.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np
import torch
from scipy.optimize import least_squares

from parallax.distance.learner import DistanceLearner, regression_residuals
from parallax.distance.levenberg_marquardt import DampedSolver, LevenbergMarquardt
from parallax.tools.analysis.synthetic_pans import PAPER_LATERAL_POSITIONS_M, paper_regression

SCIPY_MAX_NFEV = 40


def _median_ms(
    operation: Callable[[], object], repeats: int, before: Callable[[], None] = lambda: None
) -> float:
    times = []
    for _ in range(repeats):
        before()
        start = time.perf_counter()
        operation()
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def paper_sized_learner() -> DistanceLearner:
    pans, distances = paper_regression(300, np.random.default_rng(0))
    learner = DistanceLearner(
        PAPER_LATERAL_POSITIONS_M,
        queue_size=300,
        hidden=30,
        initial_epochs=5,
        epochs_per_call=1,
        seed=0,
    )
    for s, distance in zip(pans, distances):
        learner.observe(s, distance)
    return learner


def _scipy_fit(
    optimizer: LevenbergMarquardt,
    inputs: torch.Tensor,
    targets: torch.Tensor,
    start: torch.Tensor,
    max_nfev: int = SCIPY_MAX_NFEV,
) -> tuple[float, float, int]:
    """(milliseconds, SSE, Jacobian evaluations) of MINPACK from ``start``."""
    batch = (inputs, targets)
    root_decay, params = float(np.sqrt(optimizer.weight_decay)), optimizer.num_params
    decay_rows = params if root_decay else 0
    padding = max(params - targets.numel() - decay_rows, 0)

    def residuals(flat: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            values = optimizer.residuals(
                torch.from_numpy(flat), regression_residuals, batch
            ).numpy()
        return np.concatenate([values, root_decay * flat[:decay_rows], np.zeros(padding)])

    def jacobian(flat: np.ndarray) -> np.ndarray:
        values = optimizer.jacobian(
            torch.from_numpy(flat), regression_residuals, batch, True
        ).numpy()
        decay = root_decay * np.eye(params)[:decay_rows]
        return np.concatenate([values, decay, np.zeros((padding, params))])

    begin = time.perf_counter()
    solution = least_squares(
        residuals, start.numpy().copy(), jac=jacobian, method="lm", max_nfev=max_nfev
    )
    elapsed = 1e3 * (time.perf_counter() - begin)
    return elapsed, 2.0 * float(solution.cost), int(solution.njev)


class EpochFromStart:
    """One LM epoch of ``learner`` on its own queue, on its device, timed from a fixed start:
    :meth:`restore` puts the parameters and μ back where they were at construction, :meth:`epoch`
    runs one epoch. The weighted inputs, targets and start are kept for the other timings."""

    def __init__(self, learner: DistanceLearner) -> None:
        self.optimizer, self.closed_form = learner.optimizer, learner.residual_jacobian
        self.inputs, self.targets = learner.queue.inputs * learner.weights, learner.queue.targets
        self.start, self.start_mu = self.optimizer.flat_parameters().clone(), self.optimizer.mu

    def restore(self) -> None:
        self.optimizer.set_flat_parameters(self.start)
        self.optimizer.mu = self.start_mu

    def epoch(self) -> None:
        self.optimizer.step(
            regression_residuals,
            self.inputs,
            self.targets,
            per_sample=True,
            jacobian=self.closed_form,
        )


def run(repeats: int = 50) -> dict[str, float]:
    """Median milliseconds per operation, plus the SciPy comparison (see the module docstring)."""
    learner = paper_sized_learner()
    timed = EpochFromStart(learner)
    optimizer, inputs, targets = timed.optimizer, timed.inputs, timed.targets
    start, start_mu = timed.start, timed.start_mu
    restore, epoch = timed.restore, timed.epoch

    def jacobian() -> None:  # autograd's, as a model without a closed form gets it
        optimizer.jacobian(start, regression_residuals, (inputs, targets), True)

    def closed_form_jacobian() -> None:  # the learner's, at the parameters restore() sets
        timed.closed_form(inputs, targets)

    full_jacobian = optimizer.jacobian(
        start, regression_residuals, (inputs, targets), True
    ).double()
    with torch.no_grad():
        errors = optimizer.residuals(start, regression_residuals, (inputs, targets)).double()

    decay, weights = optimizer.weight_decay, start.double()

    def damped_solve() -> None:
        gradient = full_jacobian.T @ errors + decay * weights
        DampedSolver(full_jacobian, errors, gradient, decay, weights)(start_mu)

    for _ in range(3):  # warm-up
        restore(), epoch(), jacobian(), damped_solve()
    results = {
        "lm_epoch_ms": _median_ms(epoch, repeats, restore),
        "lm_jacobian_ms": _median_ms(jacobian, repeats),
        "lm_closed_form_jacobian_ms": _median_ms(closed_form_jacobian, repeats, restore),
        "lm_gram_and_solve_ms": _median_ms(damped_solve, repeats),
        "torch_threads": float(torch.get_num_threads()),
    }
    learner.epochs_per_call = 10
    snapshot = learner.state_dict()
    observe_s, observe_d = paper_regression(1, np.random.default_rng(1))
    results["observe_10_epochs_ms"] = _median_ms(
        lambda: learner.observe(observe_s[0], float(observe_d[0])),
        max(1, repeats // 5),
        lambda: learner.load_state_dict(snapshot),
    )
    learner.load_state_dict(snapshot)

    scipy_ms, scipy_sse, scipy_jacobians = _scipy_fit(optimizer, inputs, targets, start)
    restore()
    begin = time.perf_counter()
    ours = optimizer.run(
        regression_residuals,
        inputs,
        targets,
        epochs=max(scipy_jacobians, 1),
        per_sample=True,
        jacobian=timed.closed_form,
    )
    results.update(
        scipy_fit_ms=scipy_ms,
        scipy_sse=scipy_sse,
        scipy_jacobians=float(scipy_jacobians),
        lm_same_jacobians_ms=1e3 * (time.perf_counter() - begin),
        lm_same_jacobians_sse=ours.sse,
        start_sse=optimizer.objective(errors, start),
    )
    return results


if __name__ == "__main__":
    for name, value in run().items():
        print(f"{name:>24s}: {value:.6g}")
