"""Calibrated 2D: the execution model, fitted on a 3D backend (``footsim-calibrate``,
:mod:`footsim.tools.calibrate`).

:func:`collect` rolls out random double steps (with probability ``repeat`` the previous action
again, so steady walking dominates as in a policy's gait) on a 3D backend from an empty scene,
resetting after a fall.  For every double step it records

* the displacement the planar footstep geometry predicts (what the 2D backend executes): the
  navigation frame (mean of the two feet) after the step in the frame before it, from the walk
  engine's footsteps (``StepResult.feet``);
* the displacement the simulated robot really made: the base's planar pose after the step in
  the frame of the base before it (``StepResult.pose``);
* whether it fell.

Actions are uniform in ``[-1, 1]`` times a magnitude drawn in ``[0.25, 1] × scale`` per new
action.  :func:`fit` fits the **execution model**: per output (dx, dy, dθ) a linear regression on
the predicted displacement (``features=dx,dy,dtheta`` by default; ``abs_dx, abs_dy, abs_dtheta``
can be added) with intercept and residual σ, and the fall probability per double step as a
logistic regression on the absolute action values.  ``backend=pymunk backend.execution_model=FILE``
makes the 2D backend execute through it (:class:`ExecutionModel`, ``footsim.backends.pymunk2d``).
``backend.fall_model=PATH`` gives that backend a fall model from a capability map instead
(:class:`CapabilityFallModel`: each commanded double step falls with the rate of the map's nearest
cell).

:func:`footsim.calibration.walkcheck.execution_model_consistency` (``footsim-calibrate
compare=FILE.json``) runs the walkcheck sequences on
pymunk with and without the model and on the 3D backend and builds the consistency table (final
planar pose differences).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.walk.footsteps import DoubleStep, FootstepGeometry

FORMAT = "footsim-execution-model"
VERSION = 1
FEATURES = ("dx", "dy", "dtheta", "abs_dx", "abs_dy", "abs_dtheta")
OUTPUTS = ("dx", "dy", "dtheta")
DEFAULT_FEATURES = ("dx", "dy", "dtheta")  # the abs_* terms fit random data better but extrapolate worse
FALL_FEATURES = tuple(f"abs_a{i}" for i in range(6))


def features(displacement, names=FEATURES) -> np.ndarray:
    """Feature vector(s) of predicted displacement(s) ``(..., 3)``."""
    d = np.asarray(displacement, dtype=float)
    table = {
        "dx": d[..., 0],
        "dy": d[..., 1],
        "dtheta": d[..., 2],
        "abs_dx": np.abs(d[..., 0]),
        "abs_dy": np.abs(d[..., 1]),
        "abs_dtheta": np.abs(d[..., 2]),
    }
    return np.stack([table[n] for n in names], axis=-1)


class ExecutionModel:
    """Commanded (2D-predicted) → executed displacement per double step, plus fall risk.

    ``predict(d, rng)`` maps the displacement the footstep geometry predicts (dx, dy, dθ in the
    frame before the step) to the executed one, with Gaussian residual noise from ``rng``
    (``noise=False``: the mean).  ``fall_probability(action)`` is the logistic fall model (0
    without one).
    """

    def __init__(self, data: dict, source: str = "<dict>", noise: bool = True):
        self.source, self.noise = source, noise
        where = f"execution model {source}"

        def fail(msg):
            raise ValueError(f"{where}: {msg}")

        if not isinstance(data, dict) or data.get("format") != FORMAT:
            fail(f'not a footsim execution model (expected "format": "{FORMAT}", made by footsim-calibrate)')
        if int(data.get("version", 0)) != VERSION:
            fail(f"version {data.get('version')!r} is not supported (expected {VERSION})")
        names = tuple(data.get("features", FEATURES))
        unknown = set(names) - set(FEATURES)
        if unknown:
            fail(f"unknown features {sorted(unknown)}; known: {list(FEATURES)}")
        if tuple(data.get("outputs", OUTPUTS)) != OUTPUTS:
            fail(f"outputs must be {list(OUTPUTS)}")
        try:
            coef = np.asarray(data["coef"], dtype=float)
            intercept = np.asarray(data.get("intercept", [0.0] * 3), dtype=float)
            std = np.asarray(data.get("residual_std", [0.0] * 3), dtype=float)
        except KeyError as err:
            fail(f"missing key {err}")
        except (TypeError, ValueError) as err:
            fail(f"coef/intercept/residual_std must be numbers ({err})")
        if coef.shape != (3, len(names)) or intercept.shape != (3,) or std.shape != (3,):
            fail(
                f"coef must be 3 x {len(names)} (outputs x features), intercept and residual_std 3 values; "
                f"got {coef.shape}, {intercept.shape}, {std.shape}"
            )
        if not (np.isfinite(coef).all() and np.isfinite(intercept).all() and np.isfinite(std).all()) or (std < 0).any():
            fail("coefficients must be finite and residual_std >= 0")
        self.names, self.coef, self.intercept, self.std = names, coef, intercept, std
        self.fall = None
        fall = data.get("fall")
        if fall is not None:
            try:
                fc = np.asarray(fall["coef"], dtype=float)
                fb = float(fall["intercept"])
            except (KeyError, TypeError, ValueError) as err:
                fail(f"fall model needs numeric 'coef' (6) and 'intercept' ({err})")
            if fc.shape != (6,) or not (np.isfinite(fc).all() and math.isfinite(fb)):
                fail("fall.coef must be 6 finite numbers (one per |action| value)")
            self.fall = (fc, fb)
        self.data = data

    @classmethod
    def load(cls, path, noise: bool = True) -> ExecutionModel:
        path = Path(path).expanduser()
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            raise FileNotFoundError(f"execution model file not found: {path}") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise ValueError(f"execution model {path}: not valid JSON ({err})") from None
        return cls(data, str(path), noise)

    def mean(self, displacement) -> np.ndarray:
        return self.coef @ features(displacement, self.names) + self.intercept

    def predict(self, displacement, rng: np.random.Generator | None = None) -> np.ndarray:
        out = self.mean(displacement)
        if self.noise and rng is not None and self.std.any():
            out = out + rng.normal(0.0, 1.0, 3) * self.std
        return out

    def fall_probability(self, action) -> float:
        if self.fall is None:
            return 0.0
        fc, fb = self.fall
        z = float(fc @ np.abs(np.asarray(action, dtype=float)) + fb)
        return 1.0 / (1.0 + math.exp(-z)) if z > -700 else 0.0


class CapabilityFallModel:
    """Fall probability of a commanded double step from a capability map (``footsim-capability``'s
    ``capability.csv``): ``backend=pymunk backend.fall_model=PATH``.

    A commanded double step, as its unit action (6 values in [-1, 1]: the step divided by the
    robot's step limits, right foot then left, :data:`footsim.calibration.capability.ACTION_COLUMNS`),
    takes the fall rate of the map's **nearest cell** (squared Euclidean distance in that unit
    space; on a tie the cell written first).  Nearest rather than interpolated because

    * it works on every grid the map tool writes (``same:N``, ``full:N``, axis lists) without
      assuming a regular 6-D lattice, which the default ``same:5`` map is not (both feet take the
      same step: a 3-D subset of the box);
    * the value used is a measured one: without randomization the simulators are deterministic
      and a cell's rate is 0 or 1, so interpolating would invent rates between cells that none of
      the trials showed; and a cell with rate 0 can never make the robot fall;
    * it is the lookup of the footstep planner's ``controller.stable_region`` (the same map, the
      same cells), so the planner and the calibrated 2D backend agree on what is stable.

    For a ``same:N`` map the nearest cell of a double step is, per axis, the level nearest the
    mean of its two feet's values (the distance to a cell ``(c, c)`` is
    ``|r - c|² + |l - c|² = 2 |(r + l)/2 - c|² + const``).
    """

    def __init__(self, actions, fall_rates, source: str = "<arrays>"):
        actions = np.asarray(actions, dtype=float)
        fall_rates = np.asarray(fall_rates, dtype=float)
        where = f"fall model {source}"
        if actions.ndim != 2 or actions.shape[1] != 6 or actions.shape[0] == 0:
            raise ValueError(f"{where}: needs at least one cell of 6 unit action values, got shape {actions.shape}")
        if fall_rates.shape != (actions.shape[0],):
            raise ValueError(f"{where}: one fall rate per cell needed, got {fall_rates.shape} for {actions.shape[0]}")
        if not np.isfinite(actions).all():
            raise ValueError(f"{where}: cell actions must be finite")
        bad = np.flatnonzero(~(np.isfinite(fall_rates) & (fall_rates >= 0.0) & (fall_rates <= 1.0)))
        if bad.size:
            raise ValueError(
                f"{where}: fall_rate of cell {actions[bad[0]].tolist()} is {float(fall_rates[bad[0]])!r} "
                "(must be in [0, 1]; a cell without trials has none)"
            )
        self.actions, self.fall_rates, self.source = actions, fall_rates, source

    @classmethod
    def load(cls, path) -> CapabilityFallModel:
        """A capability map's CSV (or the directory holding ``capability.csv``)."""
        from footsim.calibration.capability import read_map  # capability imports the backends: not at import time

        cells = read_map(Path(path).expanduser())
        if not cells:
            raise ValueError(f"fall model {path}: the capability map has no cells")
        return cls([c.action for c in cells], [c.fall_rate for c in cells], str(path))

    def cell_index(self, action) -> int:
        """Row of the map's nearest cell to the unit action (6 values)."""
        a = np.asarray(action, dtype=float).reshape(6)
        return int(np.argmin(((self.actions - a) ** 2).sum(axis=1)))

    def probability(self, action) -> float:
        """The fall rate of the nearest cell."""
        return float(self.fall_rates[self.cell_index(action)])


