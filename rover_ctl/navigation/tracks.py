"""Obstacle tracks with velocity: rangefinder echoes in ENU associated into tracks, each with a
constant-velocity Kalman filter, so that the navigator knows where an obstacle will be.

Pure: no clock, no I/O. The obstacle memory (``rover_ctl.navigation.proximity``) hands every echo
it remembers to ``ObstacleTracker.add`` and asks ``moving`` for the confirmed moving tracks.

**Association (gating).** An echo at time ``t`` joins the track whose position predicted to ``t``
is nearest, if that is within ``track_gate_m`` (Euclidean, metres: global nearest neighbour, one
echo at a time, as echoes come one per rangefinder reading). The gate is a fixed distance rather
than a Mahalanobis one because an echo is a point on an obstacle's surface, not its centre: as the
rover moves the point wanders over the surface by up to the obstacle's size, which no Gaussian
measurement model describes; the gate is about an obstacle's radius plus what it moves between
two echoes. Two obstacles closer than the gate share a track (see "Limits").

**Filter.** State ``[east, north, v_east, v_north]``, constant velocity with white-noise
acceleration of spectral density ``track_accel_sigma_mps2**2`` (filterpy's
``Q_discrete_white_noise``), position measured with isotropic noise ``track_echo_sigma_m``. The
two axes then share one model and, as the filter starts with a diagonal covariance, one 2x2
covariance ``P = [[pp, pv], [pv, vv]]`` for ``[position, velocity]`` of either axis; a step of
``dt`` is::

    predict:  x += v dt
              pp += 2 dt pv + dt^2 vv + q dt^4 / 4;   pv += dt vv + q dt^3 / 2;   vv += q dt^2
    update:   s = pp + r^2;  k_p = pp / s;  k_v = pv / s;  y = z - x
              x += k_p y;  v += k_v y
              vv -= k_v pv;  pv *= 1 - k_p;  pp *= 1 - k_p

which is exactly filterpy's ``KalmanFilter`` on the 4-state model (tests check it) at a fraction
of its cost in the control loop (issue 17: no general-purpose linear algebra per step).

**Birth, confirmation, death.** An echo outside every gate starts a tentative track at the echo,
velocity 0 with standard deviation ``track_init_speed_sigma_mps``. After ``track_confirm_hits``
echoes it is confirmed. A track that has had no echo for ``track_coast_s`` dies. At most
``track_max_count`` tracks live; a new one replaces the one silent longest.

**Moving.** A confirmed track is moving when its speed is at least ``track_min_speed_mps`` (below
it, echo and pose noise), at most ``track_max_speed_mps`` (above it, not an obstacle but a beam's
echo sliding along a surface as the rover turns), and its velocity differs from the rover's by at
least ``track_min_speed_mps``: a side beam's echo slides along a wall the rover drives beside at
the rover's own velocity, and an obstacle that keeps pace with the rover needs no prediction
anyway (its range does not change). Only moving tracks change what the navigator sees.

Limits: echoes of two obstacles closer than the gate are merged (their velocity is then an
average). A static surface swept by a beam of a *turning* rover gives an echo sliding at range x
yaw rate; below ``track_max_speed_mps`` (e.g. 2 m away turning at 0.5 rad/s) it is taken as
moving and predicted along the surface, which is where the surface is anyway, so it shortens a
neighbouring sector's range to the surface earlier than the beam would see it. Telling these
apart needs the free space the beams see (a beam passing where the track was), not done here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rover_ctl.config import ProximityParams


@dataclass
class Track:
    """One obstacle's estimate: position and velocity in ENU at ``time_s``."""

    ident: int
    time_s: float
    east_m: float
    north_m: float
    v_east_mps: float = 0.0
    v_north_mps: float = 0.0
    pp: float = 0.0
    """Position variance of either axis (m^2)."""
    pv: float = 0.0
    """Position-velocity covariance of either axis (m^2/s)."""
    vv: float = 0.0
    """Velocity variance of either axis (m^2/s^2)."""
    hits: int = 1
    last_echo_s: float = 0.0
    born_en: tuple[float, float] | None = None
    """Where the track started (its first echo): how far it has really gone tells a mover from an
    echo wandering over a static obstacle's face."""

    @property
    def travel_m(self) -> float:
        """Distance from the first echo to the current estimate (0 without a birth position)."""
        return 0.0 if self.born_en is None else math.hypot(self.east_m - self.born_en[0], self.north_m - self.born_en[1])

    @property
    def speed_mps(self) -> float:
        return math.hypot(self.v_east_mps, self.v_north_mps)

    def snapshot(self) -> "Track":
        """A copy of the estimate (position and velocity; the tracker goes on updating its own)."""
        return Track(self.ident, self.time_s, self.east_m, self.north_m, self.v_east_mps, self.v_north_mps)

    def position_at(self, time_s: float) -> tuple[float, float]:
        dt = time_s - self.time_s
        return self.east_m + self.v_east_mps * dt, self.north_m + self.v_north_mps * dt

    def predict(self, time_s: float, accel_var: float) -> None:
        """The constant-velocity prediction to ``time_s``. No-op for an earlier time: rangefinders
        report a few milliseconds apart and out of order, and such an echo is fused as if taken now."""
        dt = time_s - self.time_s
        if dt <= 0.0:
            return
        self.east_m += self.v_east_mps * dt
        self.north_m += self.v_north_mps * dt
        pp, pv, vv = self.pp, self.pv, self.vv
        self.pp = pp + 2.0 * dt * pv + dt * dt * vv + accel_var * dt**4 / 4.0
        self.pv = pv + dt * vv + accel_var * dt**3 / 2.0
        self.vv = vv + accel_var * dt * dt
        self.time_s = time_s

    def update(self, east_m: float, north_m: float, echo_var: float) -> None:
        """Fuse one echo measured at ``time_s`` (predict first)."""
        s = self.pp + echo_var
        k_p, k_v = self.pp / s, self.pv / s
        y_east, y_north = east_m - self.east_m, north_m - self.north_m
        self.east_m += k_p * y_east
        self.north_m += k_p * y_north
        self.v_east_mps += k_v * y_east
        self.v_north_mps += k_v * y_north
        self.vv -= k_v * self.pv
        self.pv *= 1.0 - k_p
        self.pp *= 1.0 - k_p
        self.hits += 1
        self.last_echo_s = self.time_s


