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

**Filter.** State ``x = [p, v]``, ``p = [east, north]``, ``v`` its velocity: constant velocity
with white-noise acceleration of spectral density ``q = track_accel_sigma_mps2**2`` on either axis
(filterpy's ``Q_discrete_white_noise``). An echo measures ``p``. Its covariance ``R`` is not
isotropic: a rangefinder places the echo on its beam's axis, at the measured range, while the
obstacle may be anywhere across the cone. Along the beam (unit vector ``u``) the echo is good to
``s = track_echo_sigma_m``; across it (``n``) the cone's half-width ``w = range tan(beam_half)``
is one more sigma::

    R = s^2 u u^T + (s^2 + w^2) n n^T

A uniform spread over the cone would have variance ``w^2 / 3``, but successive echoes of one
obstacle share their error across the beam (it changes only as the beam sweeps over the obstacle),
and the filter, which takes every echo's error as independent of the last, would average a dozen
of them into a confident sideways velocity; the whole half-width keeps it from that.

Without it the filter took the echo's sideways slide as the obstacle's motion: a beam swept by the
rover's turn moves its echo across at range x yaw rate (a walker 3 m out, the rover turning at
0.44 rad/s: a track crossing at 1.3 m/s, SITL ``head_on`` world 146, where the rover then crossed
in front of the walker). With ``R`` shaped like the cone, a single beam tells the track's motion
along it and leaves the motion across it to the prior and to other beams; the velocity's
covariance says which (``Track.velocity_var``). The covariance ``P = [[A, C], [C^T, B]]`` in 2x2
blocks (position, position-velocity, velocity); a step of ``dt``::

    predict:  p += v dt;  A += dt (C + C^T) + dt^2 B + q dt^4 / 4 I;  C += dt B + q dt^3 / 2 I;  B += q dt^2 I
    update:   S = A + R;  K_p = A S^-1;  K_v = C^T S^-1;  y = z - p
              p += K_p y;  v += K_v y;  A -= K_p A;  C -= K_p C;  B -= K_v C

which is filterpy's ``KalmanFilter`` on the 4-state model (tests check it), written out on 2x2
blocks: no general-purpose linear algebra in the control loop (issue 17).

**Birth, confirmation, death.** An echo outside every gate starts a tentative track at the echo,
velocity 0 with standard deviation ``track_init_speed_sigma_mps`` on either axis. After
``track_confirm_hits`` echoes it is confirmed. A track that has had no echo for ``track_coast_s``
dies. At most ``track_max_count`` tracks live; a new one replaces the one silent longest.

**Moving.** A confirmed track is moving when its speed is at least ``track_min_speed_mps`` (below
it, echo and pose noise), at most ``track_max_speed_mps`` (above it, not an obstacle but a beam's
echo sliding along a surface as the rover turns), and it does not keep pace with the rover: its
velocity differs from the rover's ``r`` by at least ``track_min_speed_mps`` and, the rover moving,
by at least ``track_pace_sigma`` of its own standard deviations (``(v - r)^T B^-1 (v - r) >= k^2``;
a rover standing still slides no echo, and a slow walker's speed is only a sigma or two). A side
beam's echo slides along a wall the rover drives beside at the rover's own velocity, across the
beam, where the cone leaves the slide's speed uncertain; and an obstacle that keeps pace with the
rover needs no prediction anyway (its range does not change). Only moving tracks change what the
navigator sees.

Limits: echoes of two obstacles closer than the gate are merged (their velocity is then an
average). A static surface swept by a beam of a *turning* rover gives an echo sliding at range x
yaw rate; the cone-shaped ``R`` damps how much of that slide becomes velocity, but may make of it
an obstacle coming at the rover along the beam, and an echo sliding farther than the cone's width
(a long wall) still reads as moving. The autopilot leaves out moving tracks on a wall the
persistent-obstacle map knows (``obstacle_map.track_on_wall_m``,
``rover_ctl.navigation.obstacle_map``); a wall seen for the first time is not there yet. Telling
the two apart from the free space the beams see was tried (a track counted as a mover once an
echo of it fell where a beam had seen free space less than ``free_memory_s`` before) and made
paths longer: walls' echoes do that too (likely an echo placed on the beam's axis, in front of a
surface the cone found off the axis; not checked). SITL, worlds 1-40 of each, paths over 1.5
times the shortest: ``walls`` 10 -> 13, ``cul_de_sac`` 12 -> 17.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rover_ctl.config import ProximityParams


