"""Tune the quintic walk (and a few motor settings) for the PyBullet backend.

    python scripts/tune_walk_pybullet.py eval                      # walkcheck-style table, current conf
    python scripts/tune_walk_pybullet.py eval trunk_pitch=0.1 backend.position_gain_scale=3
    python scripts/tune_walk_pybullet.py search trials=40 seed=0   # random search around the conf

Runs the standard walk-check sequences (``footsim.calibration.walkcheck``) on PyBullet with overrides of
``conf/walk/pybullet.yaml`` (``key=value``) and ``conf/backend/pybullet.yaml``
(``backend.key=value``).  The search samples around the current values, scores each candidate
(sequences passed, then the mean displacement error), stops a candidate at its first failure
(to keep the run lean on a shared machine), and prints the best overrides found.  Single core.
"""

from __future__ import annotations

import math
import sys
import time

import footsim  # noqa: F401  (before NumPy loads: footsim pins OpenBLAS's kernels)

# isort: split
import numpy as np

from footsim import config as fconf
from footsim.calibration.walkcheck import TOLERANCE, error_ratio, run_sequence, standard_sequences

# Search ranges (FACTS: the ranges the Bit-Bots' Optuna study used, narrowed where our model needs).
RANGES = {
    "freq": (1.4, 2.4),
    "double_support_ratio": (0.0, 0.4),
    "foot_rise": (0.04, 0.09),
    "trunk_height": (0.37, 0.40),
    "trunk_pitch": (-0.15, 0.25),
    "trunk_swing": (0.0, 0.8),
    "trunk_phase": (-0.4, 0.3),
    "trunk_x_offset": (-0.03, 0.03),
    "trunk_y_offset": (-0.01, 0.01),
    "trunk_z_movement": (0.0, 0.03),
    "trunk_pitch_p_coef_forward": (-1.0, 1.0),
    "trunk_pitch_p_coef_turn": (-0.5, 0.5),
    "first_step_swing_factor": (0.5, 2.0),
    "backend.position_gain_scale": (1.0, 8.0),
}


def _commanded(sequences) -> dict:
    backend = make("pymunk", {}, {})
    try:
        return {s.name: run_sequence(backend, s) for s in sequences}
    finally:
        backend.close()


def make(name: str, walk_over: dict, backend_over: dict):
    walk_cfg = fconf.load_preset("walk", backend="pybullet")
    walk_cfg.update(walk_over)
    robot = fconf.build_robot("wolfgang")
    backend_cfg = fconf.load_preset("backend", {"name": name, **(backend_over if name == "pybullet" else {})})
    return fconf.build_backend(backend_cfg, robot, fconf.build_walk(walk_cfg))


def evaluate(walk_over: dict, backend_over: dict, sequences, commanded, stop_at_failure=False, verbose=False):
    """(passed, mean error, rows) of the sequences on PyBullet with these overrides."""
    backend = make("pybullet", walk_over, backend_over)
    passed, errors, rows = 0, [], []
    try:
        for seq in sequences:
            res = run_sequence(backend, seq)
            ratio = error_ratio(res, commanded[seq.name], seq.measure)
            ok = not res["fell"] and res["sim_error"] is None and ratio <= TOLERANCE
            passed += ok
            errors.append(min(ratio, 2.0) + (1.0 if res["fell"] else 0.0))
            rows.append((seq.name, res["steps"], len(seq.actions), res["fell"], ratio, ok))
            if verbose:
                print(
                    f"  {seq.name:22s} {res['steps']:3d}/{len(seq.actions)} fell={res['fell']!s:5} "
                    f"err={100 * ratio:5.0f}% {'ok' if ok else 'FAIL'}",
                    flush=True,
                )
            if stop_at_failure and not ok:
                break
    finally:
        backend.close()
    return passed, float(np.mean(errors)), rows


def _parse(args: list[str]) -> tuple[dict, dict, dict]:
    walk_over, backend_over, opts = {}, {}, {}
    for arg in args:
        key, _, value = arg.partition("=")
        if key.startswith("backend."):
            backend_over[key[8:]] = float(value)
        elif key in ("trials", "seed", "scale"):
            opts[key] = float(value)
        else:
            walk_over[key] = float(value)
    return walk_over, backend_over, opts


def main(argv: list[str]) -> None:
    mode = argv[0] if argv else "eval"
    walk_over, backend_over, opts = _parse(argv[1:])
    sequences = standard_sequences()
    commanded = _commanded(sequences)
    if mode == "eval":
        t = time.perf_counter()
        passed, err, _ = evaluate(walk_over, backend_over, sequences, commanded, verbose=True)
        print(f"passed {passed}/{len(sequences)}, mean error {err:.3f}, {time.perf_counter() - t:.0f} s")
        return
    rng = np.random.default_rng(int(opts.get("seed", 0)))
    scale = opts.get("scale", 0.15)
    base = fconf.load_preset("walk", backend="pybullet")
    base.update(walk_over)
    backend_base = fconf.load_preset("backend", "pybullet")
    base.update({f"backend.{k}": v for k, v in backend_base.items() if f"backend.{k}" in RANGES})
    base.update({f"backend.{k}": v for k, v in backend_over.items()})
    best = (-1, math.inf, {})
    for trial in range(int(opts.get("trials", 20))):
        cand = {}
        if trial > 0:
            start = {**base, **best[2]}
            for key, (lo, hi) in RANGES.items():
                if rng.random() < 0.4:
                    cand[key] = float(np.clip(start[key] + rng.normal(0, scale * (hi - lo)), lo, hi))
            cand = {**best[2], **cand}
        walk_c = {k: v for k, v in cand.items() if not k.startswith("backend.")}
        back_c = {**backend_over, **{k[8:]: v for k, v in cand.items() if k.startswith("backend.")}}
        passed, err, _ = evaluate(walk_c, back_c, sequences, commanded, stop_at_failure=False)
        if (passed, -err) > (best[0], -best[1]):
            best = (passed, err, cand)
        print(
            f"trial {trial}: passed {passed} err {err:.3f} | best {best[0]} {best[1]:.3f} "
            + " ".join(f"{k}={v:.4g}" for k, v in best[2].items()),
            flush=True,
        )
        if best[0] == len(sequences):
            break


if __name__ == "__main__":
    main(sys.argv[1:])
