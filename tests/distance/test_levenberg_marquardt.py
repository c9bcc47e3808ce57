"""Levenberg–Marquardt optimiser (paper §3.5, trainlm): against MINPACK, against Adam, safety."""

from __future__ import annotations

import math
import statistics

import numpy as np
import pytest
import torch
from scipy.optimize import least_squares
from torch import nn

from parallax.distance import DistanceMLP, LevenbergMarquardt
from parallax.distance.levenberg_marquardt import DampedSolver
from parallax.tools.analysis.synthetic_pans import PAPER_LATERAL_POSITIONS_M, paper_regression


def trainlm(model: nn.Module, **settings) -> LevenbergMarquardt:
    """MATLAB trainlm's optimiser: the numbers below are taken without the weight decay that
    LevenbergMarquardt's default (the recipe's) adds."""
    return LevenbergMarquardt(model, **{"weight_decay": 0.0, **settings})


def regression(forward, inputs, targets):
    return forward(inputs) - targets


def scaled_network(
    inputs: torch.Tensor, targets: torch.Tensor, hidden: int, seed: int
) -> DistanceMLP:
    network = DistanceMLP(inputs.shape[1], hidden, generator=torch.Generator().manual_seed(seed))
    network.fit_scaling(inputs, targets, preserve_function=False)
    return network


def minpack_sse(
    optimizer: LevenbergMarquardt, inputs: torch.Tensor, targets: torch.Tensor
) -> float:
    """SSE that SciPy's MINPACK reaches from the optimiser's current parameters (left unchanged)."""
    batch = (inputs, targets)

    def residuals(flat):
        with torch.no_grad():
            return optimizer.residuals(torch.from_numpy(flat), regression, batch).numpy()

    def jacobian(flat):
        return optimizer.jacobian(torch.from_numpy(flat), regression, batch, True).numpy()

    solution = least_squares(
        residuals,
        optimizer.flat_parameters().numpy().copy(),
        jac=jacobian,
        method="lm",
        max_nfev=5000,
    )
    assert solution.status > 0, solution.message
    return 2.0 * float(solution.cost)


def test_matches_minpack_from_the_same_start_teacher_student():
    """Data from a 2-3-1 network plus noise, both optimisers started from the same nearby point."""
    rng = np.random.default_rng(0)
    inputs = torch.from_numpy(rng.uniform(-1.0, 1.0, size=(200, 2)))
    teacher = DistanceMLP(2, 3, generator=torch.Generator().manual_seed(11))
    with torch.no_grad():
        targets = teacher(inputs) + torch.from_numpy(rng.normal(0.0, 0.05, size=200))
    student = DistanceMLP(2, 3)
    student.load_state_dict(teacher.state_dict())
    with torch.no_grad():
        for parameter in student.parameters():
            parameter.add_(0.05 * torch.from_numpy(rng.normal(size=tuple(parameter.shape))))
    optimizer = trainlm(student)
    reference = minpack_sse(optimizer, inputs, targets)
    result = optimizer.run(regression, inputs, targets, epochs=300, per_sample=True)
    assert result.stop == "min_grad"
    assert result.sse <= 1.01 * reference


def test_matches_minpack_on_the_paper_regression_for_most_starts():
    """One lateral position, 2 hidden units: non-convex, so ask it of the median of 5 starts."""
    ratios = []
    for seed in range(5):
        pans, distances = paper_regression(
            100, np.random.default_rng(seed), lateral_positions_m=[0.10]
        )
        inputs, targets = torch.from_numpy(pans), torch.from_numpy(distances)
        optimizer = trainlm(scaled_network(inputs, targets, hidden=2, seed=seed))
        reference = minpack_sse(optimizer, inputs, targets)
        ratios.append(
            optimizer.run(regression, inputs, targets, epochs=300, per_sample=True).sse / reference
        )
    assert statistics.median(ratios) <= 1.01, ratios


