"""Robot descriptions: one spec per robot, from which every simulator's model is generated."""

from footsim.robots.spec import RobotSpec, get_robot, ROBOTS

__all__ = ["RobotSpec", "get_robot", "ROBOTS"]
