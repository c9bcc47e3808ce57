"""Tests of the sensory coding model (paper §3.3, eqs. 1–6): retina, pursuit, dictionaries."""
