"""Defining and launching one run: the resolved run every actor reads (config.py), the one loader of run files
(runfile.py), the run directory's lifecycle (rundir.py), launching a run in its placement (launch.py), the one spawn
path of an actor process (main.py), and the agents' checkpoint files (checkpoint.py)."""