@dataclass
class Track:
    """One obstacle's estimate: position and velocity in ENU at ``time_s``, with its covariance in
    three 2x2 blocks (module docstring)."""

    ident: int
    time_s: float
    east_m: float
    north_m: float
    v_east_mps: float = 0.0
    v_north_mps: float = 0.0
    a: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Position covariance ``A`` as (ee, en, nn) (m^2)."""
    c: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    """Position-velocity covariance ``C`` as (e.ve, e.vn, n.ve, n.vn) (m^2/s)."""
    b: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Velocity covariance ``B`` as (ee, en, nn) (m^2/s^2)."""
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

    def velocity_var(self, ue: float, un: float) -> float:
        """Variance of the velocity's component along the unit vector ``(ue, un)`` (m^2/s^2)."""
        b_ee, b_en, b_nn = self.b
        return ue * ue * b_ee + 2.0 * ue * un * b_en + un * un * b_nn

    def snapshot(self) -> "Track":
        """A copy of the estimate (position and velocity; the tracker goes on updating its own)."""
        return Track(self.ident, self.time_s, self.east_m, self.north_m, self.v_east_mps, self.v_north_mps, b=self.b)

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
        (a_ee, a_en, a_nn), (c_ee, c_en, c_ne, c_nn), (b_ee, b_en, b_nn) = self.a, self.c, self.b
        dt2 = dt * dt
        qa, qc, qb = accel_var * dt2 * dt2 / 4.0, accel_var * dt2 * dt / 2.0, accel_var * dt2
        self.a = (a_ee + 2.0 * dt * c_ee + dt2 * b_ee + qa, a_en + dt * (c_en + c_ne) + dt2 * b_en, a_nn + 2.0 * dt * c_nn + dt2 * b_nn + qa)
        self.c = (c_ee + dt * b_ee + qc, c_en + dt * b_en, c_ne + dt * b_en, c_nn + dt * b_nn + qc)
        self.b = (b_ee + qb, b_en, b_nn + qb)
        self.time_s = time_s

    def update(self, east_m: float, north_m: float, r: tuple[float, float, float]) -> None:
        """Fuse one echo measured at ``time_s`` (predict first) with covariance ``r`` = (ee, en, nn) (m^2)."""
        (a_ee, a_en, a_nn), (c_ee, c_en, c_ne, c_nn), (b_ee, b_en, b_nn) = self.a, self.c, self.b
        s_ee, s_en, s_nn = a_ee + r[0], a_en + r[1], a_nn + r[2]
        det = s_ee * s_nn - s_en * s_en
        i_ee, i_en, i_nn = s_nn / det, -s_en / det, s_ee / det
        # Gains: K_p = A S^-1 (position), K_v = C^T S^-1 (velocity).
        kp = (a_ee * i_ee + a_en * i_en, a_ee * i_en + a_en * i_nn, a_en * i_ee + a_nn * i_en, a_en * i_en + a_nn * i_nn)
        kv = (c_ee * i_ee + c_ne * i_en, c_ee * i_en + c_ne * i_nn, c_en * i_ee + c_nn * i_en, c_en * i_en + c_nn * i_nn)
        y_e, y_n = east_m - self.east_m, north_m - self.north_m
        self.east_m += kp[0] * y_e + kp[1] * y_n
        self.north_m += kp[2] * y_e + kp[3] * y_n
        self.v_east_mps += kv[0] * y_e + kv[1] * y_n
        self.v_north_mps += kv[2] * y_e + kv[3] * y_n
        self.a = (a_ee - kp[0] * a_ee - kp[1] * a_en, a_en - kp[0] * a_en - kp[1] * a_nn, a_nn - kp[2] * a_en - kp[3] * a_nn)
        self.c = (c_ee - kp[0] * c_ee - kp[1] * c_ne, c_en - kp[0] * c_en - kp[1] * c_nn,
                  c_ne - kp[2] * c_ee - kp[3] * c_ne, c_nn - kp[2] * c_en - kp[3] * c_nn)  # fmt: skip
        self.b = (b_ee - kv[0] * c_ee - kv[1] * c_ne, b_en - kv[0] * c_en - kv[1] * c_nn, b_nn - kv[2] * c_en - kv[3] * c_nn)
        self.hits += 1
        self.last_echo_s = self.time_s


