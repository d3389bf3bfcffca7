"""The PyBullet backend: the sim (``sim.py``: ``PybulletSim``'s physics verbs and state contract,
``PybulletBackend``) and the pool of built worlds it reuses (``world_pool.py``).  Importing this
package does not import pybullet; the registry (``footsim.backends.base.BACKENDS``) names
``footsim.backends.bullet.sim``."""
