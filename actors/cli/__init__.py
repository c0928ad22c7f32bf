"""The command line, `kinswarm`: run a learning swarm, run the model-based baseline, inject faults into a running
swarm, show its status, rebuild a run's report. The subcommands (commands.py), their arguments (parser.py), the
console script (entry.py: light, so a Ctrl-C while the rest imports is a clean exit; this package's own import must
stay as light) and the fault and status client (control.py)."""
