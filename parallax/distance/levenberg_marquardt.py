"""Levenberg–Marquardt optimiser for small torch modules (paper §3.5, ref. [33]).

The paper trains its distance network (eqs. 13–15) with MATLAB's ``trainlm``; this is that
algorithm for any small ``nn.Module``. Each epoch evaluates the residuals e and their dense
Jacobian J (``torch.func.jacrev`` over ``functional_call``), then tries damped Gauss–Newton steps
(JᵀJ + μI)Δ = −Jᵀe in float64 with μ adapted as ``trainlm`` does: a step is taken only if it
lowers the sum of squared residuals (then μ ← μ·mu_decrease), otherwise it is thrown away and
μ ← μ·mu_increase, until μ exceeds mu_max. Training stops at max epochs, when ‖Jᵀe‖ < min_grad,
or when μ > mu_max. Non-finite steps or residuals count as failed steps, and a non-finite
Jacobian stops the epoch without a step, so NaN/inf never reach the parameters.

Beyond ``trainlm``, ``weight_decay`` λ > 0 minimises Σe² + λ‖w‖² over the parameters w: the
Gauss–Newton model of that sum gives the steps (JᵀJ + λI + μI)Δ = −(Jᵀe + λw), and a step is
taken only if it lowers Σe² + λ‖w‖² (the sum of squares of e and √λ·w, without forming those
P extra rows).

The residuals come from a closure ``closure(forward, *batch) -> residuals`` where ``forward``
calls the model with the candidate parameters: ``lambda forward, x, y: forward(x) - y``. With
``per_sample=True`` the rows of ``batch`` are independent samples and the Jacobian is built one
sample at a time under ``vmap`` (cheaper than a full ``jacrev`` for the distance network). A
model that knows its Jacobian in closed form hands it over as ``jacobian(*batch) -> (m, P)``,
the Jacobian of the residuals, and autograd is not called.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor, nn
from torch.func import functional_call, jacrev, vmap

from parallax.distance.settings import LevenbergMarquardtConfig

#: ``closure(forward, *batch)`` returns the residual tensor (any shape; it is flattened).
ResidualClosure = Callable[..., Tensor]

#: ``jacobian(*batch)`` returns the residuals' Jacobian, (number of residuals, parameters), in
#: the order of the model's ``named_parameters()``.
JacobianFunction = Callable[..., Tensor]

#: μ is never decreased below this, so JᵀJ + μI stays positive definite in float64.
MU_FLOOR = 1e-20


@dataclass(frozen=True)
class LMStepResult:
    """Outcome of one epoch: ``sse`` is Σe² (+ λ‖w‖²) at the parameters held after the epoch,
    ``grad_norm`` ‖Jᵀe (+ λw)‖ where the epoch started."""

    accepted: bool
    sse: float
    grad_norm: float
    mu: float
    stop: str  # "" (go on), "min_grad", "mu_max" or "non_finite_jacobian"


@dataclass(frozen=True)
class LMRunResult:
    """Outcome of ``run``: ``epochs`` counts accepted steps."""

    epochs: int
    sse: float
    grad_norm: float
    mu: float
    stop: str  # as LMStepResult.stop, or "max_fail"; "" means the epoch budget ran out


class LevenbergMarquardt:
    """``trainlm``-style Levenberg–Marquardt over the trainable parameters of ``model``."""

    def __init__(
        self,
        model: nn.Module,
        *,
        mu: float = LevenbergMarquardtConfig.mu,
        mu_decrease: float = LevenbergMarquardtConfig.mu_decrease,
        mu_increase: float = LevenbergMarquardtConfig.mu_increase,
        mu_max: float = LevenbergMarquardtConfig.mu_max,
        min_grad: float = LevenbergMarquardtConfig.min_grad,
        max_params: int = LevenbergMarquardtConfig.max_params,
        max_jacobian_elements: int = LevenbergMarquardtConfig.max_jacobian_elements,
        weight_decay: float = LevenbergMarquardtConfig.weight_decay,
    ) -> None:
        """The options are distance.lm's (parallax.config checks their ranges)."""
        self.model = model
        self.weight_decay = float(weight_decay)
        self.initial_mu = float(mu)
        self.mu_decrease = float(mu_decrease)
        self.mu_increase = float(mu_increase)
        self.mu_max = float(mu_max)
        self.min_grad = float(min_grad)
        self.max_jacobian_elements = int(max_jacobian_elements)
        self.mu = self.initial_mu

        self._names = [name for name, p in model.named_parameters() if p.requires_grad]
        params = dict(model.named_parameters())
        self._params = [params[name] for name in self._names]
        self.num_params = sum(p.numel() for p in self._params)
        if self.num_params == 0:
            raise ValueError(f"{type(model).__name__} has no trainable parameters to optimise")
        if self.num_params > int(max_params):
            raise ValueError(
                f"{type(model).__name__} has {self.num_params} trainable parameters, more than "
                f"max_params={max_params}: a dense Levenberg–Marquardt step needs a "
                f"{self.num_params}×{self.num_params} matrix; use a first-order optimiser instead"
            )

    # -- parameters as one flat vector ------------------------------------------------------
    def flat_parameters(self) -> Tensor:
        """The trainable parameters as one flat vector (a copy)."""
        return torch.cat([p.detach().reshape(-1) for p in self._params])

    def _unflatten(self, flat: Tensor) -> dict[str, Tensor]:
        parts = flat.split([p.numel() for p in self._params])
        return {name: part.view(p.shape) for name, part, p in zip(self._names, parts, self._params)}

    def set_flat_parameters(self, flat: Tensor) -> None:
        """Write the flat vector ``flat`` into the model's trainable parameters."""
        with torch.no_grad():
            for param, value in zip(self._params, self._unflatten(flat).values()):
                param.copy_(value)

    def residuals(
        self, flat: Tensor, closure: ResidualClosure, batch: tuple[Tensor, ...]
    ) -> Tensor:
        """``closure``'s residuals on ``batch`` with the parameters ``flat``, as one vector."""
        params = self._unflatten(flat)

        def forward(*args: object, **kwargs: object) -> Tensor:
            return functional_call(self.model, params, args, kwargs)

        return closure(forward, *batch).reshape(-1)

    def objective(self, errors: Tensor, flat: Tensor) -> float:
        """Σe² + λ‖w‖² in float64 for the residuals ``errors`` at the parameters ``flat``."""
        sse = errors.double().square().sum()
        if self.weight_decay:
            sse = sse + self.weight_decay * flat.double().square().sum()
        return float(sse)

    def jacobian(
        self, flat: Tensor, closure: ResidualClosure, batch: tuple[Tensor, ...], per_sample: bool
    ) -> Tensor:
        """The residuals' Jacobian at ``flat`` (residuals × parameters) by autograd;
        ``per_sample``: one sample at a time, for residuals that each depend on one sample only."""
        if not per_sample:
            return jacrev(lambda f: self.residuals(f, closure, batch))(flat)

        def one_sample(f: Tensor, *sample: Tensor) -> Tensor:
            params = self._unflatten(f)

            def forward(*args: object, **kwargs: object) -> Tensor:
                return functional_call(self.model, params, args, kwargs)

            return closure(forward, *(t.unsqueeze(0) for t in sample)).reshape(-1)

        in_dims = (None,) + (0,) * len(batch)
        return vmap(jacrev(one_sample), in_dims=in_dims)(flat, *batch).reshape(-1, self.num_params)

    # -- the algorithm ------------------------------------------------------------------------
    def step(
        self,
        closure: ResidualClosure,
        *batch: Tensor,
        per_sample: bool = False,
        jacobian: JacobianFunction | None = None,
    ) -> LMStepResult:
        """One epoch: a Jacobian (``jacobian(*batch)`` when given, else autograd's), then damped
        steps until one lowers Σe² (+ λ‖w‖²) or μ > mu_max."""
        if per_sample and (not batch or len({t.shape[0] for t in batch}) != 1):
            raise ValueError(
                "per_sample=True needs batch tensors that share their first dimension, "
                f"got shapes {[tuple(t.shape) for t in batch]}"
            )
        flat = self.flat_parameters()
        with torch.no_grad():
            residuals = self.residuals(flat, closure, batch)
        if not bool(torch.isfinite(residuals).all()):
            raise ValueError("residuals at the current parameters are not finite; check the data")
        sse = self.objective(residuals, flat)
        if self.mu > self.mu_max:
            return LMStepResult(False, sse, math.nan, self.mu, "mu_max")
        jacobian_elements = residuals.numel() * self.num_params
        if jacobian_elements > self.max_jacobian_elements:
            raise ValueError(
                f"Jacobian of {residuals.numel()} residuals × {self.num_params} parameters = "
                f"{jacobian_elements} elements exceeds "
                f"max_jacobian_elements={self.max_jacobian_elements}"
            )

        if jacobian is None:  # autograd's
            matrix = self.jacobian(flat, closure, batch, per_sample).double()
        else:  # the model's own
            matrix = jacobian(*batch).double()
        errors = residuals.double()
        gradient = matrix.T @ errors
        weights = flat.double()
        if self.weight_decay:
            gradient = gradient + self.weight_decay * weights
        grad_norm = float(torch.linalg.vector_norm(gradient))
        if not math.isfinite(grad_norm):  # e.g. exp() overflowing in the derivative only
            return LMStepResult(False, sse, grad_norm, self.mu, "non_finite_jacobian")
        if grad_norm < self.min_grad:
            return LMStepResult(False, sse, grad_norm, self.mu, "min_grad")

        solve = DampedSolver(matrix, errors, gradient, self.weight_decay, weights)
        while self.mu <= self.mu_max:
            delta = solve(self.mu)
            if delta is not None:
                candidate = flat + delta.to(flat.dtype)
                with torch.no_grad():
                    candidate_residuals = self.residuals(candidate, closure, batch)
                candidate_sse = self.objective(candidate_residuals, candidate)
                if math.isfinite(candidate_sse) and candidate_sse < sse:
                    self.set_flat_parameters(candidate)
                    self.mu = max(self.mu * self.mu_decrease, MU_FLOOR)
                    return LMStepResult(True, candidate_sse, grad_norm, self.mu, "")
            self.mu *= self.mu_increase
        return LMStepResult(False, sse, grad_norm, self.mu, "mu_max")

    def run(
        self,
        closure: ResidualClosure,
        *batch: Tensor,
        epochs: int,
        per_sample: bool = False,
        validation: Callable[[], float] | None = None,
        max_fail: int | None = None,
        jacobian: JacobianFunction | None = None,
    ) -> LMRunResult:
        """Up to ``epochs`` epochs; stops early at min_grad or mu_max.

        With ``validation`` (the validation samples' error at the current parameters) it stops
        as MATLAB's ``train`` does: after ``max_fail`` epochs in a row whose validation error
        rose above the best so far (stop "max_fail"), and leaves the parameters at the epoch
        with the lowest validation error.
        """
        if int(epochs) != epochs or epochs < 1:
            raise ValueError(f"epochs must be a positive integer, got {epochs!r}")
        if validation is not None and (max_fail is None or max_fail < 1):
            raise ValueError(f"a validation stop needs max_fail ≥ 1, got {max_fail!r}")
        accepted = 0
        result = None
        if validation is not None:
            best_error, best_flat, fails = validation(), self.flat_parameters(), 0
        for _ in range(int(epochs)):
            result = self.step(closure, *batch, per_sample=per_sample, jacobian=jacobian)
            accepted += int(result.accepted)
            if validation is not None and result.accepted:
                error = validation()
                if error < best_error:
                    best_error, best_flat, fails = error, self.flat_parameters(), 0
                elif error > best_error:
                    fails += 1
                if fails >= max_fail:
                    result = LMStepResult(True, result.sse, result.grad_norm, self.mu, "max_fail")
            if result.stop:
                break
        assert result is not None
        if validation is not None:
            self.set_flat_parameters(best_flat)
        return LMRunResult(accepted, result.sse, result.grad_norm, self.mu, result.stop)

    def state_dict(self) -> dict[str, float]:
        return {"mu": self.mu}

    def load_state_dict(self, state: dict[str, float]) -> None:
        mu = float(state["mu"])
        if not mu > 0:
            raise ValueError(f"mu in a Levenberg–Marquardt state must be positive, got {mu!r}")
        self.mu = mu


