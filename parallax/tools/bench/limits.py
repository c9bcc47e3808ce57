"""The machine's limits for one step (`parallax-bench`): measured matmul throughput and copy
bandwidth, the coder's floating-point work and memory traffic per frame (its roofline bound),
the CPU cost of a render measured alone, and the whole step's ceiling on this machine."""

from __future__ import annotations

import os
import time

import torch

from parallax.tools.bench.timing import interleaved_medians_ms


# --- the machine's limits ----------------------------------------------------------------------
def _synchronised(operation, device: str):
    """``operation`` followed by a wait for the device, so host clocks time the device's work."""
    if device == "cpu":
        return operation
    return lambda: (operation(), torch.cuda.synchronize())


def machine_limits(threads: int, device: str = "cpu") -> dict[str, float]:
    """Measured float32 matmul throughput (GFLOP/s) and copy bandwidth (GB/s) of ``device``
    (the CPU at ``threads`` torch threads, or the GPU; full float32, TF32 off)."""
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    previous_tf32 = torch.backends.cuda.matmul.allow_tf32
    torch.backends.cuda.matmul.allow_tf32 = False  # the coder's products are plain float32
    try:
        n = 1024 if device == "cpu" else 8192
        a, b = torch.randn(n, n, device=device), torch.randn(n, n, device=device)
        out = torch.empty(n, n, device=device)
        mm = _synchronised(lambda: torch.mm(a, b, out=out), device)
        ms = interleaved_medians_ms({"mm": mm}, repeats=20)["mm"]
        gflops = 2 * n**3 / (ms * 1e-3) / 1e9
        # 128 MiB on the CPU, 2 GiB on a GPU: far beyond the caches
        src = torch.ones((32 if device == "cpu" else 512) * 2**20, device=device)
        dst = torch.empty_like(src)
        copy = _synchronised(lambda: dst.copy_(src), device)
        ms = interleaved_medians_ms({"copy": copy}, repeats=10)["copy"]
        gbps = 2 * src.numel() * 4 / (ms * 1e-3) / 1e9  # one read + one write per element
    finally:
        torch.set_num_threads(previous)
        torch.backends.cuda.matmul.allow_tf32 = previous_tf32
    return {"matmul_gflops": gflops, "copy_gbps": gbps}


def cuda_components(repeats: int) -> dict[str, float]:
    """Median ms of the coder (encode + dictionary update, both scales), the policy's act +
    update and one LM epoch on the GPU, each followed by a device synchronisation."""
    from parallax.policy.natural_actor_critic import NaturalActorCritic
    from parallax.tools.bench.coding import _coder, _frames
    from parallax.tools.bench.distance import EpochFromStart, paper_sized_learner
    from parallax.tools.bench.policy import NUM_SCALES, STATE_DIM, THETA_ALONE, _pooled_activities

    operations = {}
    for batch in (1, 16, 64):
        references, currents = _frames(batch)
        coder = _coder("gram", True, ["coarse", "fine"]).to("cuda")
        coder.set_reference(references)
        current = torch.from_numpy(currents).to("cuda")
        operations[f"encode_update_both_B{batch}_ms"] = _synchronised(
            lambda coder=coder, current=current: coder(current), "cuda"
        )
    for batch in (1, 16, 64):
        policy = NaturalActorCritic(
            STATE_DIM, NUM_SCALES, seed=0, feature_norm="none", **THETA_ALONE
        ).to("cuda")
        generator = torch.Generator().manual_seed(0)
        states = _pooled_activities(batch, generator).to("cuda")
        rewards = -torch.rand(batch, generator=generator).to("cuda")
        valid = torch.ones(batch, dtype=torch.bool, device="cuda")

        def act_update(policy=policy, states=states, rewards=rewards, valid=valid) -> None:
            action = policy.act(states)
            policy.update(states, action, rewards, states, valid)

        operations[f"policy_act_update_B{batch}_ms"] = _synchronised(act_update, "cuda")
    timed = EpochFromStart(paper_sized_learner().to("cuda"))
    operations["lm_epoch_ms"] = _synchronised(lambda: (timed.restore(), timed.epoch()), "cuda")
    return interleaved_medians_ms(operations, repeats, warmup=5)


