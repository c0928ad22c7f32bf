"""The agent actor: one joint (or a compound agent with no joint) running the lockstep step (actor.py),
standing in for lost children (standin.py) and keeping its learned state in checkpoints (memory.py); a fleet's agent,
one joint of every robot (fleet.py). The step it runs is the step library's (actors/step/). Nothing is imported here:
importing a module of this package (or the step library through it) loads no actor, no Zenoh and no asyncio."""
