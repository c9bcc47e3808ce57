"""Speed of the pursuit policy (§3.4): one trainer iteration's act + update, batched robots.

``run()`` returns median milliseconds for B = 1 and B = 16 robots at the paper's state size
(2 scales × 288 bases = 576), for each feature normalisation, plus ``act`` and ``update`` alone
for the configured default (zscore), all on one torch thread, and B = 16 once more with the
caller's thread count. Timings use ``time.perf_counter`` after a warm-up.
"""

from __future__ import annotations

import statistics
import time

import torch

from parallax.policy.natural_actor_critic import NaturalActorCritic
from parallax.policy.settings import FEATURE_NORMS

STATE_DIM = 576
NUM_SCALES = 2
#: The states timed here are pooled activities alone, without the eye-position and reward-change
#: entries of the recipe's state.
THETA_ALONE = dict(eye_position_reference_m=0.0, reward_change_gain=0.0)
WARMUP = 10


def _pooled_activities(batch: int, generator: torch.Generator) -> torch.Tensor:
    # Non-negative and about 0.006 per entry, like eq. (3)'s pooled activities.
    return torch.rand(batch, STATE_DIM, generator=generator) * 0.012


def _time_iteration(
    policy: NaturalActorCritic, batch: int, repeats: int
) -> tuple[float, float, float]:
    """Median ms of act, of update, and of act + update (the trainer's per-iteration cost)."""
    generator = torch.Generator().manual_seed(0)
    states = [_pooled_activities(batch, generator) for _ in range(repeats + WARMUP + 1)]
    rewards = -torch.rand(repeats + WARMUP + 1, batch, generator=generator)
    valid = torch.ones(batch, dtype=torch.bool)
    action = policy.act(states[0])
    act_ms, update_ms, both_ms = [], [], []
    for i in range(1, repeats + WARMUP + 1):
        start = time.perf_counter()
        policy.update(states[i - 1], action, rewards[i], states[i], valid)
        middle = time.perf_counter()
        action = policy.act(states[i])
        end = time.perf_counter()
        if i > WARMUP:
            update_ms.append((middle - start) * 1e3)
            act_ms.append((end - middle) * 1e3)
            both_ms.append((end - start) * 1e3)
    return (statistics.median(act_ms), statistics.median(update_ms), statistics.median(both_ms))


def run(repeats: int = 50) -> dict[str, float]:
    """Median milliseconds per named operation (state_dim 576)."""
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats!r}")
    results: dict[str, float] = {}
    caller_threads = torch.get_num_threads()
    # The policy's tensors are tiny: timed on one intra-op thread, which is how the trainer
    # runs it (more threads only contend for the cores on a busy machine).
    torch.set_num_threads(1)
    try:
        for norm in FEATURE_NORMS:
            for batch in (1, 16):
                policy = NaturalActorCritic(
                    STATE_DIM, NUM_SCALES, feature_norm=norm, seed=0, **THETA_ALONE
                )
                act_ms, update_ms, both_ms = _time_iteration(policy, batch, repeats)
                results[f"act_update_B{batch}_{norm}_ms"] = both_ms
                if norm == "zscore":
                    results[f"act_B{batch}_ms"] = act_ms
                    results[f"update_B{batch}_ms"] = update_ms
                    results[f"act_update_B{batch}_ms"] = both_ms
        torch.set_num_threads(caller_threads)
        policy = NaturalActorCritic(
            STATE_DIM, NUM_SCALES, feature_norm="zscore", seed=0, **THETA_ALONE
        )
        results["act_update_B16_caller_threads_ms"] = _time_iteration(policy, 16, repeats)[2]
        results["caller_threads"] = float(caller_threads)
    finally:
        torch.set_num_threads(caller_threads)
    return results


if __name__ == "__main__":
    for name, value in run().items():
        print(f"{name:32s} {value:8.3f}")
