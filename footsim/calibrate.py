"""Calibrated 2D: ``footsim-calibrate backend=mujoco [n_steps=600] [seed=0] [scale=0.7] out=FILE.json``.

Rolls out random double steps (with probability ``repeat`` the previous action again, so steady
walking dominates as in a policy's gait) on a 3D backend from an empty scene, resetting after a
fall.  For every double step it records

* the displacement the planar footstep geometry predicts (what the 2D backend executes): the
  navigation frame (mean of the two feet) after the step in the frame before it, from the walk
  engine's footsteps (``StepResult.feet``);
* the displacement the simulated robot really made: the base's planar pose after the step in
  the frame of the base before it (``StepResult.pose``);
* whether it fell.

(uniform in ``[-1, 1]`` times a magnitude drawn in ``[0.25, 1] × scale`` per new action) and fits the **execution model**: per output (dx, dy, dθ) a linear regression on the predicted
displacement (``features=dx,dy,dtheta`` by default; ``abs_dx, abs_dy, abs_dtheta`` can be added)
with intercept and residual σ, and the fall probability per double step as a logistic regression on
the absolute action values.  ``backend=pymunk backend.execution_model=FILE`` makes the 2D
backend execute through it (:class:`ExecutionModel`, ``footsim.backends.pymunk2d``).

``footsim-calibrate compare=FILE.json [backend=mujoco] [out=FILE.md]`` runs the walkcheck
sequences on pymunk with and without the model and on the 3D backend and prints the
consistency table (final planar pose differences).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

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


def _draw(rng: np.random.Generator, scale: float) -> np.ndarray:
    """A random action: uniform in [-1, 1]^6 times a magnitude drawn in [0.25, 1] x ``scale``
    (small and large steps both well represented)."""
    return rng.uniform(-1.0, 1.0, 6) * rng.uniform(0.25, 1.0) * scale


# -- data ---------------------------------------------------------------------------------------
def collect(
    backend, n_steps: int, seed: int = 0, scale: float = 1.0, repeat: float = 0.9, progress: bool = True
) -> dict[str, np.ndarray]:
    """Random double steps on ``backend``; arrays ``action (n,6), predicted (n,3), executed (n,3),
    fell (n,)`` (``executed`` is NaN where the robot fell or the sim failed)."""
    from footsim.geometry import Pose2D
    from footsim.scene import Scene
    from footsim.walk.footsteps import DoubleStep, FootstepGeometry

    rng = np.random.default_rng(seed)
    robot = backend.robot
    geometry = FootstepGeometry(robot.step_limits, robot.foot_length, robot.foot_width, backend.walk.foot_distance)
    scene = Scene(goal=Pose2D(100.0, 0.0, 0.0))
    rows = {"action": [], "predicted": [], "executed": [], "fell": []}
    pose = feet = None
    action = np.zeros(6)
    resets = 0
    iterator = range(n_steps)
    if progress:
        from tqdm import tqdm

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
        after = (
            result.feet
            if result.feet is not None
            else geometry.execute(feet, DoubleStep.from_action(action, robot.step_limits))[1]
        )
        predicted = feet.nav_pose.relative(after.nav_pose)
        bad = result.fell or result.sim_error is not None or not all(math.isfinite(v) for v in result.pose)
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


# -- 2D vs 3D consistency -----------------------------------------------------------------------
def consistency(model_path: str, backend3d: str = "mujoco", seed: int = 0) -> tuple[list[dict], str]:
    """Walkcheck sequences on pymunk (geometry), pymunk + model (mean, and with noise) and the 3D
    backend: final planar pose differences to the 3D backend, over the full sequences (as
    ``footsim-walkcheck``) and with the 2D runs cut at the double step where the 3D robot fell."""
    from footsim import config as fconf
    from footsim.geometry import wrap_angle
    from footsim.walkcheck import Sequence, make_backend, run_sequence, standard_sequences

    ExecutionModel.load(model_path)  # a bad file fails before the 3D runs
    sequences = standard_sequences()
    ref_backend = make_backend(backend3d)
    try:
        ref = {s.name: run_sequence(ref_backend, s, seed=seed) for s in sequences}
    finally:
        ref_backend.close()
    walk = fconf.build_walk(fconf.load_preset("walk", backend="pymunk"))
    robot = fconf.build_robot("wolfgang")
    variants = {
        "pymunk (geometry)": {},
        "pymunk + model (mean)": {"execution_model": model_path, "execution_noise": False},
        "pymunk + model (with noise)": {"execution_model": model_path},
    }
    rows = []
    for label, options in variants.items():
        backend = fconf.build_backend({"name": "pymunk", **options}, robot, walk)
        try:
            for cut in (False, True):
                dp, dy, dyaw = [], [], []
                for s in sequences:
                    seq = s
                    if cut and ref[s.name]["steps"] < len(s.actions):
                        seq = Sequence(s.name, s.actions[: ref[s.name]["steps"]], s.measure, s.stop)
                    ra = run_sequence(backend, seq, seed=seed)
                    a, b = ra["pose"], ref[s.name]["pose"]
                    dyaw.append(abs(ra["yaw"] - ref[s.name]["yaw"]))
                    dp.append(math.hypot(a.x - b.x, a.y - b.y))
                    dy.append(abs(wrap_angle(a.theta - b.theta)))
                rows.append(
                    {
                        "pair": f"{label} – {backend3d}",
                        "sequences": "cut at 3D fall" if cut else "full",
                        "pos_mean": float(np.mean(dp)),
                        "pos_max": float(np.max(dp)),
                        "yaw_mean": float(np.mean(dy)),
                        "yaw_max": float(np.max(dy)),
                        "turn_mean": float(np.mean(dyaw)),
                        "turn_max": float(np.max(dyaw)),
                    }
                )
        finally:
            backend.close()
    lines = [
        "| pair | sequences | position diff mean [m] | max [m] | yaw diff mean [rad] | max [rad] "
        "| total turn diff mean [rad] | max [rad] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted(rows, key=lambda r: r["sequences"] != "full"):
        lines.append(
            f"| {r['pair']} | {r['sequences']} | {r['pos_mean']:.3f} | {r['pos_max']:.3f} | "
            f"{r['yaw_mean']:.3f} | {r['yaw_max']:.3f} | {r['turn_mean']:.3f} | {r['turn_max']:.3f} |"
        )
    falls = [
        f"{s.name} ({ref[s.name]['steps']}/{len(s.actions)})"
        for s in sequences
        if ref[s.name]["fell"] or ref[s.name]["sim_error"]
    ]
    lines += ["", f"{backend3d} fell in: {', '.join(falls) if falls else 'none'}"]
    return rows, "\n".join(lines)


# -- command ------------------------------------------------------------------------------------
USAGE = (
    "usage: footsim-calibrate backend=mujoco [n_steps=800] [seed=0] [scale=1.0] [repeat=0.9] "
    "[features=dx,dy,dtheta] out=FILE.json\n"
    "       footsim-calibrate compare=FILE.json [backend=mujoco] [out=FILE.md]"
)


def main(argv: list[str] | None = None) -> None:
    from footsim.backends.base import require_known_backends
    from footsim.rl.common import write_json
    from footsim.utils import atomic_write_text, parse_kv_args

    args = parse_kv_args(
        sys.argv[1:] if argv is None else argv,
        {
            "backend": "mujoco",
            "n_steps": "800",
            "seed": "0",
            "scale": "1.0",
            "repeat": "0.9",
            "features": ",".join(DEFAULT_FEATURES),
            "out": "",
            "compare": "",
        },
        "footsim-calibrate",
    )
    require_known_backends([args["backend"]], "footsim-calibrate")
    if args["compare"]:
        _, table = consistency(args["compare"], args["backend"], int(args["seed"]))
        print(table)
        if args["out"]:
            atomic_write_text(args["out"], table + "\n")
        return
    if not args["out"]:
        raise SystemExit(f"footsim-calibrate: out=FILE.json is required\n{USAGE}")
    try:
        n_steps, seed = int(args["n_steps"]), int(args["seed"])
        scale, repeat = float(args["scale"]), float(args["repeat"])
    except ValueError as err:
        raise SystemExit(f"footsim-calibrate: bad number ({err})\n{USAGE}")
    if n_steps <= 0 or not 0 < scale <= 1 or not 0 <= repeat < 1:
        raise SystemExit("footsim-calibrate: need n_steps > 0, 0 < scale <= 1, 0 <= repeat < 1")
    if args["backend"] == "pymunk":
        raise SystemExit("footsim-calibrate: calibrate against a 3D backend (mujoco, dm_control, pybullet)")
    from footsim.walkcheck import make_backend

    backend = make_backend(args["backend"])
    try:
        data = collect(backend, n_steps, seed, scale, repeat)
    finally:
        backend.close()
    names = [f for f in args["features"].split(",") if f]
    model = fit(
        data,
        meta={"backend": args["backend"], "n_steps": n_steps, "seed": seed, "scale": scale, "repeat": repeat},
        names=names,
    )
    write_json(args["out"], model)
    print(f"{model['n_samples']} double steps, {model['n_falls']} falls on {args['backend']}")
    for k, name in enumerate(OUTPUTS):
        terms = " ".join(f"{c:+.3f}·{f}" for c, f in zip(model["coef"][k], names))
        print(
            f"  {name} = {terms} {model['intercept'][k]:+.4f}   σ={model['residual_std'][k]:.4f}  "
            f"R²={model['r2'][k]:.3f}  (uncorrected 2D RMSE {model['uncorrected_rmse'][k]:.4f})"
        )
    print(f"execution model written to {args['out']}")
