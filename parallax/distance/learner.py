"""The egocentric distance learner, paper §3.5–3.5.2, eqs. (9)–(15).

Each new eye-movement vector s (the pan at the end of each lateral position, degrees) is
queued with its target distance (eq. 9). Once the queue holds c vectors, every new s triggers a
warm-started Levenberg–Marquardt fit of the network (eqs. 13–15) on the weighted queue
(eqs. 10–12): ``initial_epochs`` the first time, ``epochs_per_call`` afterwards. Without
``warm_start`` every fit starts from new random weights, for ``initial_epochs``.

Scaling: before each fit the network's [−1, 1] input/target scaling is refitted to the current
(weighted) queue; from the second fit on, with a warm start, the weights are re-expressed so
that the network's function is unchanged by the refit, so the warm start really starts where the
last fit ended. With ``keep_first_scaling`` a warm fit keeps the first fit's scaling instead, as
MATLAB's train keeps the mapminmax settings of the network it configured at its first call.

μ is carried from one fit to the next (the queue changes by one sample); if a fit ended with
μ > mu_max the next one starts again from the initial μ. The reported ``loss`` is the mean
squared error in m² over the queue after the fit (LM itself minimises the sum of squares).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import torch
from torch import Tensor

from parallax.checks import default
from parallax.distance.estimators import ESTIMATORS
from parallax.distance.levenberg_marquardt import LevenbergMarquardt
from parallax.distance.metrics import distance_error_by_range
from parallax.distance.network import DistanceMLP
from parallax.distance.queue_memory import QueueMemory
from parallax.distance.settings import DistanceConfig
from parallax.distance.targets import TargetSource, make_target_source
from parallax.distance.weighting import position_weights, sensitive_positions

STATE_VERSION = 1


def regression_residuals(forward, inputs: Tensor, targets: Tensor) -> Tensor:  # type: ignore[no-untyped-def]
    """The network's errors on a batch, the residuals Levenberg–Marquardt minimises (eq. 15)."""
    return forward(inputs) - targets


