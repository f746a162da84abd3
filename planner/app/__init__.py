"""Layer 7: applications: plan files, motion plans, sending to an arm, the command line, demo, plots, benchmarks."""