class DampedSolver:
    """Solves (JᵀJ + (λ + μ)I)Δ = −g, g = Jᵀe + λw, for successive μ, factorising the smaller
    Gram matrix (λ = ``decay``, w = ``weights``; λ = 0: the plain step −(JᵀJ + μI)⁻¹Jᵀe).

    With fewer residuals m than parameters P (the distance network: 100 or 300 vs 541) the step
    comes from an m×m Cholesky factorisation. With ν = λ + μ, (JᵀJ + νI)⁻¹Jᵀ = Jᵀ(JJᵀ + νI)⁻¹
    and (JᵀJ + νI)⁻¹ = (I − Jᵀ(JJᵀ + νI)⁻¹J)/ν give
    Δ = −Jᵀ(JJᵀ + νI)⁻¹(e − (λ/ν)·Jw) − (λ/ν)·w.
    """

    def __init__(
        self,
        jacobian: Tensor,
        errors: Tensor,
        gradient: Tensor,
        decay: float = 0.0,
        weights: Tensor | None = None,
    ) -> None:
        self.jacobian, self.errors, self.gradient = jacobian, errors, gradient
        self.decay, self.weights = float(decay), weights
        self.dual = jacobian.shape[0] < jacobian.shape[1]
        self.gram = jacobian @ jacobian.T if self.dual else jacobian.T @ jacobian
        self.eye = torch.eye(self.gram.shape[0], dtype=self.gram.dtype, device=self.gram.device)
        if self.dual and self.decay:
            self.jacobian_weights = jacobian @ weights

    def __call__(self, mu: float) -> Tensor | None:
        """The step for this μ, or None when the factorisation fails or the step is not finite."""
        damping = self.decay + mu
        factor, info = torch.linalg.cholesky_ex(self.gram + damping * self.eye)
        if int(info) != 0:
            return None
        if not self.dual:
            delta = -torch.cholesky_solve(self.gradient.unsqueeze(-1), factor).squeeze(-1)
        elif not self.decay:
            delta = -(
                self.jacobian.T @ torch.cholesky_solve(self.errors.unsqueeze(-1), factor)
            ).squeeze(-1)
        else:
            share = self.decay / damping
            right = (self.errors - share * self.jacobian_weights).unsqueeze(-1)
            delta = -(self.jacobian.T @ torch.cholesky_solve(right, factor)).squeeze(-1)
            delta = delta - share * self.weights
        return delta if bool(torch.isfinite(delta).all()) else None
