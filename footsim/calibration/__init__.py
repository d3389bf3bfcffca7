"""The walk measured on the simulators: does it walk, how fast, and what the 2D backend should
execute to match a 3D one.

- :mod:`footsim.calibration.walkcheck`: open-loop double-step sequences on each backend against
  the commanded displacement, and the cross-backend consistency report (``footsim-walkcheck``).
- :mod:`footsim.calibration.walktune`: the Bit-Bots' walk-tuning objective for Optuna sweeps
  (``footsim-walktune``).
- :mod:`footsim.calibration.execution_model`: the commanded → executed displacement (and fall
  probability) fitted on a 3D backend, which ``backend=pymunk backend.execution_model=FILE``
  executes through (``footsim-calibrate``).
"""
