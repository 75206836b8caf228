"""The tracking bound a run must meet to be `ok`, which the default design of an arm is also chosen
for: one definition for gen (gen/arm's design choice) and tools (tools/run/verdict.py)."""

from gen.lib.params import default

DEFAULT_MAX_ERROR_DEG: float = default("hil", "max-error-deg")  # the registry's (firmware/params/params.toml)