def _draw(rng: np.random.Generator, scale: float) -> np.ndarray:
    """A random action: uniform in [-1, 1]^6 times a magnitude drawn in [0.25, 1] x ``scale``
    (small and large steps both well represented)."""
    return rng.uniform(-1.0, 1.0, 6) * rng.uniform(0.25, 1.0) * scale


# -- data ---------------------------------------------------------------------------------------
def collect(
    backend,
    n_steps: int,
    fell: Callable[[Any], bool],
    seed: int = 0,
    scale: float = 1.0,
    repeat: float = 0.9,
    progress: bool = True,
) -> dict[str, np.ndarray]:
    """Random double steps on ``backend``; arrays ``action (n,6), predicted (n,3), executed (n,3),
    fell (n,)`` (``executed`` is NaN where the robot fell or the sim failed).  ``fell(result)`` is
    the fall rule (the task's: ``footsim.tasks.nav.tilted_over``)."""

    rng = np.random.default_rng(seed)
    robot = backend.robot
    geometry = FootstepGeometry(robot.step_limits, robot.foot_length, robot.foot_width, backend.walk.foot_distance)
    scene = Scene(goal=Pose2D(100.0, 0.0, 0.0))
    rows: dict[str, list] = {"action": [], "predicted": [], "executed": [], "fell": []}
    pose = feet = None
    action = np.zeros(6)
    resets = 0
    iterator = range(n_steps)
    if progress:
        iterator = tqdm(iterator, desc=f"calibrating on {backend.name}", unit="double step", leave=False)
    for _ in iterator:
        if pose is None:
            pose = backend.reset(scene, np.random.default_rng(seed + 1000 + resets))
            feet = geometry.initial_feet()
            resets += 1
            action = _draw(rng, scale)
        elif rng.random() >= repeat:
            action = _draw(rng, scale)
        result = backend.execute(DoubleStep.from_action(action, robot.step_limits))
        assert feet is not None  # set together with pose at every reset
        after = (
            result.feet
            if result.feet is not None
            else geometry.execute(feet, DoubleStep.from_action(action, robot.step_limits))[1]
        )
        predicted = feet.nav_pose.relative(after.nav_pose)
        bad = fell(result) or result.sim_error is not None or not all(math.isfinite(v) for v in result.pose)
        executed = (math.nan,) * 3 if bad else tuple(pose.relative(result.pose))
        rows["action"].append(action.copy())
        rows["predicted"].append(tuple(predicted))
        rows["executed"].append(executed)
        rows["fell"].append(bool(bad))
        if bad:
            pose = None
        else:
            pose, feet = result.pose, after
    return {k: np.asarray(v, dtype=float) for k, v in rows.items()}


