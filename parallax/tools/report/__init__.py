"""`parallax-report`: tables and figures of runs and sweeps, beside the paper's numbers."""
