"""Pursuit policy (paper §3.4, eqs. 5–8): natural actor-critic over pan increments.

``NaturalActorCritic`` is the learner the trainer instantiates from ``conf/policy/nac.yaml``.
``features`` holds what it acts on: ``PolicyInputs`` builds the state from what the robots
observe (θ, and beyond the paper θ_ref, the pans and the reward change) and ``FeatureNormalizer``
the optional normalisations of θ. ``Pursuer`` is its bookkeeping in the loop: each turn's last
step, θ(I0, I0), the rule at a trial's reset, learning and acting.
"""

from parallax.policy.features import FeatureNormalizer, PolicyInputs
from parallax.policy.natural_actor_critic import PAPER_ACTIONS_DEG, NaturalActorCritic
from parallax.policy.pursuer import Pursuer
from parallax.policy.settings import FEATURE_NORMS

__all__ = [
    "FEATURE_NORMS",
    "PAPER_ACTIONS_DEG",
    "FeatureNormalizer",
    "NaturalActorCritic",
    "PolicyInputs",
    "Pursuer",
]