class DistanceLearner:
    """Queue memory + weighting + MLP + Levenberg–Marquardt, trained as s vectors arrive."""

    def __init__(
        self,
        lateral_positions: Sequence[float],
        *,
        seed: int,
        queue_size: int = DistanceConfig.queue_size,
        hidden: int = DistanceConfig.hidden,
        weighting: bool = DistanceConfig.weighting,
        y: float = DistanceConfig.y,
        sensitivity: Mapping[str, float] = default(DistanceConfig, "sensitivity"),
        epochs_per_call: int = DistanceConfig.epochs_per_call,
        initial_epochs: int = DistanceConfig.initial_epochs,
        lm: Mapping[str, float] = default(DistanceConfig, "lm"),
        targets: str | TargetSource = DistanceConfig.targets,
        odometry: Mapping[str, float] = default(DistanceConfig, "odometry"),
        fit_from: int | None = DistanceConfig.fit_from,
        input_scaling: str = DistanceConfig.input_scaling,
        validation_fraction: float = DistanceConfig.validation_fraction,
        test_fraction: float = DistanceConfig.test_fraction,
        max_fail: int = DistanceConfig.max_fail,
        reset_mu: bool = DistanceConfig.reset_mu,
        warm_start: bool = DistanceConfig.warm_start,
        keep_first_scaling: bool = DistanceConfig.keep_first_scaling,
        estimator: str = DistanceConfig.estimator,
    ) -> None:
        """The settings are distance.*'s (parallax.config checks them); ``sensitivity``, ``lm``
        and ``odometry`` may give only some of their node's settings, the others keep the
        schema's defaults."""
        self.lateral_positions = [float(value) for value in lateral_positions]
        self.epochs_per_call, self.initial_epochs = int(epochs_per_call), int(initial_epochs)
        self.sensitive = sensitive_positions(self.lateral_positions, **sensitivity)
        flags = self.sensitive if weighting else [False] * len(self.lateral_positions)
        self.weights = torch.tensor(
            position_weights(self.lateral_positions, flags, float(y)), dtype=torch.float64
        )

        self.network = DistanceMLP(
            len(self.lateral_positions),
            hidden,
            input_scaling,
            generator=torch.Generator().manual_seed(int(seed)),
        )
        self.optimizer = LevenbergMarquardt(self.network, **lm)
        self.queue = QueueMemory(queue_size, len(self.lateral_positions))
        self.target_source = make_target_source(targets, odometry)
        self.fit_from = int(queue_size if fit_from is None else fit_from)
        self.validation_fraction = float(validation_fraction)
        self.test_fraction = float(test_fraction)
        self.max_fail, self.reset_mu = int(max_fail), bool(reset_mu)
        self.warm_start, self.keep_first_scaling = bool(warm_start), bool(keep_first_scaling)
        # dividerand's draws, one permutation of the queue per fit
        self.split_generator = torch.Generator().manual_seed(int(seed) + 1)
        # the new weights of each fit without a warm start
        self.init_generator = torch.Generator().manual_seed(int(seed) + 2)
        self.fits = 0
        self.observations = 0
        # what reads a distance from s: the network, or another estimator of the same queue
        self.estimator = ESTIMATORS[estimator](self)

    @property
    def is_ready(self) -> bool:
        """The network has been trained at least once (the queue held ``fit_from`` vectors)."""
        return self.fits > 0

    def _as_inputs(self, s: Tensor | np.ndarray | Sequence[float]) -> Tensor:
        inputs = torch.as_tensor(
            np.asarray(s, dtype=np.float64) if not isinstance(s, Tensor) else s
        )
        inputs = inputs.detach().to(device=self.weights.device, dtype=torch.float64)
        if inputs.shape[-1:] != self.weights.shape or inputs.dim() > 2:
            raise ValueError(
                f"pans must have shape (r,) or (n, r) with r={self.weights.numel()}, "
                f"got {tuple(inputs.shape)}"
            )
        if not bool(torch.isfinite(inputs).all()):
            raise ValueError(
                f"pans must be finite, got {inputs[~torch.isfinite(inputs)][0].item()!r}"
            )
        return inputs

    def observe(
        self, s: Tensor | np.ndarray | Sequence[float], distance: float
    ) -> dict[str, float]:
        """Queue (s, target from ``distance``); fit once the queue is full. Returns floats:

        trained (0/1), loss (MSE in m² over the vectors the fit used, after the fit; NaN before
        the first fit), rmse_m, epochs (accepted LM steps), mu, grad_norm (‖Jᵀe‖ at the last
        epoch), stopped_min_grad, stopped_mu_max, stopped_non_finite, stopped_max_fail (0/1)
        and queue_fill.
        """
        inputs = self._as_inputs(s)
        if inputs.dim() != 1:
            raise ValueError(
                f"observe takes one vector s of shape ({self.weights.numel()},), "
                f"got {tuple(inputs.shape)}"
            )
        return self.observe_batch(inputs[None, :], [distance])

    def observe_batch(
        self, S: Tensor | np.ndarray | Sequence[Sequence[float]], distances: Sequence[float]
    ) -> dict[str, float]:
        """Queue the rows of S in order (as ``observe`` would, one by one), then fit once.

        B robots in lockstep give B vectors s at a time; one fit for all of them is the distance
        learner's counterpart of the policy's mean update and the dictionaries' single step.
        With one row this is exactly ``observe``. Returns the same statistics.
        """
        inputs = self._as_inputs(S)
        if inputs.dim() != 2 or inputs.shape[0] != len(distances):
            raise ValueError(
                f"observe_batch takes S of shape (n, {self.weights.numel()}) and n distances, "
                f"got {tuple(inputs.shape)} and {len(distances)}"
            )
        for row, distance in zip(inputs, distances):
            self.queue.push(row, self.target_source(row, distance))
            self.observations += 1
        stats = {
            "trained": 0.0,
            "loss": math.nan,
            "rmse_m": math.nan,
            "epochs": 0.0,
            "mu": self.optimizer.mu,
            "grad_norm": math.nan,
            "stopped_min_grad": 0.0,
            "stopped_mu_max": 0.0,
            "stopped_non_finite": 0.0,
            "stopped_max_fail": 0.0,
            "queue_fill": float(self.queue.fill),
        }
        if self.queue.fill < self.fit_from:
            return stats
        return {**stats, **self._fit()}

    def _split(self, count: int) -> tuple[Tensor, Tensor]:
        """Training and validation rows of a queue of ``count`` vectors, as MATLAB's
        ``dividerand`` draws them: a random permutation, the validation and test shares
        rounded, training the rest; the test rows are left out of the fit."""
        order = torch.randperm(count, generator=self.split_generator)
        validation = round(self.validation_fraction * count)
        training = count - validation - round(self.test_fraction * count)
        train_rows, validation_rows = order[:training], order[training : training + validation]
        return train_rows.sort().values, validation_rows.sort().values

    def residual_jacobian(self, inputs: Tensor, _targets: Tensor) -> Tensor:
        """The Jacobian of the fit's residuals d(s) − target: the network's own, in closed form
        (what Levenberg–Marquardt is handed instead of autograd's)."""
        return self.network.parameter_jacobian(inputs)

    def _fit(self) -> dict[str, float]:
        """Fits the network to the queue (§3.5.2); the statistics ``observe`` documents."""
        if self.reset_mu or self.optimizer.mu > self.optimizer.mu_max:
            self.optimizer.mu = self.optimizer.initial_mu
        inputs, targets = self.queue.inputs, self.queue.targets
        weighted = inputs * self.weights
        warm = self.is_ready and self.warm_start
        if self.is_ready and not self.warm_start:
            self.network.reset_parameters(self.init_generator)
        if not (warm and self.keep_first_scaling):
            self.network.fit_scaling(weighted, targets, preserve_function=warm)
        epochs = self.epochs_per_call if warm else self.initial_epochs
        fit_inputs, fit_targets, validation = weighted, targets, None
        if self.validation_fraction or self.test_fraction:
            train_rows, validation_rows = (
                rows.to(targets.device) for rows in self._split(targets.numel())
            )
            fit_inputs, fit_targets = weighted[train_rows], targets[train_rows]
            if validation_rows.numel():
                check_inputs, check_targets = weighted[validation_rows], targets[validation_rows]

                def validation() -> float:
                    with torch.no_grad():
                        errors = regression_residuals(self.network, check_inputs, check_targets)
                    return float(errors.square().sum())

        result = self.optimizer.run(
            regression_residuals,
            fit_inputs,
            fit_targets,
            epochs=epochs,
            per_sample=True,
            validation=validation,
            max_fail=self.max_fail,
            jacobian=self.residual_jacobian,
        )
        self.fits += 1
        mse = result.sse / targets.numel()
        if self.optimizer.weight_decay or fit_targets is not targets:
            # result.sse holds λ‖w‖² too, or covers the training rows only: report the data's
            # error over the whole queue
            with torch.no_grad():
                mse = float(regression_residuals(self.network, weighted, targets).square().mean())
        return dict(
            trained=1.0,
            loss=mse,
            rmse_m=math.sqrt(mse),
            epochs=float(result.epochs),
            mu=result.mu,
            grad_norm=result.grad_norm,
            stopped_min_grad=float(result.stop == "min_grad"),
            stopped_mu_max=float(result.stop == "mu_max"),
            stopped_non_finite=float(result.stop == "non_finite_jacobian"),
            stopped_max_fail=float(result.stop == "max_fail"),
        )

    def predict(self, S: Tensor | np.ndarray | Sequence[Sequence[float]]) -> Tensor | np.ndarray:
        """(n, r) pans in degrees → (n,) metres (or (r,) → a scalar), as the run's estimator
        (distance.estimator) reads them.

        Returns a float64 tensor for a tensor input, a NumPy array otherwise.
        """
        if not self.is_ready:
            raise RuntimeError(
                f"distance learner is not ready (queue {self.queue.fill}/{self.queue.capacity}, "
                f"{self.fits} fits); check is_ready before predict"
            )
        distances = self.estimator.predict(self._as_inputs(S))
        return distances.to(S.device) if isinstance(S, Tensor) else distances.cpu().numpy()

    def queue_error(self) -> dict[str, float]:
        """The network scored on its own queue S: |d̂ − d|/d in % per range of Tables 4–5.

        The paper names no held-out set for Tables 4–5 (§4.1: "we test the depth cue … from 3 to
        10 meters with 0.1 meter interval"), and in half of its rows the printed total is not
        the mean over the 71 grid distances, as it is for a random sample of them such as the
        queue; this is that probable protocol. Empty before the first fit, and when the targets
        are not the panels' distances (odometry).
        """
        found = self.queue_predictions()
        return {} if found is None else distance_error_by_range(*found)

    def queue_predictions(self) -> tuple[Tensor, Tensor] | None:
        """The network's answers for the vectors of its queue, and their distances (what
        :meth:`queue_error` scores); None where it has none to score."""
        if not self.is_ready or self.target_source.walks:
            return None
        return self.predict(self.queue.inputs), self.queue.targets

    def to(self, device: torch.device | str) -> DistanceLearner:
        """Moves the network, the queue and the input weights to ``device`` (in place; returns
        self).

        Fits then run there; ``observe`` and ``predict`` accept inputs on any device.
        """
        self.weights = self.weights.to(device)
        self.network.to(device)  # parameters keep their identity, so the optimizer still holds them
        self.queue.to(device)
        return self

    def state_dict(self) -> dict[str, object]:
        """Everything needed to resume bit-identically (tensors are copies)."""
        return {
            "version": STATE_VERSION,
            "shape": {
                "inputs": self.weights.numel(),
                "queue_size": self.queue.capacity,
                "hidden": self.network.hidden_layer.out_features,
            },
            "weights": self.weights.clone(),
            "network": {k: v.clone() for k, v in self.network.state_dict().items()},
            "queue": self.queue.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "targets": self.target_source.state_dict(),
            "fits": self.fits,
            "observations": self.observations,
            "split_generator": self.split_generator.get_state(),
            # only a learner without a warm start draws from it
            **({} if self.warm_start else {"init_generator": self.init_generator.get_state()}),
        }

    def load_state_dict(self, state: Mapping[str, object]) -> None:
        if state.get("version") != STATE_VERSION:
            raise ValueError(
                f"distance learner state version {state.get('version')!r}, expected {STATE_VERSION}"
            )
        shape = {
            "inputs": self.weights.numel(),
            "queue_size": self.queue.capacity,
            "hidden": self.network.hidden_layer.out_features,
        }
        if state["shape"] != shape:
            raise ValueError(
                f"distance learner state is for {state['shape']!r}, this learner is {shape!r}"
            )
        if not torch.equal(torch.as_tensor(state["weights"]).cpu(), self.weights.cpu()):
            raise ValueError(
                f"state was saved with input weights {state['weights']!r}, this learner uses "
                f"{self.weights!r} (different L, y or sensitivity)"
            )
        self.network.load_state_dict(state["network"])  # type: ignore[arg-type]
        self.queue.load_state_dict(state["queue"])  # type: ignore[arg-type]
        self.optimizer.load_state_dict(state["optimizer"])  # type: ignore[arg-type]
        self.target_source.load_state_dict(state["targets"])  # type: ignore[arg-type]
        if "split_generator" in state:  # a learner that never splits may be saved without it
            self.split_generator.set_state(state["split_generator"])  # type: ignore[arg-type]
        if "init_generator" in state:
            self.init_generator.set_state(state["init_generator"])  # type: ignore[arg-type]
        self.fits = int(state["fits"])  # type: ignore[arg-type]
        self.observations = int(state["observations"])  # type: ignore[arg-type]
