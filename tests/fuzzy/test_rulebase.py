"""Loading and checking rule-base files; inference semantics; batch and compiled paths agree."""

import math
import textwrap
import warnings

import numpy as np
import pytest

from rover_ctl.fuzzy import RuleBaseError, load_rulebase, shipped

HEADER = """
name = "tiny"
and = "{and_method}"
defuzzifier = "{defuzzifier}"

[inputs.x]
range = [0, 10]
sets = {{ lo = [0, 0, 0, 10], hi = [0, 10, inf, inf] }}

[inputs.z]
range = [0, 10]
sets = {{ lo = [0, 0, 0, 10], hi = [0, 10, inf, inf] }}

[outputs.y]
range = [0, 10]
default = 3.5
sets = {{ a = [0, 2, 4], b = [6, 8, 10] }}
"""


def write(tmp_path, rules, and_method="min", defuzzifier="area_centre", header=HEADER):
    text = header.format(and_method=and_method, defuzzifier=defuzzifier)
    text += "\n[rules]\nlist = [\n" + "".join(f'  "{r}",\n' for r in rules) + "]\n"
    path = tmp_path / "tiny.toml"
    path.write_text(textwrap.dedent(text))
    return path


FULL = ["if x is lo and z is lo then y is a", "if x is lo and z is hi then y is a", "if x is hi then y is b"]


def test_shipped_rule_bases_load_by_name():
    assert {"paper", "default"} <= set(shipped())
    assert load_rulebase("default").warnings == []


@pytest.mark.parametrize(
    "rules, header_edit, message",
    [
        (["if x is mid then y is a"], None, "tiny.toml rule 1: unknown set 'mid' of x (known: lo, hi)"),
        (["if w is lo then y is a"], None, "tiny.toml rule 1: unknown input 'w'"),
        (["if x is lo then q is a"], None, "tiny.toml rule 1: unknown output 'q'"),
        (["if x is lo y is a"], None, "tiny.toml rule 1: expected 'if <input> is <set>"),
        (["if x is lo and x is hi then y is a"], None, "x appears twice"),
        (["if x is lo then y is a", "if x is lo then y is b"], None, "tiny.toml rule 2: conflicts with tiny.toml rule 1"),
        (["if x is lo then y is a", "if x is lo and z is hi then y is b"], None, "tiny.toml rule 2: never applies"),
        (FULL, ("lo = [0, 0, 0, 10]", "lo = [0, 5, 3, 10]"), "tiny.toml [inputs.x] set lo: breakpoints must be ascending"),
        (FULL, ("lo = [0, 0, 0, 10]", 'lo = [0, "a", 10]'), "set lo: expected a number, got 'a'"),
        (FULL, ("lo = [0, 0, 0, 10]", "lo = [0, 10]"), "set lo: expected [a, b, c, d] (trapezoid) or [a, peak, c]"),
        (FULL, ("b = [6, 8, 10]", "b = [6, 8, inf, inf]"), "output sets must be finite"),
        (FULL, ("range = [0, 10]", "range = [10, 0]"), "tiny.toml [inputs.x]: range must be finite with low < high"),
        (FULL, ('and = "{and_method}"', 'and = "max"'), "unknown 'and' method 'max'"),
        (FULL, ("[inputs.x]", "colour = 1\n[inputs.x]"), "tiny.toml: unknown key(s) colour"),
        ([], None, "tiny.toml: [rules] needs a non-empty list"),
    ],
)  # fmt: skip
def test_errors_name_file_and_rule(tmp_path, rules, header_edit, message):
    header = HEADER if header_edit is None else HEADER.replace(*header_edit, 1)
    path = write(tmp_path, rules, header=header)
    with pytest.raises(RuleBaseError) as info:
        load_rulebase(path)
    assert message in str(info.value)
    assert "\n" not in str(info.value)


OUTPUT_Y = "[outputs.y]\nrange = [0, 10]\ndefault = 3.5"


