"""The command lines (``[project.scripts]`` in ``pyproject.toml``): argument parsing, printing and
files only; what they compute lives in its domain module.

- ``footsim-bench``: :mod:`footsim.tools.bench` runs :mod:`footsim.bench`.
- ``footsim-calibrate``: :mod:`footsim.tools.calibrate` runs :mod:`footsim.calibration.execution_model`.
- ``footsim-model``: :mod:`footsim.tools.model` writes :mod:`footsim.robots` models as MJCF / URDF.
- ``footsim-scenes``: :mod:`footsim.tools.scenes` samples :mod:`footsim.tasks.scenes`.
- ``footsim-sweep-summary``: :mod:`footsim.tools.sweep_summary` runs :mod:`footsim.rl.sweeps`.
- ``footsim-transfer-matrix``: :mod:`footsim.tools.transfer_matrix` runs :mod:`footsim.rl.transfer_matrix`.
- ``footsim-walkcheck``: :mod:`footsim.tools.walkcheck` runs :mod:`footsim.calibration.walkcheck`.
- ``footsim-walkplot``: :mod:`footsim.tools.walkplot` runs :mod:`footsim.walk.plot`.
- ``footsim-walktune``: :mod:`footsim.tools.walktune` runs :mod:`footsim.calibration.walktune`.
- ``footsim-train``: :mod:`footsim.tools.train`, the Hydra app that runs :func:`footsim.rl.train.train`.
- ``footsim-eval``: :mod:`footsim.tools.evaluate`, the Hydra app that runs :mod:`footsim.rl.evaluate`.
"""
