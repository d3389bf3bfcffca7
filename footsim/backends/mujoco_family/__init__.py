"""The MuJoCo-engine backends: ``mujoco_sim`` (the ``mujoco`` bindings) and ``dm_control_sim``
(dm_control's mjcf and Physics), with what they share in ``engine`` (model options, obstacle
pool, warnings, overlay, common sim verbs) and ``randomization`` (the physics terms as edits of
the same ``mjModel`` arrays).

Both simulators pick their OpenGL backend once, at import: without a display, rendering is
headless (EGL) unless ``MUJOCO_GL`` says otherwise.  This package sets that default before
either is imported.
"""

import os

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"
