"""Runs: one HIL or SIL run (hil), a study's runs on slots, threads or a cluster (runner),
their analysis and verdict."""
