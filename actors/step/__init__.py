"""The step as a library: plain functions and small classes over what an agent holds, with no Zenoh, no asyncio and
no actor runtime (tests/test_arrows.py keeps it so). The agent actor calls it as its messages arrive; the inprocess
loop, the env faces, the benchmarks and the research loops call it in a plain loop (swarm.py).

passes.py    one agent's share of a step: the top-down pass (`TopDown`), the bottom-up pass, what its learner decides
             from (`Decision`), the action as the joint's increment (`AgentPasses`); `robot_passes`, both passes over a
             whole robot
swarm.py     the driver: a run's learners, the faults due at a step, one joint's learn and decide, and `Swarm`, a whole
             robot's step of a plain loop (the inprocess placement, the env faces)
geometry.py  the robot's geometry by its kind (planar, spatial): frames, a leaf's tip, the state S_i
trace.py     what an agent saw and chose at each step of an epoch, for the recording
seed.py      the one seed of an agent's learner
epoch.py     what an epoch starts with, and when the learners checkpoint
learned.py   a learner's learned state as a checkpoint holds it
"""
