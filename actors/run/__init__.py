"""Defining and launching one run: the resolved run every actor reads (config.py), the one loader of run files
(runfile.py, its table plumbing in tables.py) and the resolved run written back (resolved.py), the run directory's
lifecycle (rundir.py), launching a run in its placement (launch.py) and resuming one (resume.py), the one spawn path
of an actor process (main.py), and the agents' checkpoint files (checkpoint.py)."""