@pytest.mark.parametrize(
    "header_edit, message",
    [
        (("default = 3.5", "default = inf"), "tiny.toml [outputs.y] default: expected a finite number, got inf"),
        (("default = 3.5", "default = -inf"), "tiny.toml [outputs.y] default: expected a finite number, got -inf"),
        (("default = 3.5", "default = nan"), "tiny.toml [outputs.y] default: expected a number, got nan"),
        (("default = 3.5", "default = 1e400"), "tiny.toml [outputs.y] default: 1e400 is beyond the float range"),
        (("default = 3.5", "default = 1e30"), "tiny.toml [outputs.y] default: expected a number within +-1e+12, got 1e+30"),
        (("default = 3.5", "default = -1e308"), "tiny.toml [outputs.y] default: expected a number within +-1e+12, got -1e+308"),
        (("default = 3.5", "default = 1" + "0" * 300), "tiny.toml [outputs.y] default: expected a number within +-1e+12, got 1000"),
        (("default = 3.5", "default = 10.5"), "tiny.toml [outputs.y]: default 10.5 is outside range [0, 10]"),
        ((OUTPUT_Y, "[outputs.y]\nrange = [1, 10]"), "tiny.toml [outputs.y]: default 0 (the value when none is given: set one) is outside range [1, 10]"),
        (("lo = [0, 0, 0, 10]", "lo = [0, 0, 0, 1e400]"), "tiny.toml [inputs.x] set lo: 1e400 is beyond the float range"),
        (("lo = [0, 0, 0, 10]", "lo = [0, 0, 0, -1E+999]"), "tiny.toml [inputs.x] set lo: -1E+999 is beyond the float range"),
        (("lo = [0, 0, 0, 10]", "lo = [0, 0, 0, inf]"), "tiny.toml [inputs.x] set lo: only a shoulder can be infinite (a = b = -inf or c = d = inf)"),
        (("lo = [0, 0, 0, 10]", "lo = [-inf, 0, 0, 10]"), "tiny.toml [inputs.x] set lo: only a shoulder can be infinite"),
        (("lo = [0, 0, 0, 10]", "lo = [0, inf, inf, inf]"), "tiny.toml [inputs.x] set lo: only a shoulder can be infinite"),
        (("lo = [0, 0, 0, 10]", "lo = [-inf, -inf, -inf]"), "tiny.toml [inputs.x] set lo: a set needs a support of non-zero width"),
        (("lo = [0, 0, 0, 10]", "lo = [-inf, -inf, inf, inf]"), "tiny.toml [inputs.x] set lo: a set cannot be a shoulder on both sides"),
        (("lo = [0, 0, 0, 10]", "lo = [0, 0, 0, 2e12]"), "tiny.toml [inputs.x] set lo: expected a number within +-1e+12, got 2e+12"),
        (("a = [0, 2, 4]", "a = [-1e200, 0, 1e200]"), "tiny.toml [outputs.y] set a: expected a number within +-1e+12, got -1e+200"),
        (("range = [0, 10]", "range = [0, 1e400]"), "tiny.toml [inputs.x] range: 1e400 is beyond the float range"),
        (("range = [0, 10]", "range = [-inf, 10]"), "tiny.toml [inputs.x] range: expected a finite number, got -inf"),
        ((OUTPUT_Y, "[outputs.y]\nrange = [-1e308, 1e308]\ndefault = 3.5"), "tiny.toml [outputs.y] range: expected a number within +-1e+12, got -1e+308"),
        (("[inputs.x]\n", "[inputs.x]\nperiod = inf\n"), "tiny.toml [inputs.x] period: expected a finite number, got inf"),
        (("[inputs.x]\n", "[inputs.x]\nperiod = nan\n"), "tiny.toml [inputs.x] period: expected a number, got nan"),
        (("[inputs.x]\n", "[inputs.x]\nperiod = 1e400\n"), "tiny.toml [inputs.x] period: 1e400 is beyond the float range"),
        (("[inputs.x]\n", "[inputs.x]\nperiod = 1e13\n"), "tiny.toml [inputs.x] period: expected a number within +-1e+12"),
        (("[inputs.x]\n", "[inputs.x]\nperiod = 0\n"), "tiny.toml [inputs.x]: period must be positive"),
        (("[inputs.x]\n", "[inputs.x]\nperiod = 4\n"), "tiny.toml [inputs.x] set lo: a circular input's breakpoints must lie within -period..2 x period (-4..8"),
        (("[inputs.x]\n", "[inputs.x]\nperiod = 1e-300\n"), "tiny.toml [inputs.x] set lo: a circular input's breakpoints must lie within"),
        (("[inputs.x]\nrange = [0, 10]\nsets = {{ lo = [0, 0, 0, 10], hi = [0, 10, inf, inf] }}",
          "[inputs.x]\nrange = [0, 10]\nperiod = 10\nsets = {{ lo = [-10, 0, 0, 10], hi = [0, 10, 20] }}"), None),  # loads
        (("name = \"tiny\"", "name = \"tiny\"\nresolution = 1e400"), "tiny.toml: resolution must be a whole number 11-1000001, got 1e400"),
    ],
)  # fmt: skip
def test_non_finite_or_absurd_numbers_are_refused(tmp_path, header_edit, message):
    assert header_edit[0] in HEADER
    path = write(tmp_path, FULL, header=HEADER.replace(*header_edit, 1))
    if message is None:
        load_rulebase(path)
        return
    with pytest.raises(RuleBaseError) as info:
        load_rulebase(path)
    assert message in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("defuzzifier", ["area_centre", "centroid", "mean_of_maxima"])
