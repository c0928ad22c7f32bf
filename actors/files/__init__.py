"""A run's files, and what every actor reads of them: the resolved run (config.py: `<run>/config.json`), the one
loader of run files (runfile.py, its table plumbing in tables.py) and the resolved run written back (resolved.py:
`<run>/run.toml`), the run directory's lifecycle (rundir.py) and a run resumed from it (resume.py), the agents'
checkpoint files (checkpoint.py). The floor the actors stand on: it imports no actor, no supervisor and no launcher
(tests/test_cycles.py: package arrows run one way)."""
