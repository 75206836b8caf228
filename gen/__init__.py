"""Offline generation: synthesis, verification and C emission."""
