"""footsim's Optuna (>= 4) sweeper for Hydra, selected as ``hydra/sweeper=optuna``.

It replaces the published ``hydra-optuna-sweeper`` (which pins optuna < 3): both register
``hydra/sweeper/optuna``, so they must not be installed together.  See docs/SWEEPS.md.
"""

__version__ = "0.1.0"
