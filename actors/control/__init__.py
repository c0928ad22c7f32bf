"""Talking to a running swarm from outside it (client.py): the fault and status client the command line, the
experiments and the benchmarks share. Below the command line: it imports no command."""
