"""Launching one run (launch.py): its session and placement, its watchers, its records, a resume. The roof of the
actors: it imports the supervisor, the deploy plan and the report, and none of them imports it (the run's files,
what every actor reads, are actors/files/; an actor's process, actors/process/)."""
