"""Tests of the egocentric distance learner (paper §3.5–3.5.2, eqs. 9–15) and its optimiser."""