def test_the_largest_numbers_allowed_evaluate_finitely(tmp_path, defuzzifier):
    header = HEADER.replace("lo = [0, 0, 0, 10], hi = [0, 10, inf, inf]", "lo = [-1e12, -1e12, -1e12, 1e12], hi = [-1e12, 1e12, inf, inf]", 1)
    header = header.replace(OUTPUT_Y, "[outputs.y]\nrange = [-1e12, 1e12]\ndefault = -1e12", 1)
    header = header.replace("a = [0, 2, 4], b = [6, 8, 10]", "a = [-1e12, -1e12, 0], b = [-1e12, 1e12, 1e12]", 1)
    rb = load_rulebase(write(tmp_path, FULL, defuzzifier=defuzzifier, header=header))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for x in (-1e12, -1.0, 0.0, 5e11, 1e12, 1e300, math.inf, -math.inf, math.nan):
            one = rb.evaluate_one(x=x, z=5.0)["y"]
            batch = float(rb.evaluate({"x": np.array([x]), "z": np.array([5.0])})["y"][0])
            assert math.isfinite(one) and math.isfinite(batch) and -1e12 <= one <= 1e12, (x, one, batch)


def test_unreadable_files(tmp_path):
    with pytest.raises(RuleBaseError, match="no such rule base file or shipped name"):
        load_rulebase(tmp_path / "absent.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = [")
    with pytest.raises(RuleBaseError, match="bad.toml: invalid TOML"):
        load_rulebase(bad)


def test_uncovered_combinations_are_a_warning(tmp_path):
    rb = load_rulebase(write(tmp_path, ["if x is hi then y is b"]))
    assert rb.warnings == [
        "tiny.toml: 2 input combination(s) have no rule for y: x=lo, z=lo; x=lo, z=hi "
        "(the output falls back on the other rules, or on 3.5)"
    ]


def test_decision_list_earlier_rule_decides_overlap(tmp_path):
    rb = load_rulebase(write(tmp_path, ["if x is hi and z is hi then y is a", "if x is hi then y is b", "if x is lo then y is a"]))
    assert rb.evaluate_one(x=10, z=10)["y"] == pytest.approx(2.0)  # only cell (hi, hi): rule 1
    assert rb.evaluate_one(x=10, z=0)["y"] == pytest.approx(8.0)  # cell (hi, lo): rule 2


@pytest.mark.parametrize("defuzzifier", ["area_centre", "centroid", "mean_of_maxima"])
def test_no_rule_fires_gives_the_default(tmp_path, defuzzifier):
    rb = load_rulebase(write(tmp_path, FULL, defuzzifier=defuzzifier))
    # negative inputs fire no set (the sets start at 0), NaN fires nothing either
    for x in (-1.0, math.nan):
        assert rb.evaluate_one(x=x, z=5.0) == {"y": 3.5}
        assert rb.evaluate({"x": np.array([x]), "z": np.array([5.0])})["y"].tolist() == [3.5]
    assert rb.explain(x=-1.0, z=5.0) == []


