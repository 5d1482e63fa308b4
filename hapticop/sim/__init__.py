"""Simulation of the dead-end hallway experiment: the world, a blind operator, the simulated devices, metrics and plots.

Blocks: `world` (the hallway world: the robot's pose in it, the judge), `blind_operator` (the operator
holding the Falcon), `devices` (simulated devices behind their real protocols). Libraries: `hallway`
(walls, LIDAR ray-cast, clearance), `operator` (the synthetic operator's hand on the handle), `metrics`
(the run's log and §5/§6 of docs/hallway-experiment.md), `plot` (a PNG of a run; needs matplotlib). The
robot's dynamics are not here: the ropod plant supplies the pose.
"""
