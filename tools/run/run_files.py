"""The files of a run folder (armctl hil, run, commission, identify, and the study's runs), named once."""

TELEMETRY_LOG = "telemetry.lcmlog"  # the LCM log the logger writes: the run's telemetry
CONTROLLER_SUMMARY = "controller_summary.json"  # arm_controller --summary
SIM_SUMMARY = "sim_summary.json"  # arm_sim --summary
RUN_RECORD = "run.json"  # the run's record: config, results, environment (tools/run/run_analysis.py)
UNCERTAINTY_FILE = "uncertainty.json"  # the simulated arm's uncertainty, as run
