"""Programs built on the core: evaluation, replay, pictures, the report, the benchmark and the
analysis studies. The core (envs, coding, policy, distance, the experiment loop, the trainer)
never imports from here."""
