"""The paper's algorithm with its open settings from its lineage keeps the critic bounded.

A short, shrunken run of ``experiment=paper_single_5`` (conf/experiment/paper_algorithm.yaml:
ξ = 0.3, λ = 0.01, AEC's initial weights and step sizes) must keep the critic's scale mean |v·φ|
(``policy_critic_scale`` in metrics.jsonl) of the order of the rewards (−(eC + eF) ∈ [−2, 0]);
the same run with the open settings chosen without the lineage (``unsourced_single_5``: ξ = 1,
no decay, the projection) lets it grow, which shows the check can fail.
"""

from __future__ import annotations

import json

from tests.conftest import TINY, train_tiny_run

#: Mean |v·φ| a bounded critic stays below here: a few times the largest |reward| (2).
BOUND = 5.0
SHORT_RUN = [
    *[o for o in TINY if not o.startswith(("train.presentations", "curriculum."))],
    "train.presentations=60",
    "env.trial_length=10",
    "perturbation.start_fraction=null",
]


def _critic_scales(run_dir, experiment: str) -> list[float]:
    train_tiny_run(run_dir, [f"experiment={experiment}", *SHORT_RUN])
    records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [r["policy_critic_scale"] for r in records if "policy_critic_scale" in r]


def test_the_paper_family_keeps_its_critic_bounded(tmp_path):
    lineage = _critic_scales(tmp_path / "paper", "paper_single_5")
    assert len(lineage) == 60
    assert max(lineage) < BOUND
    unsourced = _critic_scales(tmp_path / "unsourced", "unsourced_single_5")
    assert max(unsourced) > BOUND
