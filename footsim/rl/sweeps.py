"""Hydra multirun support: a failure marker per job and ``footsim-sweep-summary``.

* :class:`JobStatusCallback` (configured in ``conf/config.yaml`` under ``hydra.callbacks``) runs at
  the end of every job, in the job's own process, whatever the launcher.  When the task raised,
  it writes ``FAILED.json`` (error, traceback, overrides) into the job's run dir, so a crashed
  job is visible in the sweep directory itself; Hydra still runs the other jobs of the batch and
  exits non-zero at the end.
* ``footsim-sweep-summary dir=MULTIRUN_DIR [out=PREFIX]`` gathers every job below a multirun
  directory (any directory holding ``.hydra/overrides.yaml``) into one table: job, status
  (``ok`` / ``failed`` / ``no_eval``), the job's overrides, and its ``eval/summary.json``.
  Writes ``PREFIX.csv`` and ``PREFIX.md`` atomically (default ``MULTIRUN_DIR/sweep_summary``)
  and prints the markdown table.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
import traceback
from pathlib import Path
from typing import Any

from hydra.core.utils import JobStatus
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import OmegaConf

from footsim.rl.common import SUMMARY_METRICS, write_json
from footsim.utils import atomic_write_text

FAILED_FILE = "FAILED.json"
SUMMARY_FILE = Path("eval") / "summary.json"


# -- failure marker ---------------------------------------------------------------------------
class JobStatusCallback(Callback):
    """Writes ``FAILED.json`` into a job's run dir when its task function raised."""

    def on_job_end(self, config, job_return, **kwargs: Any) -> None:
        try:
            out_dir = Path(str(job_return.hydra_cfg.hydra.runtime.output_dir))
        except Exception:  # no hydra config: nothing sensible to write
            return
        marker = out_dir / FAILED_FILE
        if job_return.status != JobStatus.FAILED:
            marker.unlink(missing_ok=True)  # a re-run into the same dir succeeded
            return
        error = job_return._return_value  # the exception (reading .return_value would re-raise it)
        record = {
            "error": f"{type(error).__name__}: {error}",
            "traceback": "".join(traceback.format_exception(type(error), error, error.__traceback__)),
            "overrides": list(job_return.overrides or []),
            "job_num": _job_num(job_return),
        }

        write_json(marker, record)
        if _multirun(job_return):
            print(
                f"footsim: job {record['job_num']} ({' '.join(record['overrides'])}) failed: {record['error']} "
                f"(details: {marker}); the other jobs go on",
                file=sys.stderr,
                flush=True,
            )


def _multirun(job_return) -> bool:
    try:
        return job_return.hydra_cfg.hydra.mode == RunMode.MULTIRUN
    except Exception:
        return False


def _job_num(job_return) -> Any:
    try:
        return job_return.hydra_cfg.hydra.job.num
    except Exception:
        return None


# -- summary -----------------------------------------------------------------------------------
def _scalar(value: Any) -> bool:
    return value is None or isinstance(value, (bool, int, float, str))


def _job_sort_key(path: Path):
    return [(0, int(p), "") if p.isdigit() else (1, 0, p) for p in path.parts]


def find_jobs(sweep_dir: Path) -> list[Path]:
    """Every job directory (holding ``.hydra/overrides.yaml``) below ``sweep_dir``, in job order."""
    jobs = [p.parent.parent for p in sweep_dir.rglob(".hydra/overrides.yaml")]
    return sorted(jobs, key=lambda p: _job_sort_key(p.relative_to(sweep_dir)))


def _read_overrides(job: Path) -> dict[str, str]:
    overrides: dict[str, str] = {}
    for item in OmegaConf.to_container(OmegaConf.load(job / ".hydra" / "overrides.yaml")) or []:
        key, sep, value = str(item).partition("=")
        overrides[key.lstrip("+~")] = value if sep else ""
    return overrides


