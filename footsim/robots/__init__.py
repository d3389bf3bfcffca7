"""Robot descriptions: one spec per robot, from which every simulator's model is generated.

- :mod:`footsim.robots.spec`: the schema (:class:`RobotSpec`, links, joints, shapes, limits, the
  leg geometry derived from the joint origins).
- :mod:`footsim.robots.wolfgang`: the Wolfgang-OP figures in that schema.
- :mod:`footsim.robots.registry`: robot names to spec builders (the Hydra ``robot`` group).

``footsim.robots.mjcf`` (needs mujoco) and ``footsim.robots.urdf`` build the models; they are
not imported here so that ``import footsim.robots`` stays light.
"""

from footsim.robots.registry import ROBOTS, get_robot, robot_from_config
from footsim.robots.spec import Joint, Link, RobotSpec
from footsim.robots.wolfgang import wolfgang

__all__ = ["RobotSpec", "Link", "Joint", "get_robot", "robot_from_config", "wolfgang", "ROBOTS"]