def coder_work_per_frame(cfg) -> dict[str, float]:
    """Floating-point operations and bytes moved by the coder for one frame pair (all scales).

    Counted as the coder computes them: correlations X·Φᵀ (2PKN), the Gram matrix ΦΦᵀ (2N²K),
    k steps of C ← C − c·G[j] (2kPN), the reconstruction from the k picks (2PkK), the sparse
    dictionary gradient Bᵀ·R from the picks (2PkK) and the pooled activities from the picks
    (2Pk). Bytes: the patches and the dictionary read about three times, the Gram matrix once,
    the correlation matrix read and written at each of the k steps (the dense (P, N) codes are
    not made: θ comes from the picks).

    ``shared_flops`` and ``shared_bytes`` are the part a lockstep of B robots does once, not B
    times: the Gram matrix and the reads of the dictionary and the Gram matrix (one dictionary
    per scale, all robots' patches in one pursuit); see :func:`coder_bound_ms`.
    """
    from parallax.coding.retina import ScaleSpec

    flops = bytes_moved = shared_flops = shared_bytes = 0.0
    N, k = int(cfg.coder.atoms), int(cfg.coder.sparsity)
    for scale in cfg.coder.scales:
        spec = cfg.coder.scale_specs[scale]
        geometry = ScaleSpec.from_mapping(spec)
        P, K = geometry.patch_count, geometry.dim
        flops += 2 * P * K * N + 2 * N * N * K + 2 * k * P * N + 4 * P * k * K + 2 * P * k
        bytes_moved += 4 * (3 * P * K + 3 * N * K + N * N + 2 * (k + 1) * P * N)
        shared_flops += 2 * N * N * K
        shared_bytes += 4 * (3 * N * K + N * N)
    return {
        "flops": flops,
        "bytes": bytes_moved,
        "shared_flops": shared_flops,
        "shared_bytes": shared_bytes,
    }


def coder_bound_ms(work: dict[str, float], limits: dict[str, float], robots: int) -> float:
    """The coder's roofline bound for one lockstep of ``robots`` frames (ms): its work divided by
    the measured matmul throughput, or its traffic by the copy bandwidth, whichever is longer.
    The Gram matrix and the dictionary reads are counted once per lockstep, not per robot."""
    flops = robots * (work["flops"] - work["shared_flops"]) + work["shared_flops"]
    bytes_moved = robots * (work["bytes"] - work["shared_bytes"]) + work["shared_bytes"]
    return (
        max(flops / (limits["matmul_gflops"] * 1e9), bytes_moved / (limits["copy_gbps"] * 1e9))
        * 1e3
    )


# --- the whole step's ceiling --------------------------------------------------------------------
def usable_cores() -> int:
    """CPU cores this process may run on (its affinity, which a cluster job may narrow)."""
    return len(os.sched_getaffinity(0))


def render_cpu_ms_per_frame(frames: int = 200) -> float:
    """CPU milliseconds one 256×256 left-eye frame costs, rendered alone: the process's CPU time
    (the GL thread, Mesa's rasteriser threads, everything) over ``frames`` frames, after a warm-up.
    No roofline exists for the renderer, so this measured cost is the step's floor for it."""
    import parallax.envs

    env = parallax.envs.load(
        seed=0,
        lateral_positions=[0.05, 0.1],
        trial_length=30,
        image_size=256,
        initial_pan_jitter_deg=0.0,
    )
    try:
        env.reset()
        for _ in range(20):
            env.physics.render_left_eye()
        start = time.process_time()
        for _ in range(frames):
            env.physics.render_left_eye()
        return (time.process_time() - start) / frames * 1e3
    finally:
        env.close()


def ceiling_steps_per_second(
    render_cpu_ms: float, coder_bound: float, robots: int, cores: int
) -> float:
    """Robot-iterations per second if the coder ran at its roofline bound (``coder_bound``, ms
    for a lockstep of ``robots``), every frame cost ``render_cpu_ms`` of CPU and ``cores`` cores
    were busy all the time, with nothing else to do: the most this machine can give."""
    return cores * robots / (robots * render_cpu_ms + coder_bound) * 1e3
