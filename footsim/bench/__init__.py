"""Speed benchmarks, run by ``footsim-bench`` (:mod:`footsim.tools.bench`) for ``docs/BENCHMARKS.md``.

- :mod:`footsim.bench.env2d`: the 2D env's steps/s, without and with rays.
- :mod:`footsim.bench.walk`: the walk engine and leg IK, one double step.
- :mod:`footsim.bench.planners`: the baselines' planning times on obstacle scenes.
- the 3D backends: env time against raw physics time (``footsim.bench.physics3d``).
- :mod:`footsim.bench.suite`: the table of benchmarks by name.
"""
