"""Mission executor: acceptance, hold times, DO_JUMP counts, loiter, RTL, delays, speed, skips."""

from __future__ import annotations

import pytest

from rover_ctl.config import ExecutorParams
from rover_ctl.autopilot.executor import EventKind, MissionExecutor, Mode, Severity
from rover_ctl.mission.model import FRAME_GLOBAL_RELATIVE_ALT, FRAME_MISSION, MissionItem

MAX_SPEED_MPS = 1.5
PARAMS = ExecutorParams(acceptance_radius_m=2.0, cruise_speed_mps=1.0, rtl_radius_m=1.0)


def to_enu(lat: float, lon: float) -> tuple[float, float]:
    """Test frame: latitude is north metres, longitude east metres."""
    return (lon, lat)


def wp(east: float, north: float, hold_s: float = 0.0, radius_m: float = 0.0) -> MissionItem:
    return MissionItem(16, FRAME_GLOBAL_RELATIVE_ALT, hold_s, radius_m, x=north, y=east)


def do(command: int, *params: float) -> MissionItem:
    return MissionItem(command, FRAME_MISSION, *params)


def executor(*items: MissionItem, params: ExecutorParams = PARAMS) -> MissionExecutor:
    ex = MissionExecutor(list(items), to_enu, params, MAX_SPEED_MPS)
    ex.start()
    return ex


def kinds(output, kind):
    return [e.seq for e in output.events if e.kind is kind]


def drive(ex: MissionExecutor, t0: float = 0.0, dt: float = 0.1, steps: int = 10_000, stop_after: int | None = None):
    """Teleport the rover to each target: return the sequence of reached seqs and the last time."""
    reached, t, position = [], t0, (0.0, 0.0)
    for _ in range(steps):
        out = ex.update(t, position)
        reached += kinds(out, EventKind.ITEM_REACHED)
        if ex.complete or (stop_after is not None and len(reached) >= stop_after):
            return reached, t
        if out.target_en is not None:
            position = out.target_en
        t += dt
    raise AssertionError("mission did not finish")


def test_waypoint_reached_within_acceptance_radius_only():
    ex = executor(wp(10, 0), wp(10, 10, radius_m=0.5))
    out = ex.update(0.0, (0.0, 0.0))
    assert out.target_en == (10.0, 0.0) and not out.hold and out.current_seq == 1
    assert kinds(out, EventKind.CURRENT) == [1]
    assert out.speed_limit_mps == pytest.approx(1.0) and out.acceptance_radius_m == 2.0
    assert not kinds(ex.update(0.1, (7.9, 0.0)), EventKind.ITEM_REACHED)
    out = ex.update(0.2, (8.1, 0.0))
    assert kinds(out, EventKind.ITEM_REACHED) == [1] and kinds(out, EventKind.CURRENT) == [2]
    assert out.target_en == (10.0, 10.0) and out.acceptance_radius_m == 0.5
    assert not kinds(ex.update(0.3, (10.0, 9.4)), EventKind.ITEM_REACHED)  # item's own radius, 0.5 m
    out = ex.update(0.4, (10.0, 9.6))
    assert kinds(out, EventKind.ITEM_REACHED) == [2] and kinds(out, EventKind.COMPLETE) == [2]
    assert ex.complete and out.hold and out.target_en is None
    assert ex.update(0.5, (10.0, 9.6)).hold  # complete -> hold


def test_hold_time_at_a_waypoint():
    ex = executor(wp(5, 0, hold_s=3.0), wp(5, 5))
    ex.update(0.0, (0.0, 0.0))
    reached = ex.update(1.0, (5.0, 0.0))
    assert kinds(reached, EventKind.ITEM_REACHED) == [1] and reached.hold and reached.target_en == (5.0, 0.0)
    assert ex.update(3.9, (5.0, 0.0)).hold and ex.current_seq == 1
    out = ex.update(4.0, (5.0, 0.0))
    assert not out.hold and out.current_seq == 2 and out.target_en == (5.0, 5.0)


