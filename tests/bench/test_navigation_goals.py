"""The navigation benchmark's table of issue 12's goals: each goal met, or the rows that miss it."""

from __future__ import annotations

from bench.bench_navigation import goal_lines


def _row(scenario, rate=1.0, moving=0, path=1.1, variant="default", **extra):
    return {"scenario": scenario, "rulebase": variant, "runs": 100, "success_rate": rate, "collisions": moving,
            "collisions_moving": moving, "path_ratio": path, **extra}  # fmt: skip


def test_every_goal_met_reads_yes():
    rows = [_row("open"), _row("narrow_gap", path=1.27, through_gap=99), _row("open", rate=0.5, variant="paper")]
    table = goal_lines(rows)
    assert table[0] == "| issue 12 goal, `default` rows | met |"
    assert [line.rsplit("|", 2)[1].strip() for line in table[2:]] == ["yes", "yes", "yes (99 of 100)", "yes"]


def test_a_missed_goal_names_the_scenarios_and_their_figures():
    rows = [_row("head_on", rate=0.97, moving=2), _row("walls", path=1.45), _row("narrow_gap", through_gap=60),
            _row("crossing", rate=0.98, moving=1)]  # fmt: skip
    table = "\n".join(goal_lines(rows))
    assert "| success at least 98% in every scenario | no: head_on 97% |" in table  # 98% meets it
    assert "| no collision with the rover moving | no: head_on 2, crossing 1 |" in table
    assert "| no (60 of 100) |" in table
    assert "| path at most 1.3 x the shortest in every scenario | no: walls 1.45 |" in table


def test_a_failed_scenario_has_no_path_and_misses_the_path_goal():
    table = "\n".join(goal_lines([_row("open", rate=0.0, path=float("nan"))]))
    assert "no: open nan" in table


def test_no_rows_of_the_variant_no_table():
    assert goal_lines([_row("open", variant="paper")]) == []
