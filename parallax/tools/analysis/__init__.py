"""Studies that probe one part of the method: baselines without vision, the reward landscape,
time to learn, where the pixels match best, when the weighting helps, and the synthetic pans and
pursuit task they run on."""
