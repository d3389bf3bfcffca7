"""The command lines (``[project.scripts]`` in ``pyproject.toml``): argument parsing, printing and
files only; what they compute lives in its domain module.

==========================  =========================================  ==========================================
command                     module                                     library it drives
==========================  =========================================  ==========================================
``footsim-bench``           :mod:`footsim.tools.bench`                 :mod:`footsim.bench`
``footsim-calibrate``       :mod:`footsim.tools.calibrate`             :mod:`footsim.calibrate`
``footsim-model``           :mod:`footsim.tools.model`                 :mod:`footsim.robots`
``footsim-scenes``          :mod:`footsim.tools.scenes`                :mod:`footsim.tasks.scenes`
``footsim-sweep-summary``   :mod:`footsim.tools.sweep_summary`         :mod:`footsim.sweeps`
``footsim-transfer-matrix`` :mod:`footsim.tools.transfer_matrix`       :mod:`footsim.rl.transfer_matrix`
``footsim-walkcheck``       :mod:`footsim.tools.walkcheck`             :mod:`footsim.walkcheck`
``footsim-walkplot``        :mod:`footsim.tools.walkplot`              :mod:`footsim.walk.plot`
``footsim-walktune``        :mod:`footsim.tools.walktune`              :mod:`footsim.walktune`
``footsim-train``           :mod:`footsim.rl.train` (``main``)         :mod:`footsim.rl.train`
``footsim-eval``            :mod:`footsim.rl.evaluate` (``main``)      :mod:`footsim.rl.evaluate`
==========================  =========================================  ==========================================
"""
