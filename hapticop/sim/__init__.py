"""Simulation of the dead-end hallway experiment: the world, a blind operator, metrics and plots.

`hallway` (walls, LIDAR ray-cast, clearance), `operator` (the synthetic operator's hand on the handle),
`metrics` (the run's log and §5/§6 of hallway-experiment.md), `plot` (a PNG of a run; needs matplotlib).
The robot's dynamics are not here: the ropod plant supplies the pose.
"""
