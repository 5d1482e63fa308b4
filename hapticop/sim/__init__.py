"""Simulation: the scene world on MuJoCo, the operators, the simulated devices, the judge, metrics and plots.

Blocks: `scene_world` (a scene in MuJoCo: the robot's pose in it, contacts, clearances, the judge),
`blind_operator` (the operator holding the Falcon), `devices` (simulated devices behind their real
protocols). Libraries: `scene` and `scene_files` (scenes in YAML, checked and compiled to MJCF), `engine`
(the scene loaded in MuJoCo), `operator` (the synthetic operator's hand on the handle), `judge` and
`metrics` (targets and docs/hallway-experiment.md §5/§6), `plot` (a PNG of a run; needs matplotlib). The
robot's dynamics are not here: the ropod plant supplies the pose.
"""

import os

# MuJoCo is used for physics and ray casting only, never for its OpenGL renderer. Left to choose a GL
# backend, `import mujoco` imports GLFW, whose library search starts a Python process to ask each
# candidate library its version: CPU in every process that imports MuJoCo, and a child that Ctrl+C can
# interrupt mid-reply (a BrokenPipeError traceback on the run's stderr). A user's own choice stands.
os.environ.setdefault("MUJOCO_GL", "disable")
