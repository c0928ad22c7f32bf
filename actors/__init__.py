"""The actors and everything that runs them, by what each serves:

step/        the step as a library (the passes, the geometry, what a learner decides from): no Zenoh, no asyncio
agent/       the agent actor: the step library on messages, standing in for lost children, its checkpoints
learning/    the learners (paper §4) and what an agent observes; imports only numpy and numba
tasks/       one module per task: what the generic agent asks of a task
simulator/   the simulator's actors: the robot's clock and live faults, a fleet's, the baseline's controller
runtime/     the shell every actor runs in: the Zenoh session, the mailbox, link faults
supervisor/  a run's supervisor: spawning, epochs, checkpoints, faults, restarts, hosts; the inprocess placement
run/         defining and launching one run: the run file, the resolved run, its directory, the spawn path
deploy/      several hosts: the deploy plan and what a host needs from the others
report/      what a run leaves for a person: plots, summary, motion.gif, the rerun recording
cli/         the command line
env/         the robot and its task as Gymnasium and PettingZoo environments, importable as kinswarm.env
"""
