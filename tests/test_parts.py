"""The run's parts built in one place (parallax.parts): the named seed tree gives every part the
seed the index arithmetic of earlier versions gave it, so every committed number stands."""

from __future__ import annotations

import pytest

from parallax.parts import Seeds, seeds_for


@pytest.mark.parametrize("seed", [0, 1, 7, 12345])
@pytest.mark.parametrize("robots", [1, 3, 16])
def test_the_named_seed_tree_gives_the_seeds_of_the_index_arithmetic(seed, robots) -> None:
    seeds = Seeds.of(seed, robots)
    # the arithmetic as it was written: one per world, then the coder, the policy, the learner
    old = seeds_for(seed, robots + 3)
    assert list(seeds.worlds) == old[:robots]
    assert (seeds.coder, seeds.policy, seeds.distance) == tuple(old[robots : robots + 3])
    assert list(seeds.walkers) == seeds_for(seeds_for(seed, robots + 4)[robots + 3], robots)
    assert seeds.explore == seeds_for(seed, robots + 5)[robots + 4] % 2**32


def test_the_help_names_the_app_and_keeps_internal_nodes_out() -> None:
    import subprocess
    import sys

    text = subprocess.run(
        [sys.executable, "-c", "from parallax.train import main; main()", "--help"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert text.startswith("parallax-train: ")
    assert "powered by Hydra" not in text
    assert "conf/experiment/" in text.splitlines()[1]
    groups = [line for line in text.splitlines() if line.startswith(("coder: ", "policy: "))]
    assert groups == ["coder: coarse, fine, two_scale", "policy: nac"]