def test_min_and_product_and(tmp_path):
    # x = 2.5: lo 0.75, hi 0.25; z = 5: lo 0.5, hi 0.5
    rb_min = load_rulebase(write(tmp_path, FULL))
    a, b = rb_min.set_strengths([np.array([2.5]), np.array([5.0])])[0][0]
    assert (a, b) == pytest.approx((0.5, 0.25))  # max(min(.75,.5), min(.75,.5)); min(.25, max z)
    rb_prod = load_rulebase(write(tmp_path, FULL, and_method="product"))
    a, b = rb_prod.set_strengths([np.array([2.5]), np.array([5.0])])[0][0]
    assert (a, b) == pytest.approx((0.375, 0.125))
    assert rb_prod.evaluate_one(x=2.5, z=5.0)["y"] == pytest.approx(float(rb_prod.evaluate({"x": 2.5, "z": 5.0})["y"]))


@pytest.mark.parametrize("name", ["paper", "default"])
def test_batch_and_compiled_single_paths_agree(name):
    rb = load_rulebase(name)
    rng = np.random.default_rng(7)
    n = 300
    inputs = {v.name: rng.uniform(v.low - 1.0, v.high * 1.2, n) for v in rb.inputs}
    inputs[rb.input_names[-1]][:20] = math.inf  # nothing in range
    batch = rb.evaluate(inputs)
    for i in range(n):
        one = rb.evaluate_one(**{k: float(v[i]) for k, v in inputs.items()})
        for out in rb.output_names:
            assert one[out] == pytest.approx(batch[out][i], abs=1e-3)


def test_batch_keeps_shape_and_broadcasts():
    rb = load_rulebase("paper")
    out = rb.evaluate({"target_distance": np.full((2, 3), 10.0), "target_direction": 0.0, "obstacle_left": 20.0,
                       "obstacle_front": 20.0, "obstacle_right": 20.0, "obstacle_back": 20.0})  # fmt: skip
    assert out["left_motor"].shape == (2, 3)
    with pytest.raises(RuleBaseError, match="missing input"):
        rb.evaluate({"target_distance": 1.0})


def test_explain_covers_what_fired():
    rb = load_rulebase("paper")
    inputs = dict(target_distance=10.0, target_direction=30.0, obstacle_left=5.0, obstacle_front=12.0, obstacle_right=25.0, obstacle_back=25.0)
    fired = rb.explain(**inputs)
    assert len(fired) == 2 * 2 * 2 * 2  # two sets active in each of four inputs
    strengths = [s for _, s, _ in fired]
    assert strengths == sorted(strengths, reverse=True) and max(strengths) == pytest.approx(0.5)  # min(2/3, 2/3, 0.5, 0.8)


def test_general_path_for_sets_that_are_not_a_chain(tmp_path):
    # three sets overlapping at once: not a chain, so batch takes the general sparse path
    header = HEADER.replace("sets = {{ lo = [0, 0, 0, 10], hi = [0, 10, inf, inf] }}",
                            "sets = {{ lo = [0, 0, 0, 10], mid = [0, 5, 10], hi = [0, 10, inf, inf] }}", 1)  # fmt: skip
    rules = ["if x is lo then y is a", "if x is mid and z is lo then y is b", "if x is mid and z is hi then y is a", "if x is hi then y is b"]
    rb = load_rulebase(write(tmp_path, rules, header=header))
    assert rb.inputs[0].max_active() == 3 and rb.inputs[0].chain_peaks() is None
    xs, zs = np.meshgrid(np.linspace(-1, 11, 25), np.linspace(-1, 11, 25))
    batch = rb.evaluate({"x": xs, "z": zs})["y"]
    for x, z, y in zip(xs.ravel(), zs.ravel(), batch.ravel()):
        assert rb.evaluate_one(x=x, z=z)["y"] == pytest.approx(y, abs=1e-4)
