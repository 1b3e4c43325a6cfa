"""FCL import: the same rule base as TOML and FCL evaluates the same; unsupported parts refused."""

import numpy as np
import pytest

from rover_ctl.fuzzy import RuleBaseError, load_rulebase

FCL = """
FUNCTION_BLOCK tiny   (* a comment *)
VAR_INPUT
    x : REAL;
    z : REAL;
END_VAR
VAR_OUTPUT
    y : REAL;
END_VAR
FUZZIFY x
    TERM lo := (0, 1) (10, 0);
    TERM hi := (0, 0) (10, 1);
END_FUZZIFY
FUZZIFY z
    TERM lo := (0, 1) (10, 0);
    TERM hi := (0, 0) (10, 1);
END_FUZZIFY
DEFUZZIFY y
    TERM a := (0, 0) (2, 1) (4, 0);
    TERM b := (5, 0) (6, 1) (8, 1) (10, 0);
    METHOD : COG;
    DEFAULT := 3.5;
    RANGE := (0 .. 10);
END_DEFUZZIFY
RULEBLOCK No1
    AND : MIN;
    ACCU : MAX;
    ACT : MIN;
    RULE 1 : IF x IS lo AND z IS hi THEN y IS a;
    RULE 2 : IF x IS hi THEN y IS b;
    // x lo, z lo left uncovered on purpose
END_RULEBLOCK
END_FUNCTION_BLOCK
"""

TOML = """
name = "tiny"
defuzzifier = "centroid"
[inputs.x]
range = [0, 10]
sets = { lo = [-inf, -inf, 0, 10], hi = [0, 10, inf, inf] }
[inputs.z]
range = [0, 10]
sets = { lo = [-inf, -inf, 0, 10], hi = [0, 10, inf, inf] }
[outputs.y]
range = [0, 10]
default = 3.5
sets = { a = [0, 2, 4], b = [5, 6, 8, 10] }
[rules]
list = ["if x is lo and z is hi then y is a", "if x is hi then y is b"]
"""


def test_fcl_and_toml_agree(tmp_path):
    (tmp_path / "tiny.fcl").write_text(FCL)
    (tmp_path / "tiny.toml").write_text(TOML)
    fcl, toml = load_rulebase(tmp_path / "tiny.fcl"), load_rulebase(tmp_path / "tiny.toml")
    assert fcl.defuzzifier == "centroid" and fcl.outputs[0].default == 3.5
    assert [s.points for s in fcl.inputs[0].sets] == [s.points for s in toml.inputs[0].sets]
    grid = np.linspace(-1, 11, 13)
    xs, zs = np.meshgrid(grid, grid)
    np.testing.assert_allclose(fcl.evaluate({"x": xs, "z": zs})["y"], toml.evaluate({"x": xs, "z": zs})["y"])
    assert len(fcl.warnings) == 1 and "x=lo, z=lo" in fcl.warnings[0]


@pytest.mark.parametrize(
    "edit, message",
    [
        (("RULE 2 : IF x IS hi THEN", "RULE 2 : IF x IS hi OR z IS lo THEN"), "tiny.fcl line 30: OR, NOT and WITH are not supported"),
        (("METHOD : COG", "METHOD : COA"), "tiny.fcl line 21: METHOD COA not supported"),
        (("TERM a := (0, 0) (2, 1) (4, 0)", "TERM a := (0, 0) (2, 0.5) (4, 0)"), "tiny.fcl line 19 TERM a: term points must be"),
        (("ACCU : MAX", "ACCU : SUM"), "tiny.fcl line 27: ACCU : SUM not supported"),
        (("FUZZIFY z\n", "FUZZIFY w\n"), "tiny.fcl line 14: w is not declared in VAR_INPUT"),
        (("THEN y IS a", "THEN y IS c"), "tiny.fcl rule 1: unknown set 'c' of y"),
        (("DEFAULT := 3.5", "DEFAULT := 1e999"), "tiny.fcl line 22 DEFAULT: 1e999 is not a finite number"),
        (("DEFAULT := 3.5", "DEFAULT := 10.5"), "tiny.fcl [outputs.y]: default 10.5 is outside range [0, 10]"),
        (("DEFAULT := 3.5", "DEFAULT := -1e308"), "tiny.fcl [outputs.y] default: expected a number within +-1e+12, got -1e+308"),
        (("TERM lo := (0, 1) (10, 0)", "TERM lo := (1e999, 1) (1e999, 0)"), "tiny.fcl line 11 TERM lo: 1e999 is not a finite number"),
        (("TERM lo := (0, 1) (10, 0)", "TERM lo := (0, 1) (10, 1e999)"), "tiny.fcl line 11 TERM lo: 1e999 is not a finite number"),
        (("TERM lo := (0, 1) (10, 0)", "TERM lo := (0, 1) (10, 0) (inf, 0)"), "tiny.fcl line 11 TERM lo: expected (x, mu) points with x and mu numbers, got '(0, 1) (10, 0) (inf, 0)'"),
        (("TERM a := (0, 0) (2, 1) (4, 0)", "TERM a := (0, 0) (2, 1) (4e20, 0)"), "tiny.fcl [outputs.y] set a: expected a number within +-1e+12, got 4e+20"),
        (("RANGE := (0 .. 10)", "RANGE := (0 .. 1e999)"), "tiny.fcl line 23 RANGE: 1e999 is not a finite number"),
    ],
)
def test_unsupported_or_wrong_fcl_is_one_line_error(tmp_path, edit, message):
    path = tmp_path / "tiny.fcl"
    assert edit[0] in FCL
    path.write_text(FCL.replace(*edit, 1))
    with pytest.raises(RuleBaseError) as info:
        load_rulebase(path)
    assert message in str(info.value)
    assert "\n" not in str(info.value)
