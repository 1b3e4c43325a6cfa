"""The genome's repair keeps every candidate a valid rule base, whatever vector the search asks for."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rover_ctl.fuzzy import load_rulebase, parse_rulebase
from rover_ctl.tuning.genome import Genome, GenomeError, load_document

SOURCES = {name: load_document(name) for name in ("default", "paper")}
GENOMES = {name: Genome(doc, where) for name, (doc, where) in SOURCES.items()}
SCALED = Genome(*SOURCES["default"], scale_outputs=True)


def vectors(genome: Genome):
    # Whatever CMA-ES might ask for: small steps, huge ones, and the non-numbers of a broken run.
    number = st.one_of(st.floats(-3, 3), st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, 1e6, -1e6]))
    return st.lists(number, min_size=genome.size, max_size=genome.size).map(np.array)


def assert_valid(genome: Genome, source: dict, doc: dict, output_scale: float = 1.0) -> None:
    parse_rulebase(doc, "candidate")  # the loader's checks: ascending, non-zero support, finite outputs
    for kind in ("inputs", "outputs"):
        scale = output_scale if kind == "outputs" else 1.0
        for name, spec in doc[kind].items():
            low, high = spec["range"]
            assert [round(v * scale, 4) for v in source[kind][name]["range"]] == [low, high]
            period = spec.get("period")
            for set_name, points in spec["sets"].items():
                assert all(a <= b for a, b in zip(points, points[1:])), (name, set_name, points)
                before = [round(p * scale, 4) if math.isfinite(p) else p for p in source[kind][name]["sets"][set_name]]
                for p, q in zip(before, points):
                    if not math.isfinite(p):
                        assert q == p  # shoulders stay shoulders
                    elif period is not None:
                        assert -period / 2 < q < period * 1.5 or q == p
                    elif low < p < high:
                        assert low < q < high, (name, set_name, points)  # inside the universe
                    else:
                        assert q == p  # the universe's ends are fixed


@pytest.mark.parametrize("name, examples", [("default", 60), ("paper", 10)])  # the paper's 972 rules take 0.15 s to check
def test_every_vector_decodes_to_a_valid_rule_base(name, examples):
    @settings(max_examples=examples, deadline=None)
    @given(data=st.data())
    def check(data):
        _check_vector(name, data)

    check()


def _check_vector(name, data):
    genome = GENOMES[name]
    x = data.draw(vectors(genome))
    doc, rulebase = genome.decode(x)
    assert_valid(genome, SOURCES[name][0], doc)
    assert rulebase.evaluate_one(**{v.name: 1.0 for v in rulebase.inputs})  # it runs


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_mirrors_stay_mirrors_and_stop_stays_stop(data):
    x = data.draw(vectors(SCALED))
    doc = SCALED.decode_document(x)
    assert_valid(SCALED, SOURCES["default"][0], doc, SCALED.output_scale(x))
    inputs, outputs = doc["inputs"], doc["outputs"]
    assert inputs["obstacle_left"]["sets"] == inputs["obstacle_right"]["sets"]
    assert inputs["obstacle_front_left"]["sets"] == inputs["obstacle_front_right"]["sets"]
    assert outputs["left_motor"]["sets"] == outputs["right_motor"]["sets"]
    assert outputs["left_motor"]["sets"]["stop"][1] == 0.0
    direction = inputs["target_direction"]["sets"]
    assert direction["ahead"][1] == 0.0 and direction["ahead"][0] == -direction["ahead"][2]  # symmetric about dead ahead
    assert [round(360 - p, 4) for p in reversed(direction["left"])] == direction["right"]


@pytest.mark.parametrize("name", GENOMES)
def test_the_start_is_the_source_and_repair_is_a_fixed_point(name):
    genome = GENOMES[name]
    source, _ = SOURCES[name]
    assert genome.decode_document(genome.start()) == source
    x = np.random.default_rng(3).normal(0.0, 0.5, genome.size)
    fixed = genome.repaired(x)
    assert genome.decode_document(fixed) == genome.decode_document(x)
    assert np.allclose(genome.repaired(fixed), fixed)


def test_a_moved_breakpoint_changes_the_controller():
    genome = GENOMES["default"]
    x = np.zeros(genome.size)
    x[[i for i, g in enumerate(genome.genes) if g.variable == "obstacle_front"][-1]] = 0.2  # 'far' starts 0.8 m later
    base, moved = load_rulebase("default"), genome.decode(x)[1]
    inputs = dict(target_distance=10.0, target_direction=0.0, obstacle_front=2.6, obstacle_front_left=4.0,
                  obstacle_front_right=4.0, obstacle_left=4.0, obstacle_right=4.0)  # fmt: skip
    assert base.evaluate_one(**inputs) != moved.evaluate_one(**inputs)


def test_a_rule_base_that_is_not_toml_is_refused(tmp_path):
    fcl = tmp_path / "x.fcl"
    fcl.write_text("FUNCTION_BLOCK x\nEND_FUNCTION_BLOCK\n")
    with pytest.raises(GenomeError, match="only TOML"):
        load_document(fcl)


def test_output_scale_keeps_a_fixed_default_inside_the_range():
    """The loader wants an output's default inside its range; scaling the range about 0 must not leave it out."""
    document = {**SOURCES["default"][0], "outputs": {k: {**v, "default": 120} for k, v in SOURCES["default"][0]["outputs"].items()}}
    genome = Genome(document, "default.toml", scale_outputs=True)
    x = np.zeros(genome.size)
    x[-1] = -0.5  # scale 0.5: the range [-50, 125] becomes [-25, 62.5]
    doc, rulebase = genome.decode(x)
    assert doc["outputs"]["left_motor"]["range"] == [-25.0, 120.0] and rulebase.outputs[0].default == 120
