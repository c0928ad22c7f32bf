"""The simulator's actors: the robot's actor (actor.py: the clock of the lockstep, its deadline, live joint faults,
several hosts' pauses), a fleet's (fleet.py: B robots in lockstep) and the model-based baseline's controller
(controller.py). What they drive is the simulation library in sim/ (the robot, its world, scenes and faults), which
imports nothing of the actors."""
