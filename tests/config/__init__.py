"""Tests of the configuration: the schema, the shipped conf/ files, validation, run names."""
