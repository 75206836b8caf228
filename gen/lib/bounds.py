"""The tracking bound a run must meet to be `ok`, which the default design of an arm is also chosen
for: one definition for gen (gen/arm.py's design choice) and tools (tools/verdict.py)."""

DEFAULT_MAX_ERROR_DEG = 2.0  # armctl hil --max-error-deg's default
