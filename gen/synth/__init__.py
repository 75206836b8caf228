"""Synthesis of the paper's estimator and controller: config -> LMIs -> verified, discretised,
quantised designs -> manifest.json + C headers. Entry points: gen.synth.cli (armctl synth) and
gen.synth.pipeline.synthesize (Python API). See gen/SYNTH.md."""
