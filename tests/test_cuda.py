"""The GPU path (`device=cuda`): the coder, policy and distance learner compute on a
GPU what they compute on the CPU. Skipped where torch sees no CUDA device (CI, the 2-core
machines); run on a lent GPU with ``pytest tests/test_cuda.py``."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from parallax.coding import MultiScaleCoder
from parallax.distance import DistanceLearner
from parallax.policy.natural_actor_critic import NaturalActorCritic
from parallax.tools.analysis.synthetic_pans import PAPER_LATERAL_POSITIONS_M, paper_regression

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")

SPECS = {
    "coarse": {"window": 250, "subsample": 8, "patch": 10, "stride": 1},
    "fine": {"window": 150, "subsample": 2, "patch": 10, "stride": 4},
}


def _photo_pair(batch: int, shift: int = 3) -> tuple[np.ndarray, np.ndarray]:
    import skimage.data

    photo = skimage.data.astronaut()
    references = np.stack([photo[40 * i : 40 * i + 256, 100:356] for i in range(batch)])
    return references, np.roll(references, shift, axis=2)


def test_coder_on_the_gpu_matches_the_cpu() -> None:
    coders = {
        device: MultiScaleCoder(
            ["coarse", "fine"],
            SPECS,
            atoms=288,
            sparsity=10,
            learning_rate=0.2,
            normalisation="per_half",
            learn=True,
            seed=0,
            image_size=256,
        ).to(device)
        for device in ("cpu", "cuda")
    }
    references, currents = _photo_pair(4)
    outputs = {}
    for device, coder in coders.items():
        coder.set_reference(references)
        for _ in range(3):  # three learning steps, so the dictionaries' updates are compared too
            outputs[device] = coder(currents)
    cpu, gpu = outputs["cpu"], outputs["cuda"]
    assert gpu.state.device.type == "cuda"
    torch.testing.assert_close(gpu.state.cpu(), cpu.state, rtol=1e-3, atol=1e-5)
    torch.testing.assert_close(gpu.reward.cpu(), cpu.reward, rtol=1e-3, atol=1e-5)
    for scale in ("coarse", "fine"):
        torch.testing.assert_close(
            coders["cuda"].dictionaries[scale].cpu(),
            coders["cpu"].dictionaries[scale],
            rtol=1e-3,
            atol=1e-5,
        )


def test_policy_on_the_gpu_matches_the_cpu() -> None:
    from parallax.tools.analysis.synthetic_pursuit import PUBLISHED as published

    policies = {
        device: NaturalActorCritic(576, 2, seed=3, **published).to(device)
        for device in ("cpu", "cuda")
    }
    generator = torch.Generator().manual_seed(0)
    states = [torch.rand(16, 576, generator=generator) * 0.012 for _ in range(20)]
    rewards = [-torch.rand(16, generator=generator) for _ in range(20)]
    actions = {}
    for device, policy in policies.items():
        valid = torch.ones(16, dtype=torch.bool, device=device)
        taken = []
        for t in range(19):
            action = policy.act(states[t].to(device))
            policy.update(
                states[t].to(device), action, rewards[t].to(device), states[t + 1].to(device), valid
            )
            taken.append(action.cpu())
        actions[device] = torch.stack(taken)
    # uniforms are drawn on the CPU, so the same seed picks the same actions on both devices
    assert torch.equal(actions["cuda"], actions["cpu"])
    for name in ("critic", "advantage", "actor"):
        torch.testing.assert_close(
            getattr(policies["cuda"], name).cpu(),
            getattr(policies["cpu"], name),
            rtol=1e-4,
            atol=1e-6,
        )


def test_distance_learner_on_the_gpu_matches_the_cpu() -> None:
    pans, distances = paper_regression(60, np.random.default_rng(0))
    learners = {
        device: DistanceLearner(
            PAPER_LATERAL_POSITIONS_M,
            queue_size=40,
            hidden=5,
            initial_epochs=20,
            epochs_per_call=3,
            seed=0,
            lm={"weight_decay": 0.0},
        ).to(device)
        for device in ("cpu", "cuda")
    }
    stats = {
        device: [learner.observe(s, d) for s, d in zip(pans, distances)]
        for device, learner in learners.items()
    }
    assert learners["cuda"].network.hidden_layer.weight.device.type == "cuda"
    # float64 on both: the same accepted steps, losses equal to rounding
    assert [s["epochs"] for s in stats["cuda"]] == [s["epochs"] for s in stats["cpu"]]
    np.testing.assert_allclose(
        [s["loss"] for s in stats["cuda"][40:]], [s["loss"] for s in stats["cpu"][40:]], rtol=1e-8
    )
    np.testing.assert_allclose(
        learners["cuda"].predict(pans[:10]), learners["cpu"].predict(pans[:10]), rtol=1e-8
    )
    # a state saved on the GPU loads into a CPU learner
    cpu_copy = DistanceLearner(
        PAPER_LATERAL_POSITIONS_M, queue_size=40, hidden=5, seed=1, lm={"weight_decay": 0.0}
    )
    cpu_copy.load_state_dict(learners["cuda"].state_dict())
    np.testing.assert_allclose(
        cpu_copy.predict(pans[:10]), learners["cpu"].predict(pans[:10]), rtol=1e-8
    )


def test_a_run_on_the_gpu_trains_resumes_exactly_and_evaluates_on_the_cpu(
    tmp_path, tiny_overrides
) -> None:
    from parallax.config import compose
    from parallax.tools.evaluate import main as evaluate
    from parallax.trainer import Trainer

    def train(run_dir, extra=()) -> dict:
        trainer = Trainer(
            compose(tiny_overrides + ["device=cuda", "env.robots=2", *extra]), run_dir
        )
        try:
            summary = trainer.fit()
        finally:
            trainer.exp.close()
        summary.pop("timing", None)
        return summary

    full = train(tmp_path / "full")
    train(tmp_path / "part", ["train.presentations=4"])
    assert train(tmp_path / "part") == full
    assert np.isfinite(full["mae"])
    # trained on the GPU, evaluated on the CPU: the checkpoint carries no device
    evaluate([str(tmp_path / "full"), "--distances", "3.0", "5.0", "--between", "--device", "cpu"])
    assert "mae" in json.loads((tmp_path / "full" / "eval.json").read_text())
