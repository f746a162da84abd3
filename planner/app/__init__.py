"""Layer 6: applications: plan files and motion plans, the command line, the demo, plots, benchmarks."""