@pytest.mark.parametrize("repeat, expected", [(0, [1, 2, 4]), (1, [1, 2, 1, 2, 4]), (2, [1, 2, 1, 2, 1, 2, 4])])
def test_do_jump_repeats(repeat, expected):
    # seq 1 WP, 2 WP, 3 DO_JUMP -> 1, 4 WP
    ex = executor(wp(0, 15), wp(15, 15), do(177, 1, repeat), wp(0, 0))
    assert drive(ex)[0] == expected


def test_do_jump_counts_per_item_and_restart_clears_them():
    # Nested: the inner jump runs once per pass of the outer one (ArduPilot counts per DO_JUMP item).
    ex = executor(wp(0, 5), wp(5, 5), do(177, 2, 1), do(177, 1, 1), wp(9, 9))
    assert drive(ex)[0] == [1, 2, 2, 1, 2, 5]
    ex.restart()
    assert drive(ex)[0] == [1, 2, 2, 1, 2, 5]


def test_do_jump_forever_runs_until_stopped():
    ex = executor(wp(0, 10), wp(10, 10), do(177, 1, -1), wp(0, 0))
    reached, _ = drive(ex, stop_after=40)
    assert reached == [1, 2] * 20 and not ex.complete
    ex.stop()
    assert ex.update(1e6, (0.0, 10.0)).hold


def test_do_jump_to_a_missing_item_is_skipped_with_a_warning():
    ex = executor(wp(0, 5), do(177, 9, 1), wp(5, 5))
    ex.update(0.0, (0.0, 0.0))
    out = ex.update(0.1, (0.0, 5.0))
    warnings = [e.text for e in out.events if e.severity is Severity.WARNING]
    assert warnings == ["Skipping DO_JUMP #2: no item #9"] and out.current_seq == 3


def test_a_loop_without_navigation_stops_with_a_warning():
    ex = executor(do(178, 1, 1.0), do(177, 1, -1))
    out = ex.update(0.0, (0.0, 0.0))
    assert out.hold and ex.mode is Mode.IDLE
    assert any("loops" in e.text for e in out.events)


def test_loiter_time_holds_position_for_its_time():
    loiter = MissionItem(19, FRAME_GLOBAL_RELATIVE_ALT, 5.0, x=0.0, y=10.0)
    ex = executor(loiter, wp(10, 10))
    assert ex.update(0.0, (0.0, 0.0)).target_en == (10.0, 0.0)
    arrived = ex.update(2.0, (9.0, 0.0))
    assert kinds(arrived, EventKind.ITEM_REACHED) == [1] and arrived.hold
    assert ex.update(6.9, (9.0, 0.0)).hold
    assert ex.update(7.0, (9.0, 0.0)).current_seq == 2


def test_return_to_launch_item_goes_home_then_completes():
    ex = MissionExecutor([wp(10, 0), MissionItem(20)], to_enu, PARAMS, MAX_SPEED_MPS, home_en=(1.0, 1.0))
    ex.start()
    ex.update(0.0, (0.0, 0.0))
    out = ex.update(1.0, (10.0, 0.0))
    assert out.target_en == (1.0, 1.0) and out.acceptance_radius_m == PARAMS.rtl_radius_m
    assert not ex.update(2.0, (2.5, 1.0)).hold
    out = ex.update(3.0, (1.5, 1.0))
    assert kinds(out, EventKind.COMPLETE) == [2] and out.hold


def test_rtl_mode_drives_home_and_holds_there_and_resumes_on_start():
    params = ExecutorParams(cruise_speed_mps=1.0, rtl_speed_mps=0.5, rtl_radius_m=1.0)
    ex = executor(wp(20, 0), wp(20, 20), params=params)
    ex.update(0.0, (0.0, 0.0))
    ex.update(1.0, (20.0, 0.0))
    assert ex.current_seq == 2
    ex.rtl()
    out = ex.update(2.0, (20.0, 5.0))
    assert ex.mode is Mode.RTL and out.target_en == (0.0, 0.0) and out.speed_limit_mps == 0.5 and not out.hold
    home = ex.update(3.0, (0.5, 0.5))
    assert home.hold and [e.text for e in home.events] == ["RTL: reached home"]
    assert ex.update(3.5, (1.5, 0.5)).hold and not ex.update(3.6, (1.5, 0.5)).events  # stays held, says it once
    ex.start()  # back to AUTO: the current item again
    assert ex.update(4.0, (0.5, 0.5)).target_en == (20.0, 20.0)