# -- fitting ------------------------------------------------------------------------------------
def fit_linear(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least squares ``y ≈ x @ coef.T + intercept`` per output: ``(coef (k,p), intercept (k,),
    residual σ (k,), R² (k,))``."""
    n, p = x.shape
    design = np.hstack([x, np.ones((n, 1))])
    solution, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = y - design @ solution
    dof = max(n - p - 1, 1)
    std = np.sqrt((residual**2).sum(axis=0) / dof)
    total = ((y - y.mean(axis=0)) ** 2).sum(axis=0)
    r2 = np.where(total > 0, 1.0 - (residual**2).sum(axis=0) / np.where(total > 0, total, 1.0), 1.0)
    return solution[:p].T, solution[p], std, r2


def fit_logistic(x: np.ndarray, y: np.ndarray, l2: float = 1e-2, iterations: int = 50) -> tuple[np.ndarray, float]:
    """Logistic regression by Newton's method with a small L2 penalty (not on the intercept)."""
    n, p = x.shape
    design = np.hstack([x, np.ones((n, 1))])
    w = np.zeros(p + 1)
    penalty = np.full(p + 1, l2)
    penalty[-1] = 0.0
    for _ in range(iterations):
        z = np.clip(design @ w, -30, 30)
        prob = 1.0 / (1.0 + np.exp(-z))
        grad = design.T @ (prob - y) + penalty * w
        hess = design.T @ (design * (prob * (1 - prob))[:, None]) + np.diag(penalty + 1e-9)
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.abs(step).max() < 1e-8:
            break
    return w[:p], float(w[p])


def fit(data: dict[str, np.ndarray], meta: dict | None = None, names=DEFAULT_FEATURES) -> dict:
    """The execution-model JSON payload from collected data (``names``: the regression features)."""
    names = tuple(names)
    if not names or set(names) - set(FEATURES):
        raise ValueError(f"features must be a non-empty subset of {list(FEATURES)}, got {list(names)}")
    ok = ~data["fell"].astype(bool)
    if ok.sum() < len(names) + 2:
        raise ValueError(f"too few double steps without a fall to fit ({int(ok.sum())}); raise n_steps or lower scale")
    x = features(data["predicted"][ok], names)
    coef, intercept, std, r2 = fit_linear(x, data["executed"][ok])
    fell = data["fell"].astype(float)
    fall = None
    if 0 < fell.sum() < len(fell):
        fc, fb = fit_logistic(np.abs(data["action"]), fell)
        fall = {"features": list(FALL_FEATURES), "coef": fc.tolist(), "intercept": fb, "rate": float(fell.mean())}
    # how far the uncorrected 2D prediction is from the executed displacement, per output
    raw = data["executed"][ok] - data["predicted"][ok]
    return {
        "format": FORMAT,
        "version": VERSION,
        "features": list(names),
        "outputs": list(OUTPUTS),
        "coef": coef.tolist(),
        "intercept": intercept.tolist(),
        "residual_std": std.tolist(),
        "r2": r2.tolist(),
        "fall": fall,
        "n_samples": int(len(fell)),
        "n_falls": int(fell.sum()),
        "uncorrected_rmse": np.sqrt((raw**2).mean(axis=0)).tolist(),
        "meta": meta or {},
    }
