"""Queue memory of eye-movement vectors, paper §3.5, eq. (9).

S = [s_1 s_2 … s_c]: s_1 is the newest vector, s_c the oldest. A new s is queued as s_1, the
others shift by one index (s_k becomes s_{k+1}) and the old s_c is dropped. Each s is stored
with its target distance. Rows of ``inputs`` follow the same order (row 0 is s_1).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor


class QueueMemory:
    """A first-in-first-out store of the last ``capacity`` (s, target) pairs, newest first."""

    def __init__(self, capacity: int, input_size: int, dtype: torch.dtype = torch.float64) -> None:
        self.capacity = int(capacity)
        self._inputs = torch.zeros(self.capacity, int(input_size), dtype=dtype)
        self._targets = torch.zeros(self.capacity, dtype=dtype)
        self._fill = 0

    @property
    def fill(self) -> int:
        return self._fill

    @property
    def is_full(self) -> bool:
        return self._fill == self.capacity

    @property
    def inputs(self) -> Tensor:
        """(fill, r): row k−1 is s_k, so row 0 is the newest vector."""
        return self._inputs[: self._fill]

    @property
    def targets(self) -> Tensor:
        """(fill,) target distances in the same order as ``inputs``."""
        return self._targets[: self._fill]

    @property
    def matrix(self) -> Tensor:
        """S of eq. (9), (r, fill): column k−1 is s_k."""
        return self.inputs.T

    def to(self, device: torch.device | str) -> QueueMemory:
        """Moves the stored vectors and targets to ``device`` (in place; returns self)."""
        self._inputs, self._targets = self._inputs.to(device), self._targets.to(device)
        return self

    def push(self, s: Tensor, target: float) -> None:
        """Queue ``s`` as s_1 with its target; drop s_c when full."""
        s = torch.as_tensor(s, dtype=self._inputs.dtype, device=self._inputs.device)
        if s.shape != self._inputs.shape[1:]:
            raise ValueError(f"s must have shape ({self._inputs.shape[1]},), got {tuple(s.shape)}")
        if not math.isfinite(float(target)):
            raise ValueError(f"target must be finite, got {target!r}")
        kept = min(self._fill, self.capacity - 1)
        self._inputs[1 : kept + 1] = self._inputs[:kept].clone()
        self._targets[1 : kept + 1] = self._targets[:kept].clone()
        self._inputs[0] = s
        self._targets[0] = float(target)
        self._fill = kept + 1

    def state_dict(self) -> dict[str, object]:
        return {
            "inputs": self._inputs.clone(),
            "targets": self._targets.clone(),
            "fill": self._fill,
        }

    def load_state_dict(self, state: dict[str, object]) -> None:
        inputs = torch.as_tensor(state["inputs"], dtype=self._inputs.dtype)
        targets = torch.as_tensor(state["targets"], dtype=self._targets.dtype)
        fill = int(state["fill"])  # type: ignore[arg-type]
        if inputs.shape != self._inputs.shape or targets.shape != self._targets.shape:
            raise ValueError(
                f"queue state has shape {tuple(inputs.shape)}, expected {tuple(self._inputs.shape)}"
            )
        if not 0 <= fill <= self.capacity:
            raise ValueError(f"queue fill must be in [0, {self.capacity}], got {fill}")
        self._inputs.copy_(inputs)
        self._targets.copy_(targets)
        self._fill = fill