def collect(sweep_dir: str | Path) -> list[dict[str, Any]]:
    """One row per job: ``job``, ``status``, ``error``, ``overrides`` (dict) and ``metrics`` (dict)."""
    sweep_dir = Path(sweep_dir)
    rows = []
    for job in find_jobs(sweep_dir):
        row: dict[str, Any] = {
            "job": str(job.relative_to(sweep_dir)) or ".",
            "status": "ok",
            "error": "",
            "overrides": _read_overrides(job),
            "metrics": {},
        }
        if (job / FAILED_FILE).is_file():
            row["status"] = "failed"
            try:
                row["error"] = json.loads((job / FAILED_FILE).read_text()).get("error", "")
            except (OSError, ValueError) as exc:
                row["error"] = f"unreadable {FAILED_FILE}: {exc}"
        elif (job / SUMMARY_FILE).is_file():
            try:
                summary = json.loads((job / SUMMARY_FILE).read_text())
                row["metrics"] = {k: v for k, v in summary.items() if _scalar(v) and k != "label"}
            except (OSError, ValueError) as exc:
                row["status"], row["error"] = "failed", f"unreadable {SUMMARY_FILE}: {exc}"
        else:  # still running, killed without a marker, or eval.after_train=false
            row["status"] = "no_eval"
            row["error"] = "no eval/summary.json" + ("" if (job / "model.zip").is_file() else " and no model.zip")
        rows.append(row)
    return rows


def _columns(rows: list[dict]) -> tuple[list[str], list[str]]:
    override_keys: list[str] = []
    for row in rows:
        override_keys += [k for k in row["overrides"] if k not in override_keys]
    metric_keys = {k for row in rows for k in row["metrics"]}
    ordered = [k for k in SUMMARY_METRICS if k in metric_keys] + sorted(metric_keys - set(SUMMARY_METRICS))
    return override_keys, ordered


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.4g}"
    return str(value)


def to_csv(rows: list[dict]) -> str:
    override_keys, metric_keys = _columns(rows)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["job", "status", *override_keys, *metric_keys, "error"])
    for row in rows:
        writer.writerow(
            [
                row["job"],
                row["status"],
                *(row["overrides"].get(k, "") for k in override_keys),
                *(row["metrics"].get(k, "") for k in metric_keys),
                row["error"],
            ]
        )
    return buf.getvalue()


def to_markdown(rows: list[dict], title: str = "") -> str:
    """Markdown table; overrides shared by every job are listed above it instead of as columns."""
    override_keys, metric_keys = _columns(rows)
    common = {
        k: rows[0]["overrides"].get(k)
        for k in override_keys
        if all(k in r["overrides"] and r["overrides"][k] == rows[0]["overrides"][k] for r in rows)
    }
    varying = [k for k in override_keys if k not in common] if len(rows) > 1 else []
    if len(rows) == 1:
        common = dict(rows[0]["overrides"])
    lines = [f"# Sweep summary: {title}", ""] if title else []
    n_failed = sum(r["status"] != "ok" for r in rows)
    lines.append(f"{len(rows)} jobs, {len(rows) - n_failed} ok, {n_failed} failed or without evaluation.")
    if common:
        lines += ["", "Common overrides: " + " ".join(f"`{k}={v}`" for k, v in common.items())]
    header = ["job", "status", *varying, *metric_keys, "error"]
    lines += ["", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        cells = [
            row["job"],
            row["status"],
            *(_fmt(row["overrides"].get(k)) for k in varying),
            *(_fmt(row["metrics"].get(k)) for k in metric_keys),
            row["error"],
        ]
        lines.append("| " + " | ".join(c.replace("|", "\\|").replace("\n", " ") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def write_summary(sweep_dir: str | Path, out_prefix: str | Path | None = None) -> tuple[Path, Path, list[dict]]:
    sweep_dir = Path(sweep_dir)
    if not sweep_dir.is_dir():
        raise FileNotFoundError(f"dir: {sweep_dir} is not a directory")
    rows = collect(sweep_dir)
    if not rows:
        raise FileNotFoundError(f"dir: no Hydra jobs (.hydra/overrides.yaml) below {sweep_dir}")
    prefix = Path(out_prefix) if out_prefix else sweep_dir / "sweep_summary"
    csv_path, md_path = prefix.with_name(prefix.name + ".csv"), prefix.with_name(prefix.name + ".md")
    atomic_write_text(csv_path, to_csv(rows))
    atomic_write_text(md_path, to_markdown(rows, title=str(sweep_dir)))
    return csv_path, md_path, rows
