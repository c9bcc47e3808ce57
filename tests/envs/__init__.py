"""Tests of the world (paper §3.2, §4.1, §5): the HOAP-3 physics, rendering, task, stimuli."""
