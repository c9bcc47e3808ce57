"""Pursuit policy (paper §3.4, eqs. 5–8): natural actor-critic over pan increments.

``NaturalActorCritic`` is the learner the trainer instantiates from ``conf/policy/nac.yaml``;
``features`` holds the optional state normalisations; ``synthetic_pursuit`` is a small stand-in
task used by the tests and for choosing step sizes; ``benchmark`` times act + update.
"""

from parallax.policy.features import FEATURE_NORMS, FeatureNormalizer
from parallax.policy.natural_actor_critic import PAPER_ACTIONS_DEG, NaturalActorCritic

__all__ = ["FEATURE_NORMS", "PAPER_ACTIONS_DEG", "FeatureNormalizer", "NaturalActorCritic"]
