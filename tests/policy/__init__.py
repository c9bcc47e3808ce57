"""Tests of the pursuit policy (paper §3.4, eqs. 5–8): the natural actor-critic and features."""