def test_condition_delay_holds_then_continues():
    ex = executor(wp(5, 0), do(112, 4.0), wp(5, 5))
    ex.update(0.0, (0.0, 0.0))
    out = ex.update(1.0, (5.0, 0.0))
    assert out.current_seq == 2 and out.hold and kinds(out, EventKind.CURRENT) == [2]
    assert ex.update(4.9, (5.0, 0.0)).hold
    out = ex.update(5.0, (5.0, 0.0))
    assert out.current_seq == 3 and not out.hold


def test_change_speed_is_clamped_to_the_robot_maximum():
    ex = executor(do(178, 1, 0.7), wp(5, 0), do(178, 1, 9.0), wp(5, 5), do(178, 1, -1), wp(0, 0))
    assert ex.update(0.0, (0.0, 0.0)).speed_limit_mps == pytest.approx(0.7)
    out = ex.update(1.0, (5.0, 0.0))
    assert out.speed_limit_mps == pytest.approx(MAX_SPEED_MPS)
    assert any("clamped" in e.text and e.severity is Severity.WARNING for e in out.events)
    assert ex.update(2.0, (5.0, 5.0)).speed_limit_mps == pytest.approx(MAX_SPEED_MPS)  # -1: unchanged


def test_unsupported_items_are_skipped_with_a_warning():
    servo = do(183, 1, 1500)  # DO_SET_SERVO
    local = MissionItem(16, 1, x=1.0, y=1.0)  # MAV_FRAME_LOCAL_NED waypoint
    ex = executor(servo, local, wp(3, 0))
    out = ex.update(0.0, (0.0, 0.0))
    warnings = [e.text for e in out.events if e.severity is Severity.WARNING]
    assert warnings == ["Skipping item #1: command 183 unsupported", "Skipping item #2: frame 1 unsupported"]
    assert out.current_seq == 3 and out.target_en == (3.0, 0.0)


def test_zero_lat_lon_waypoint_means_here():
    ex = executor(MissionItem(16, FRAME_GLOBAL_RELATIVE_ALT, 2.0), wp(5, 0))
    out = ex.update(0.0, (3.0, 4.0))
    assert out.target_en == (3.0, 4.0) and kinds(out, EventKind.ITEM_REACHED) == [1] and out.hold


def test_set_current_and_restart():
    ex = executor(wp(0, 5), wp(5, 5), wp(10, 5))
    ex.update(0.0, (0.0, 0.0))
    assert [e.seq for e in ex.set_current(3)] == [3]
    assert ex.update(0.1, (0.0, 0.0)).target_en == (10.0, 5.0)
    assert ex.set_current(0)[0].seq == 1  # seq 0 (home) means the first item, as ArduPilot
    with pytest.raises(ValueError, match="seq 4 does not exist"):
        ex.set_current(4)
    assert ex.current_seq == 1
    drive(ex)
    assert ex.complete
    ex.start()  # AUTO after completion restarts
    assert not ex.complete and ex.update(9.0, (0.0, 0.0)).target_en == (0.0, 5.0)


def test_idle_and_empty_missions_hold():
    ex = MissionExecutor([wp(5, 0)], to_enu, PARAMS, MAX_SPEED_MPS)
    assert ex.update(0.0, (0.0, 0.0)).hold  # not started
    empty = MissionExecutor([], to_enu, PARAMS, MAX_SPEED_MPS)
    assert empty.start()[0].severity is Severity.WARNING
    assert empty.update(0.0, (0.0, 0.0)).hold


def test_nan_and_infinite_params_count_as_zero():
    nan, inf = float("nan"), float("inf")
    ex = executor(
        MissionItem(16, FRAME_GLOBAL_RELATIVE_ALT, nan, nan, x=0.0, y=5.0),
        do(178, 1, nan),
        do(177, nan, inf),
        do(112, inf),
        wp(5, 5),
    )
    reached, _ = drive(ex)
    assert reached == [1, 5] and ex.complete
