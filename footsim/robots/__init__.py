"""Robot descriptions: one spec per robot, from which every simulator's model is generated.

``footsim.robots.mjcf`` (needs mujoco) and ``footsim.robots.urdf`` build the models; they are
not imported here so that ``import footsim.robots`` stays light.
"""

from footsim.robots.spec import ROBOTS, Joint, Link, RobotSpec, get_robot, robot_from_config, wolfgang

__all__ = ["RobotSpec", "Link", "Joint", "get_robot", "robot_from_config", "wolfgang", "ROBOTS"]
