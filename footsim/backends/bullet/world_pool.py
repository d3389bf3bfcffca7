"""Idle built Bullet worlds (a DIRECT client with floor and robot loaded), keyed by the model.

Bullet keeps ~50-70 kB per ``loadURDF`` even after ``resetSimulation`` or ``disconnect``, so 1000
create/close cycles would grow the process by ~70 MB.  ``PybulletSim.close`` parks its world
here instead (:func:`release`) and the next sim of the same model takes it (:func:`take`), so
memory is bounded by the number of sims open at once.  Beyond :data:`MAX_IDLE` idle worlds a
released world is disconnected.
"""

from __future__ import annotations

import os

import pybullet as p

MAX_IDLE = 4
_idle: dict[tuple, list[dict]] = {}


def take(key: tuple) -> dict | None:
    """An idle world of this model (its sim attributes, ``client`` among them), or None."""
    idle = _idle.get(key)
    while idle:
        world = idle.pop()
        if p.isConnected(world["client"]):
            return world
    return None


def release(client: int, path: str | None, key: tuple | None, world: dict | None) -> None:
    """Park ``world`` under ``key`` for reuse (None: disconnect ``client``); remove the URDF file ``path``."""
    try:
        if p.isConnected(client):
            if key is not None and world is not None and sum(map(len, _idle.values())) < MAX_IDLE:
                _idle.setdefault(key, []).append(world)
            else:
                p.disconnect(client)
    except Exception:  # pragma: no cover - interpreter shutdown
        pass
    if path:
        try:
            os.unlink(path)
        except OSError:
            pass
