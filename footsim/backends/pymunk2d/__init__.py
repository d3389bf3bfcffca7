"""The 2D backend, ``backend=pymunk``: feet and trunk footprints as rectangles, obstacles and the
ball as static circles, one double step per call.

What pymunk does here: :attr:`Pymunk2DBackend.space` builds the episode's scene as a pymunk space
on demand (static circles, kinematic foot and trunk polygons) for inspection and tests; no pymunk
simulation step runs during an episode.  What the compiled kernels do: the footstep placement
(:mod:`footsim.walk.kernels`) and the closed-form rectangle–circle overlap tests of a double step
(:mod:`footsim.backends.pymunk2d.collision`, numba), which ``tests/test_backend_pymunk2d.py``
checks against pymunk's own shape queries of the same polygons against the same circles.

- :mod:`footsim.backends.pymunk2d.backend`: :class:`Pymunk2DBackend`, the backend itself.
- :mod:`footsim.backends.pymunk2d.collision`: the compiled collision kernels.
- :mod:`footsim.backends.pymunk2d.render`: the top-view image of an episode (PIL).
"""

from footsim.backends.pymunk2d.backend import Pymunk2DBackend, box_hits_circles

__all__ = ["Pymunk2DBackend", "box_hits_circles"]
