"""The simulation library: the robot in its world one step after another (robot.py), the PyBullet world (world.py,
urdf.py), the robot's joint faults (faults.py), what surrounds it (scenes/), closed-form planar kinematics and a
model world (kinematics.py), the model-based laws and the rule (baseline.py). It imports nothing but protocol: the
actors drive it (actors/simulator/, the inprocess placement, kinswarm.env)."""
