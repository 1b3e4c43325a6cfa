"""The shipped paper rule base reproduces the original implementation's outputs."""

import csv
from pathlib import Path

import numpy as np
import pytest

from rover_ctl.fuzzy import load_rulebase

TOLERANCE_RPM = 0.05
EXCERPT = Path(__file__).with_name("paper_golden_excerpt.csv")


def read_golden(path: Path) -> dict[str, np.ndarray]:
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    return {name: np.array([float(r[name]) for r in rows]) for name in rows[0]}


@pytest.fixture(scope="module")
def paper():
    return load_rulebase("paper")


def check(rb, golden, single_rows):
    out = rb.evaluate({n: golden[n] for n in rb.input_names})
    for name in rb.output_names:
        worst = np.abs(out[name] - golden[f"{name}_rpm"]).max()
        assert worst <= TOLERANCE_RPM, f"{name}: worst error {worst:.4f} rpm"
    for i in range(0, len(golden["target_distance"]), max(1, len(golden["target_distance"]) // single_rows)):
        one = rb.evaluate_one(**{n: float(golden[n][i]) for n in rb.input_names})
        for name in rb.output_names:
            assert abs(one[name] - golden[f"{name}_rpm"][i]) <= TOLERANCE_RPM, f"row {i} {name}"


def test_every_golden_row_of_the_shared_reference(paper, shared_dir):
    check(paper, read_golden(shared_dir / "reference" / "paper_golden.csv"), single_rows=500)


def test_excerpt_of_golden_rows_kept_in_the_project(paper):
    check(paper, read_golden(EXCERPT), single_rows=100)


def test_rule_table_matches_the_reference_table(paper, shared_dir):
    with (shared_dir / "reference" / "paper_rulebase.csv").open(newline="") as f:
        reference = list(csv.DictReader(f))
    assert len(paper.rules) == len(reference) == 972
    for rule, row in zip(paper.rules, reference):
        for i, variable in enumerate(paper.inputs):
            assert variable.sets[rule.antecedent[i]].name == row[variable.name]
        for o, variable in enumerate(paper.outputs):
            expected = row[variable.name]
            got = "none" if rule.consequent[o] is None else variable.sets[rule.consequent[o]].name
            assert got == expected, rule.where


def test_missing_rule_case_is_reported_and_falls_back_on_the_default(paper):
    assert any("no rule for left_motor" in w and "target_direction=behind" in w for w in paper.warnings)
    # Only the missing cell fires: left has no rule -> its default 0; right concludes stop.
    crisp = dict(target_distance=7.5, target_direction=180.0, obstacle_left=0.0, obstacle_front=0.0, obstacle_right=0.0, obstacle_back=0.0)
    assert paper.evaluate_one(**crisp) == {"left_motor": 0.0, "right_motor": 0.0}
    # Mixed with other rules, that cell adds nothing to the left motor (golden row, as the original).
    row = dict(target_distance=6.4508, target_direction=161.016, obstacle_left=5.7418, obstacle_front=4.0016, obstacle_right=2.6587, obstacle_back=1.2759)
    assert paper.evaluate_one(**row)["left_motor"] == pytest.approx(-4.31414509, abs=TOLERANCE_RPM)


def test_explain_names_the_single_rule_at_crisp_inputs(paper):
    fired = paper.explain(target_distance=15.0, target_direction=0.0, obstacle_left=20.0, obstacle_front=20.0, obstacle_right=20.0, obstacle_back=20.0)
    assert len(fired) == 1
    index, strength, text = fired[0]
    assert strength == 1.0
    assert text.startswith("if target_distance is far and target_direction is ahead and obstacle_left is far")
    assert paper.rules[index].text == text