def test_fits_better_in_30_epochs_than_adam_in_2000_steps():
    """The paper's reason for Levenberg–Marquardt (§3.5.2): a second-order step per epoch.
    Counted in steps, not in seconds, so that a busy machine cannot change the verdict."""
    pans, distances = paper_regression(300, np.random.default_rng(0))
    inputs, targets = torch.from_numpy(pans), torch.from_numpy(distances)
    lm_network = scaled_network(inputs, targets, hidden=30, seed=0)
    adam_network = scaled_network(inputs, targets, hidden=30, seed=0)
    trainlm(lm_network).run(regression, inputs, targets, epochs=30, per_sample=True)
    lm_sse = float((lm_network(inputs) - targets).detach().square().sum())
    adam = torch.optim.Adam(adam_network.parameters(), lr=1e-2)
    for _ in range(2000):
        adam.zero_grad()
        loss = (adam_network(inputs) - targets).square().mean()
        loss.backward()
        adam.step()
    adam_sse = float((adam_network(inputs) - targets).detach().square().sum())
    assert math.isfinite(lm_sse) and lm_sse < adam_sse, (lm_sse, adam_sse)


def test_per_sample_jacobian_equals_full_jacobian():
    pans, distances = paper_regression(
        20, np.random.default_rng(1), lateral_positions_m=PAPER_LATERAL_POSITIONS_M[:4]
    )
    inputs, targets = torch.from_numpy(pans), torch.from_numpy(distances)
    optimizer = trainlm(scaled_network(inputs, targets, hidden=5, seed=1))
    flat = optimizer.flat_parameters()
    per_sample = optimizer.jacobian(flat, regression, (inputs, targets), True)
    full = optimizer.jacobian(flat, regression, (inputs, targets), False)
    assert per_sample.shape == (20, optimizer.num_params)
    torch.testing.assert_close(per_sample, full, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    ("inputs", "hidden", "rows", "scaling"),
    [(16, 30, 240, "per_input"), (6, 30, 100, "none"), (2, 4, 3, "global"), (11, 30, 1, "none")],
)
def test_the_networks_closed_form_jacobian_is_autograds_bit_for_bit(inputs, hidden, rows, scaling):
    generator = torch.Generator().manual_seed(inputs * rows)
    pans = 3 * torch.randn(rows, inputs, generator=generator, dtype=torch.float64) + 5
    distances = 7 * torch.rand(rows, generator=generator, dtype=torch.float64) + 3
    network = DistanceMLP(inputs, hidden, input_scaling=scaling, generator=generator)
    if rows > 1:
        network.fit_scaling(pans, distances, preserve_function=False)
    optimizer = trainlm(network)
    flat = optimizer.flat_parameters()
    autograd = optimizer.jacobian(flat, regression, (pans, distances), True)
    assert torch.equal(network.parameter_jacobian(pans), autograd)
    # so a fit that is handed it takes the same steps as one that differentiates
    fits = []
    for closed_form in (False, True):
        model = DistanceMLP(inputs, hidden, input_scaling=scaling)
        model.load_state_dict(network.state_dict())
        jacobian = (lambda x, _, m=model: m.parameter_jacobian(x)) if closed_form else None
        trainlm(model).run(
            regression, pans, distances, epochs=5, per_sample=True, jacobian=jacobian
        )
        fits.append(torch.cat([p.detach().reshape(-1) for p in model.parameters()]))
    assert torch.equal(*fits)