class ObstacleTracker:
    """Echoes -> tracks (see the module docstring)."""

    def __init__(self, params: ProximityParams) -> None:
        """``params`` is read at every call."""
        self.params = params
        self.tracks: list[Track] = []
        self._next_ident = 1

    def add(self, time_s: float, east_m: float, north_m: float) -> int:
        """Associate one echo at ``time_s``; returns the ident of the track it joined or started."""
        p = self.params
        self._expire(time_s)
        best, best_m = None, p.track_gate_m
        for track in self.tracks:
            e, n = track.position_at(time_s)
            distance_m = math.hypot(east_m - e, north_m - n)
            if distance_m <= best_m:
                best, best_m = track, distance_m
        if best is not None:
            best.predict(time_s, p.track_accel_sigma_mps2**2)
            best.update(east_m, north_m, p.track_echo_sigma_m**2)
            return best.ident
        if len(self.tracks) >= p.track_max_count:
            self.tracks.remove(min(self.tracks, key=lambda t: t.last_echo_s))
        track = Track(self._next_ident, time_s, east_m, north_m, pp=p.track_echo_sigma_m**2,
                      vv=p.track_init_speed_sigma_mps**2, last_echo_s=time_s, born_en=(east_m, north_m))  # fmt: skip
        self._next_ident += 1
        self.tracks.append(track)
        return track.ident

    def _expire(self, time_s: float) -> None:
        self.tracks = [t for t in self.tracks if time_s - t.last_echo_s <= self.params.track_coast_s]

    def confirmed(self, time_s: float) -> list[Track]:
        """Tracks alive at ``time_s`` with at least ``track_confirm_hits`` echoes."""
        self._expire(time_s)
        return [t for t in self.tracks if t.hits >= self.params.track_confirm_hits]

    def moving(self, time_s: float, rover_velocity_en: tuple[float, float] = (0.0, 0.0)) -> list[Track]:
        """Confirmed tracks whose speed is within [track_min_speed_mps, track_max_speed_mps] and
        whose velocity differs from the rover's by at least track_min_speed_mps."""
        p = self.params
        return [t for t in self.confirmed(time_s) if p.track_min_speed_mps <= t.speed_mps <= p.track_max_speed_mps
                and math.hypot(t.v_east_mps - rover_velocity_en[0], t.v_north_mps - rover_velocity_en[1]) >= p.track_min_speed_mps]  # fmt: skip
