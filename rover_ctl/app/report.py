"""The run report: metrics and plots from a run folder, after the fact.

Inputs (all in the run folder):

* ``control.csv``: the daemon's control-loop log (one row per control step, vehicle time ``t_s``);
* ``events.jsonl``: the daemon's events: ``frame`` (home of its local frame), ``mode``, ``plan``
  (path of a leg in ENU), ``reached`` (mission seq), ``complete``, ``failsafe``, ``statustext``;
* ``truth.jsonl``: the emulator's truth log (docs/architecture.md): ``state``, ``gps``,
  ``collision`` and ``fault`` records.

Errors against truth are taken at the control steps, with the truth state interpolated linearly
in time (10 Hz truth, 25 Hz control). Position error is the planar distance between estimate and
truth; heading error is wrapped to [-pi, pi). GPS error is the reported fix minus the true
position, split by the emulator into white, bias and glitch parts: ``gps_rmse_m`` is the RMS of the
whole error, ``gps_bias_rms_m`` that of the slow bias alone, which no filter can remove.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from rover_ctl.estimation.frame import LocalFrame, compass_to_enu_rad, wrap_pi
from rover_ctl.vocabulary import RoverMode



class ReportError(ValueError):
    """A run folder that lacks what the report needs; the message names the file."""


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """JSON lines; a torn last line (the writer was killed) is ignored, other bad lines refused."""
    if not path.exists():
        return []
    records = []
    lines = path.read_text(encoding="utf-8").splitlines()
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            if number == len(lines):
                break
            raise ReportError(f"{path}:{number}: not a JSON line") from None
    return records


def read_control(path: Path) -> dict[str, np.ndarray]:
    """control.csv as columns of floats (non-numeric cells become NaN)."""
    if not path.exists():
        raise ReportError(f"{path}: no control log (did the daemon start?)")
    with open(path, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        return {}

    def number(text: str) -> float:
        try:
            return float(text)
        except (TypeError, ValueError):
            return math.nan

    return {key: np.array([number(row[key]) for row in rows]) for key in rows[0]}


def _rms(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def _min(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return round(float(values.min()), 2) if values.size else math.nan


def _max(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(values.max()) if values.size else math.nan


def _path_length(east: np.ndarray, north: np.ndarray) -> float:
    return float(np.sum(np.hypot(np.diff(east), np.diff(north)))) if east.size > 1 else 0.0


class Run:
    """A run folder loaded: control columns, events, truth in the daemon's frame."""

    def __init__(self, run_dir: str | Path):
        self.dir = Path(run_dir)
        self.control = read_control(self.dir / "control.csv")
        self.events = read_jsonl(self.dir / "events.jsonl")
        self.truth_records = read_jsonl(self.dir / "truth.jsonl")
        frames = [e for e in self.events if e["type"] == "frame"]
        if not frames:
            raise ReportError(f"{self.dir / 'events.jsonl'}: no frame event (the daemon never had a home)")
        home = frames[-1]
        self.frame = LocalFrame(home["lat_deg"], home["lon_deg"], home.get("alt_m", 0.0))
        states = [r for r in self.truth_records if r["type"] == "state"]
        self.truth_t = np.array([r["t_s"] for r in states])
        if states:
            east, north = self.frame.to_enu(np.array([r["lat_deg"] for r in states]), np.array([r["lon_deg"] for r in states]))
            self.truth_east, self.truth_north = np.atleast_1d(east), np.atleast_1d(north)
            self.truth_heading = np.array([compass_to_enu_rad(math.radians(r["yaw_deg"])) for r in states])
        else:
            self.truth_east = self.truth_north = self.truth_heading = np.array([])
        self.collisions = [r for r in self.truth_records if r["type"] == "collision"]
        self.gps = [r for r in self.truth_records if r["type"] == "gps" and not r.get("dropped")]

    def active_window(self) -> tuple[float, float]:
        """Sim time from the first AUTO/RTL to mission completion (or the end of the log)."""
        starts = [e["t_s"] for e in self.events if e["type"] == "mode" and e["mode"] in (RoverMode.AUTO, RoverMode.RTL)]
        ends = [e["t_s"] for e in self.events if e["type"] == "complete"]
        t = self.control.get("t_s", np.array([0.0]))
        start = starts[0] if starts else float(t[0])
        end = ends[-1] if ends else float(t[-1])
        return start, end

    def truth_at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Truth east, north, heading at ``times`` (linear interpolation; heading unwrapped)."""
        if self.truth_t.size < 2:
            nan = np.full(times.shape, math.nan)
            return nan, nan, nan
        heading = np.unwrap(self.truth_heading)
        inside = (times >= self.truth_t[0]) & (times <= self.truth_t[-1])

        def interp(values: np.ndarray) -> np.ndarray:
            return np.where(inside, np.interp(times, self.truth_t, values), math.nan)

        return interp(self.truth_east), interp(self.truth_north), wrap_pi(interp(heading))


def compute_metrics(run: Run, timed_out: bool = False) -> dict[str, Any]:
    c = run.control
    start, end = run.active_window()
    complete = any(e["type"] == "complete" for e in run.events)
    t = c["t_s"]
    active = (t >= start) & (t <= end)
    te, tn, th = run.truth_at(t[active])
    position_err = np.hypot(c["est_east_m"][active] - te, c["est_north_m"][active] - tn)
    heading_err = wrap_pi(c["est_heading_rad"][active] - th)
    in_window = (run.truth_t >= start) & (run.truth_t <= end)
    gps_err = [
        math.hypot(g["err_white_e_m"] + g["err_bias_e_m"] + g["err_glitch_e_m"], g["err_white_n_m"] + g["err_bias_n_m"] + g["err_glitch_n_m"])
        for g in run.gps
    ]
    gps_bias = [math.hypot(g["err_bias_e_m"], g["err_bias_n_m"]) for g in run.gps]
    planned_m = 0.0
    leg_started = False
    for event in run.events:  # the first plan of each leg counts, re-plans do not
        if event["type"] in ("current", "mode"):
            leg_started = True
        elif event["type"] == "plan" and leg_started:
            planned_m += event["length_m"]
            leg_started = False
    reached = sorted({e["seq"] for e in run.events if e["type"] == "reached"})
    totals = [e["waypoints_total"] for e in run.events if e["type"] == "mission"]
    latency = c.get("latency_ms", np.array([]))
    latency = latency[np.isfinite(latency)]
    collisions = len(run.collisions)
    steps = t[active]
    # The control loop's rate against vehicle time: outside lockstep it can fall behind the vehicle.
    span_s = float(steps[-1] - steps[0]) if steps.size > 1 else math.nan
    return {
        "success": bool(complete and collisions == 0 and not timed_out),
        "complete": complete,
        "timed_out": timed_out,
        "collisions": collisions,
        "path_length_m": round(_path_length(run.truth_east[in_window], run.truth_north[in_window]), 2),
        "planned_length_m": round(planned_m, 2),
        "duration_s": round(end - start, 2),
        "cross_track_rms_m": round(_rms(c["cross_track_m"][active]), 3),
        "cross_track_max_m": round(_max(np.abs(c["cross_track_m"][active])), 3),
        "position_rmse_m": round(_rms(position_err), 3),
        "gps_rmse_m": round(_rms(np.array(gps_err)), 3),
        "gps_bias_rms_m": round(_rms(np.array(gps_bias)), 3),
        "heading_rmse_deg": round(math.degrees(_rms(heading_err)), 2),
        "control_rate_hz": round((steps.size - 1) / span_s, 2) if span_s > 0 else math.nan,
        "control_rate_min_hz": _min(c.get("loop_rate_hz", np.array([]))[active] if "loop_rate_hz" in c else np.array([])),
        "control_gap_max_s": round(float(np.max(np.diff(steps))), 3) if steps.size > 1 else math.nan,
        "loop_latency_p99_ms": round(float(np.percentile(latency, 99)), 3) if latency.size else math.nan,
        "waypoints_reached": len(reached),
        "waypoints_total": totals[-1] if totals else 0,
        "failsafes": sorted({r for e in run.events if e["type"] == "failsafe" for r in e["reasons"]}),
    }


def _world_shapes(world_path: Path | None, frame: LocalFrame) -> list[tuple[str, np.ndarray, float]]:
    """Obstacles of a world file as ("polygon", ENU vertices, 0) or ("circle", centre, radius)."""
    if world_path is None or not Path(world_path).exists():
        return []
    shapes = []
    for feature in json.loads(Path(world_path).read_text(encoding="utf-8")).get("features", []):
        geometry = feature.get("geometry") or {}
        if geometry.get("type") == "Polygon":
            ring = np.array(geometry["coordinates"][0], dtype=float)
            east, north = frame.to_enu(ring[:, 1], ring[:, 0])
            shapes.append(("polygon", np.column_stack([east, north]), 0.0))
        elif geometry.get("type") == "Point" and "radius_m" in feature.get("properties", {}):
            lon, lat = geometry["coordinates"][:2]
            shapes.append(("circle", np.array(frame.to_enu(lat, lon)), float(feature["properties"]["radius_m"])))
    return shapes


def make_plots(run: Run, world_path: Path | None = None) -> list[Path]:
    """map.png, motors.png and tracking.png in the run folder (matplotlib, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = run.control
    written = []
    start, end = run.active_window()

    fig, ax = plt.subplots(figsize=(8, 8))
    for kind, data, radius in _world_shapes(world_path, run.frame):
        if kind == "polygon":
            ax.fill(data[:, 0], data[:, 1], color="0.6", alpha=0.7)
        else:
            ax.add_patch(plt.Circle(tuple(data), radius, color="0.6", alpha=0.7))
    first_plan = True
    for event in run.events:
        if event["type"] == "plan" and event["path_en"]:
            path = np.array(event["path_en"])
            ax.plot(path[:, 0], path[:, 1], "--", color="tab:blue", lw=1, alpha=0.6, label="planned" if first_plan else None)
            first_plan = False
    for event in run.events:
        if event["type"] == "mission":
            wps = np.array(event.get("waypoints_en") or np.empty((0, 2)))
            if wps.size:
                ax.plot(wps[:, 0], wps[:, 1], "k^", ms=8, label="waypoints")
    if run.truth_east.size:
        ax.plot(run.truth_east, run.truth_north, color="tab:green", lw=2, label="driven (truth)")
    ax.plot(c["est_east_m"], c["est_north_m"], color="tab:orange", lw=1, label="estimate")
    for hit in run.collisions:
        e, n = run.frame.to_enu(hit["lat_deg"], hit["lon_deg"])
        ax.plot(e, n, "rx", ms=10)
    ax.plot(0, 0, "ks", label="home")
    ax.set_aspect("equal")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    ax.set_title("Map: obstacles, planned and driven path")
    written.append(_save(fig, run.dir / "map.png"))

    t = c["t_s"]
    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    axes[0].plot(t, c["left_set_rpm"], color="tab:blue", lw=1, label="left set")
    axes[0].plot(t, c["right_set_rpm"], color="tab:red", lw=1, label="right set")
    axes[0].plot(t, c["left_meas_rpm"], color="tab:blue", lw=0.6, alpha=0.5, label="left measured")
    axes[0].plot(t, c["right_meas_rpm"], color="tab:red", lw=0.6, alpha=0.5, label="right measured")
    axes[0].set_ylabel("wheel speed (rpm)")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].plot(t, np.where(np.isfinite(c["range_front_m"]), c["range_front_m"], np.nan), color="tab:purple")
    axes[1].set_ylabel("front range (m)")
    axes[2].plot(t, c["target_distance_m"], color="tab:green")
    axes[2].set_ylabel("target distance (m)")
    axes[3].plot(t, np.degrees(c["target_direction_rad"]), color="tab:brown")
    axes[3].set_ylabel("target direction (deg)")
    axes[3].set_xlabel("sim time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.axvspan(start, end, color="0.9", zorder=0)
    fig.suptitle("Motor speeds, front obstacle range, target distance and direction")
    written.append(_save(fig, run.dir / "motors.png"))

    te, tn, th = run.truth_at(t)
    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    axes[0].plot(t, c["cross_track_m"], color="tab:blue")
    axes[0].set_ylabel("cross-track (m)")
    axes[1].plot(t, np.hypot(c["est_east_m"] - te, c["est_north_m"] - tn), color="tab:orange")
    axes[1].set_ylabel("estimate error (m)")
    axes[2].plot(t, np.degrees(wrap_pi(c["est_heading_rad"] - th)), color="tab:green")
    axes[2].set_ylabel("heading error (deg)")
    axes[2].set_xlabel("sim time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle("Tracking error over time")
    written.append(_save(fig, run.dir / "tracking.png"))
    return written


def _save(fig: Any, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def write_report(run_dir: str | Path, world_path: str | Path | None = None, timed_out: bool = False, plots: bool = True) -> dict[str, Any]:
    """Compute the metrics, write metrics.json (and the plots) into the run folder, return them."""
    run = Run(run_dir)
    if not run.control:
        raise ReportError(f"{run.dir / 'control.csv'}: empty control log")
    metrics = compute_metrics(run, timed_out=timed_out)
    if plots:
        metrics["plots"] = [p.name for p in make_plots(run, Path(world_path) if world_path else None)]
    metrics = {key: _plain(value) for key, value in metrics.items()}
    (run.dir / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    return metrics


def _plain(value: Any) -> Any:
    """JSON-safe: numpy scalars to Python, NaN (a figure that could not be measured) to null."""
    if isinstance(value, (np.floating, np.integer)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
