"""The egocentric distance network, paper §3.5.2, eqs. (13)–(15), Fig. 6.

s (r pans, degrees) → 30 sigmoid units → one linear unit → distance (metres). Like a MATLAB
network (mapminmax), inputs and targets are mapped to [−1, 1] inside the module, so callers
never pre-scale. The scaling lives in buffers and is fitted by ``fit_scaling``; refitting it
can re-express the weights so that the network's function is unchanged (a true warm start).

Input scaling, the three a MATLAB network allows:

- ``"global"`` (default): one min/max over all of S, so the row weights of eqs. (11)–(12) survive
  normalisation;
- ``"per_input"``: MATLAB's per-row mapminmax, which undoes any constant row weight (the
  weighting then has no effect at all);
- ``"none"``: no input processing (a network whose ``inputs{1}.processFcns`` is empty). The pans
  enter as they are; only a new network's initialisation sees their ranges, as MATLAB's
  ``initnw`` spreads the Nguyen–Widrow weights over each input's range. A constant row weight
  then changes the fit through the optimiser's damping, not through the scaling.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from parallax.distance.settings import DistanceConfig


def minmax_gain_offset(values: Tensor, dim: int | None) -> tuple[Tensor, Tensor]:
    """Gain and offset of mapminmax to [−1, 1]: x ↦ gain·x + offset, reduced over ``dim``.

    A constant column (or an all-zero S) gets gain 1 and is centred on 0, so it stays finite.
    """
    low = values.amin() if dim is None else values.amin(dim=dim)
    high = values.amax() if dim is None else values.amax(dim=dim)
    span = high - low
    magnitude = torch.maximum(high.abs(), low.abs()).clamp_min(1.0)
    constant = span <= 1e-10 * magnitude
    gain = torch.where(
        constant, torch.ones_like(span), 2.0 / torch.where(constant, torch.ones_like(span), span)
    )
    offset = torch.where(constant, -(high + low) / 2, -1.0 - gain * low)
    return gain, offset


class DistanceMLP(nn.Module):
    """Eqs. (13)–(15) with internal mapminmax scaling of inputs and targets."""

    def __init__(
        self,
        inputs: int,
        hidden: int = DistanceConfig.hidden,
        input_scaling: str = DistanceConfig.input_scaling,
        generator: torch.Generator | None = None,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        self.input_scaling = input_scaling
        self.hidden_layer = nn.Linear(int(inputs), int(hidden), dtype=dtype)
        self.output_layer = nn.Linear(int(hidden), 1, dtype=dtype)
        self.register_buffer("input_gain", torch.ones(int(inputs), dtype=dtype))
        self.register_buffer("input_offset", torch.zeros(int(inputs), dtype=dtype))
        self.register_buffer("target_gain", torch.ones((), dtype=dtype))
        self.register_buffer("target_offset", torch.zeros((), dtype=dtype))
        self.reset_parameters(generator)

    @property
    def inputs(self) -> int:
        return self.hidden_layer.in_features

    def reset_parameters(self, generator: torch.Generator | None = None) -> None:
        """Nguyen–Widrow initialisation, as MATLAB's ``initnw`` for a sigmoid hidden layer.

        Rows of the hidden weights get norm β = 0.7·H^(1/r) and biases U(−β, β), for inputs in
        [−1, 1]; both are doubled because σ(x) = (1 + tanh(x/2))/2 spreads its active region
        over twice the range of tanh.
        """
        hidden, inputs = self.hidden_layer.weight.shape
        dtype = self.hidden_layer.weight.dtype
        beta = 0.7 * hidden ** (1.0 / inputs)

        def uniform(*shape: int) -> Tensor:
            return 2 * torch.rand(*shape, generator=generator, dtype=dtype) - 1

        weight = uniform(hidden, inputs)
        weight = (
            beta * weight / torch.linalg.vector_norm(weight, dim=1, keepdim=True).clamp_min(1e-12)
        )
        with torch.no_grad():
            self.hidden_layer.weight.copy_(2 * weight)
            self.hidden_layer.bias.copy_(2 * beta * uniform(hidden))
            self.output_layer.weight.copy_(uniform(1, hidden) / math.sqrt(hidden))
            self.output_layer.bias.copy_(uniform(1) / math.sqrt(hidden))

    def forward(self, s: Tensor) -> Tensor:
        """(n, r) pans in degrees (already weighted) → (n,) distances in metres."""
        normalised = s * self.input_gain + self.input_offset
        hidden = torch.sigmoid(self.hidden_layer(normalised))  # eqs. (13)–(14)
        output = self.output_layer(hidden).squeeze(-1)  # eq. (15)
        return (output - self.target_offset) / self.target_gain

    @torch.no_grad()
    def parameter_jacobian(self, s: Tensor) -> Tensor:
        """∂d/∂w for each row of ``s`` (n, r): an (n, P) matrix, its columns in the order of
        ``named_parameters()``, for Levenberg–Marquardt (§3.5).

        The closed form of eqs. (13)–(15) with the floating-point operations that autograd's
        per-sample Jacobian (``vmap(jacrev(...))``) performs, in the same order, so that it is
        bit for bit that Jacobian (tests/distance/test_network.py) at a fraction of its cost.
        """
        normalised = s * self.input_gain + self.input_offset
        weight, bias = self.hidden_layer.weight, self.hidden_layer.bias
        # one row at a time, as the per-sample Jacobian's forward pass sums it
        hidden = torch.sigmoid((normalised.unsqueeze(1) @ weight.T).squeeze(1) + bias)
        output_grad = torch.ones((), dtype=s.dtype, device=s.device) / self.target_gain
        hidden_grad = output_grad * self.output_layer.weight * (1 - hidden) * hidden
        rows = s.shape[0]
        return torch.cat(
            [
                (hidden_grad.unsqueeze(2) * normalised.unsqueeze(1)).reshape(rows, -1),
                hidden_grad,
                hidden * output_grad,
                output_grad.expand(rows, 1),
            ],
            dim=1,
        )

    @torch.no_grad()
    def fit_scaling(self, inputs: Tensor, targets: Tensor, preserve_function: bool) -> None:
        """Refit the [−1, 1] scaling to ``inputs`` (n, r) and ``targets`` (n,).

        With ``preserve_function`` the layers are re-expressed in the new scaled coordinates so
        that ``forward`` computes the same function as before (up to rounding). Without it the
        network is taken as new: under ``"none"`` each input's range is folded into the hidden
        layer's weights (``initnw``), and the inputs stay unscaled.
        """
        dim = None if self.input_scaling == "global" else 0
        input_gain, input_offset = minmax_gain_offset(inputs, dim)
        input_gain = input_gain.expand(self.inputs).clone()
        input_offset = input_offset.expand(self.inputs).clone()
        target_gain, target_offset = minmax_gain_offset(targets, None)
        if self.input_scaling == "none":
            if not preserve_function:
                # W·(g·x + o) + b = (W·diag(g))·x + (W·o + b): the initial weights cover each
                # input's raw range as they would cover [−1, 1]
                weight = self.hidden_layer.weight
                self.hidden_layer.bias.add_(weight @ input_offset)
                weight.mul_(input_gain)
            input_gain, input_offset = torch.ones_like(input_gain), torch.zeros_like(input_offset)
        if preserve_function:
            # x_old = g_old·x + o_old = (g_old/g_new)·(x_new − o_new) + o_old
            ratio = self.input_gain / input_gain
            weight = self.hidden_layer.weight
            self.hidden_layer.bias.add_(weight @ (self.input_offset - ratio * input_offset))
            weight.mul_(ratio)
            # y_new = (g_new/g_old)·(y_old − o_old) + o_new
            target_ratio = target_gain / self.target_gain
            self.output_layer.weight.mul_(target_ratio)
            self.output_layer.bias.sub_(self.target_offset).mul_(target_ratio).add_(target_offset)
        self.input_gain.copy_(input_gain)
        self.input_offset.copy_(input_offset)
        self.target_gain.copy_(target_gain)
        self.target_offset.copy_(target_offset)