class ObstacleTracker:
    """Echoes -> tracks (see the module docstring)."""

    def __init__(self, params: ProximityParams) -> None:
        """``params`` is read at every call."""
        self.params = params
        self.tracks: list[Track] = []
        self._next_ident = 1

    def echo_covariance(self, axis_rad: float | None, range_m: float) -> tuple[float, float, float]:
        """(ee, en, nn) covariance (m^2) of an echo placed ``range_m`` out on a beam pointing
        ``axis_rad`` (ENU; None: isotropic): ``track_echo_sigma_m`` along the beam, and across it
        also the cone's half-width ``w = range tan(track_beam_half_deg)`` as one more sigma
        (module docstring)."""
        p = self.params
        along = p.track_echo_sigma_m**2
        if axis_rad is None or p.track_beam_half_deg <= 0.0:
            return along, 0.0, along
        across = along + (range_m * math.tan(math.radians(p.track_beam_half_deg))) ** 2
        c, s = math.cos(axis_rad), math.sin(axis_rad)
        return along * c * c + across * s * s, (along - across) * c * s, along * s * s + across * c * c

    def add(self, time_s: float, east_m: float, north_m: float, axis_rad: float | None = None, range_m: float = 0.0) -> int:
        """Associate one echo at ``time_s``, taken ``range_m`` out on a beam pointing ``axis_rad``
        (ENU; None: a point measured alike in every direction); returns the ident of the track it
        joined or started."""
        p = self.params
        self._expire(time_s)
        best, best_m = None, p.track_gate_m
        for track in self.tracks:
            e, n = track.position_at(time_s)
            distance_m = math.hypot(east_m - e, north_m - n)
            if distance_m <= best_m:
                best, best_m = track, distance_m
        r = self.echo_covariance(axis_rad, range_m)
        if best is not None:
            best.predict(time_s, p.track_accel_sigma_mps2**2)
            best.update(east_m, north_m, r)
            return best.ident
        if len(self.tracks) >= p.track_max_count:
            self.tracks.remove(min(self.tracks, key=lambda t: t.last_echo_s))
        v0 = p.track_init_speed_sigma_mps**2
        track = Track(self._next_ident, time_s, east_m, north_m, a=r, b=(v0, 0.0, v0), last_echo_s=time_s, born_en=(east_m, north_m))
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
        which do not keep pace with the rover (module docstring)."""
        p = self.params
        return [t for t in self.confirmed(time_s) if p.track_min_speed_mps <= t.speed_mps <= p.track_max_speed_mps
                and not self._keeps_pace(t, rover_velocity_en)]

    def _keeps_pace(self, track: Track, rover_velocity_en: tuple[float, float]) -> bool:
        """The track's velocity is within ``track_min_speed_mps`` of the rover's ``r`` or, the rover
        moving, within ``track_pace_sigma`` of its standard deviations: ``(v - r)^T B^-1 (v - r) < k^2``."""
        p = self.params
        de, dn = track.v_east_mps - rover_velocity_en[0], track.v_north_mps - rover_velocity_en[1]
        if math.hypot(de, dn) < p.track_min_speed_mps:
            return True
        if math.hypot(*rover_velocity_en) < p.track_min_speed_mps:  # a rover standing still slides no echo
            return False
        b_ee, b_en, b_nn = track.b
        det = b_ee * b_nn - b_en * b_en
        return det > 0.0 and (b_nn * de * de - 2.0 * b_en * de * dn + b_ee * dn * dn) < p.track_pace_sigma**2 * det