def test_dual_and_primal_steps_agree():
    generator = torch.Generator().manual_seed(0)
    jacobian = torch.randn(30, 50, generator=generator, dtype=torch.float64)
    errors = torch.randn(30, generator=generator, dtype=torch.float64)
    dual = DampedSolver(jacobian, errors, jacobian.T @ errors)
    assert dual.dual
    gram = jacobian.T @ jacobian + 0.5 * torch.eye(50, dtype=torch.float64)
    primal_step = -torch.linalg.solve(gram, jacobian.T @ errors)
    torch.testing.assert_close(dual(0.5), primal_step, rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("rows", [30, 80])
def test_weight_decay_steps_are_the_extra_rows_steps(rows):
    # λ on the diagonal, in the dual (30 < 50 parameters) and the primal form (80 > 50): the
    # step of the sum of squares of e and √λ·w, i.e. of the rows [J; √λ·I] and [e; √λ·w]
    generator = torch.Generator().manual_seed(rows)
    jacobian = torch.randn(rows, 50, generator=generator, dtype=torch.float64)
    errors = torch.randn(rows, generator=generator, dtype=torch.float64)
    weights = torch.randn(50, generator=generator, dtype=torch.float64)
    decay, mu = 0.1, 1e-3
    solver = DampedSolver(jacobian, errors, jacobian.T @ errors + decay * weights, decay, weights)
    assert solver.dual == (rows < 50)
    root = math.sqrt(decay)
    stacked = torch.cat([jacobian, root * torch.eye(50, dtype=torch.float64)])
    stacked_errors = torch.cat([errors, root * weights])
    gram = stacked.T @ stacked + mu * torch.eye(50, dtype=torch.float64)
    expected = -torch.linalg.solve(gram, stacked.T @ stacked_errors)
    torch.testing.assert_close(solver(mu), expected, rtol=1e-9, atol=1e-10)


def test_works_for_another_small_module_in_float32():
    inputs = torch.linspace(-3, 3, 64).unsqueeze(-1)
    targets = torch.sin(inputs).squeeze(-1)
    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(1, 8), nn.Tanh(), nn.Linear(8, 1))
    optimizer = trainlm(model)
    start = float((model(inputs).squeeze(-1) - targets).detach().square().sum())
    result = optimizer.run(
        lambda forward, x, y: forward(x).squeeze(-1) - y, inputs, targets, epochs=100
    )
    assert result.sse < 1e-3 * start
    assert all(p.dtype == torch.float32 and torch.isfinite(p).all() for p in model.parameters())


def test_linear_problem_stops_at_min_grad():
    model = nn.Linear(2, 1, dtype=torch.float64)
    inputs = torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, -1.0]], dtype=torch.float64)
    targets = inputs @ torch.tensor([2.0, -3.0], dtype=torch.float64) + 0.5
    optimizer = trainlm(model)
    result = optimizer.run(
        lambda forward, x, y: forward(x).squeeze(-1) - y, inputs, targets, epochs=50
    )
    assert result.stop == "min_grad" and result.epochs < 10
    torch.testing.assert_close(
        model.weight.detach(), torch.tensor([[2.0, -3.0]], dtype=torch.float64)
    )


def test_failed_steps_are_rejected_and_mu_grows():
    """Any move away from the start gives NaN residuals: every step must be thrown away."""
    model = nn.Linear(1, 1, bias=False, dtype=torch.float64)
    start = model.weight.detach().clone()
    inputs = torch.ones(3, 1, dtype=torch.float64)

    def poisoned(forward, x):
        prediction = forward(x).squeeze(-1)
        moved = (prediction - float(start)).abs() > 0
        return torch.where(moved, torch.full_like(prediction, math.nan), prediction - 5.0)

    optimizer = trainlm(model, mu=1e-3, mu_max=1.0)
    result = optimizer.step(poisoned, inputs)
    assert not result.accepted and result.stop == "mu_max"
    assert optimizer.mu == pytest.approx(10.0)  # tried 1e-3, 1e-2, 1e-1, 1 and gave up at 10
    assert torch.equal(model.weight.detach(), start)
    assert optimizer.step(poisoned, inputs).stop == "mu_max"  # and stays stopped


def test_overflow_never_reaches_the_parameters():
    """exp() of a large input: the residuals or the Jacobian overflow after the first steps."""
    model = nn.Linear(1, 1, dtype=torch.float64)
    with torch.no_grad():
        model.weight.fill_(0.0), model.bias.fill_(0.0)
    inputs = torch.full((4, 1), 800.0, dtype=torch.float64)
    targets = torch.full((4,), 1e150, dtype=torch.float64)
    optimizer = trainlm(model, mu=1e-6)
    result = optimizer.run(
        lambda forward, x, y: torch.exp(forward(x).squeeze(-1)) - y, inputs, targets, epochs=50
    )
    assert all(torch.isfinite(p).all() for p in model.parameters())
    assert result.stop in {"mu_max", "non_finite_jacobian", "min_grad"}
    assert math.isfinite(result.sse)


def test_nan_jacobian_gives_no_step():
    jacobian = torch.full((3, 2), math.nan, dtype=torch.float64)
    errors = torch.ones(3, dtype=torch.float64)
    assert DampedSolver(jacobian, errors, jacobian.T @ errors)(1e-3) is None


