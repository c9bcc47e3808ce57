"""The test suite of parallax; run one directory at a time (``pytest -q tests/<dir>``)."""
