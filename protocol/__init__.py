"""What every side of a run reads, importing nothing else of ours: the wire (keys, messages, the codec), the robot
(topology, robots, urdf_robot, frames), what surrounds it (scene, obstacles), faults and scenario files, and the
run files' table checks (spec)."""
