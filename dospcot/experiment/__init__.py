"""Running experiments: training a config in a run folder, sweeps, reports, plots, benchmarks and the
Python API."""