def test_refuses_a_model_too_large_for_a_dense_jacobian():
    with pytest.raises(ValueError, match="10100 trainable parameters"):
        trainlm(nn.Linear(100, 100), max_params=5000)
    optimizer = trainlm(nn.Linear(4, 1), max_jacobian_elements=100)
    with pytest.raises(ValueError, match="max_jacobian_elements"):
        optimizer.step(lambda forward, x: forward(x).squeeze(-1), torch.ones(50, 4))


def test_rejects_bad_data():
    # the options' ranges are parallax.config's (tests/config/test_bad_input.py: distance.lm.*)
    optimizer = trainlm(nn.Linear(2, 1))
    with pytest.raises(ValueError, match="not finite"):
        optimizer.step(lambda forward, x: forward(x).squeeze(-1), torch.full((3, 2), math.inf))
    with pytest.raises(ValueError, match="epochs"):
        optimizer.run(lambda forward, x: forward(x).squeeze(-1), torch.ones(3, 2), epochs=0)


@pytest.mark.parametrize("per_sample", [False, True])
def test_weight_decay_finds_the_ridge_solution(per_sample):
    # Beyond trainlm: Σe² + λ‖w‖² (bias included). For a linear model that is ridge regression,
    # whose minimiser has a closed form.
    generator = torch.Generator().manual_seed(5)
    inputs = torch.randn(12, 3, generator=generator, dtype=torch.float64)
    targets = inputs @ torch.tensor([1.5, -2.0, 0.5], dtype=torch.float64) + 0.3
    targets = targets + 0.1 * torch.randn(12, generator=generator, dtype=torch.float64)
    decay = 2.0
    model = nn.Linear(3, 1, dtype=torch.float64)
    optimizer = trainlm(model, weight_decay=decay)
    result = optimizer.run(
        lambda forward, x, y: forward(x).squeeze(-1) - y,
        inputs,
        targets,
        epochs=50,
        per_sample=per_sample,
    )
    design = torch.cat([inputs, torch.ones(12, 1, dtype=torch.float64)], dim=1)
    ridge = torch.linalg.solve(
        design.T @ design + decay * torch.eye(4, dtype=torch.float64), design.T @ targets
    )
    torch.testing.assert_close(
        torch.cat([model.weight.detach().reshape(-1), model.bias.detach()]),
        ridge,
        rtol=1e-6,
        atol=1e-6,
    )
    # the objective at the parameters the fit ended with (which equal the ridge's to 1e-6 only)
    weights = torch.cat([model.weight.detach().reshape(-1), model.bias.detach()])
    data_sse = float((model(inputs).squeeze(-1) - targets).detach().square().sum())
    assert result.sse == pytest.approx(data_sse + decay * float(weights.square().sum()), rel=1e-9)


def test_validation_stop_keeps_the_best_epochs_parameters():
    """MATLAB train's early stop: after max_fail rising validation errors the fit ends, with the
    parameters of the epoch whose validation error was lowest."""
    rng = np.random.default_rng(3)
    inputs = torch.from_numpy(rng.uniform(-1, 1, (60, 2)))
    targets = torch.sin(3 * inputs[:, 0]) + 0.3 * torch.from_numpy(rng.normal(size=60))
    fit_inputs, fit_targets = inputs[:20], targets[:20]  # few, noisy: it overfits
    check_inputs, check_targets = inputs[20:], targets[20:]
    network = scaled_network(inputs, targets, hidden=8, seed=1)
    optimizer = trainlm(network)
    seen = []

    def validation() -> float:
        with torch.no_grad():
            error = float((network(check_inputs) - check_targets).square().sum())
        seen.append(error)
        return error

    result = optimizer.run(
        regression, fit_inputs, fit_targets, epochs=500, validation=validation, max_fail=3
    )
    assert result.stop == "max_fail"
    best = min(seen)
    assert seen.index(best) < len(seen) - 3  # three rises in a row after the best
    assert all(error > best for error in seen[-3:])
    with torch.no_grad():
        kept = float((network(check_inputs) - check_targets).square().sum())
    assert kept == best
