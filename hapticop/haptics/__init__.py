"""Control laws of the haptic controller: handle PD and driving map, scan filters, force models, governor.

Pure numpy, no runtime dependencies, so the laws can be unit-tested and benchmarked on their own.
The block that wires them into the 1 kHz loop lives in ``hapticop.blocks.haptic``.

Each law's parameters are a frozen dataclass (``hapticop.parameters``) that the block nests as
its own parameters. Modules:
  ``handle``        centring PD, per-axis saturation, car-driving map (thesis §5.2, §5.3.1)
  ``scan_filter``   3-sample moving average with truncated endpoints (thesis §5.3.2), 5-beam median
  ``geometry``      precomputed beam geometry seen from the robot's body (points, corridor gap, side clearance)
  ``force_models``  the ``ForceModel`` interface and the ``none``/``thesis``/``thesis_corrected``/
                    ``braking_field`` (M1) models
  ``governor``      robot-side speed governor S1 (its scan work once per scan, the limit per cycle),
                    and the blind policy

Hand micro-benchmark of all of them: ``python bench/micro_haptics.py``.
"""
