"""``rover-ctl tune`` end to end: a generation on its own LocalCluster, a second resumed from the
checkpoint on an existing cluster (``--scheduler``, 127.0.0.1), the tuned file loads."""

from __future__ import annotations

import json
import pickle

import cma
import numpy as np
import psutil
import pytest
from distributed import LocalCluster

from rover_ctl.app import tune as app_tune
from rover_ctl.app.tune import MAX_BATCH, MAX_GENERATIONS, SEED_SPACE, Cluster, TuneError, TuneOptions, check_options, draw_seeds, tune
from rover_ctl.cli import main
from rover_ctl.fuzzy import load_rulebase, parse_rulebase
from rover_ctl.tuning import scenarios
from rover_ctl.tuning.genome import Genome, load_document
from rover_ctl.tuning.verdict import HEADLINES

SMALL = ["--worlds", "1", "--generations", "1", "--population", "2", "--holdout", "1", "--workers", "1"]
TOY = ('[inputs.speed]\nrange = [0, 1]\nsets = { lo = [0, 0, 0.3, 0.6], hi = [0.4, 0.7, 1, 1] }\n'
       '[outputs.left_motor]\nrange = [0, 1]\nsets = { a = [0, 0.5, 1] }\n[rules]\nlist = ["if speed is lo then left_motor is a"]\n')
"""A valid rule base that is not a navigation rule base."""


@pytest.fixture
def no_cluster(monkeypatch):
    """A refusal must come before any cluster starts."""

    def refuse(*args):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(app_tune, "Cluster", refuse)


def test_a_two_generation_tune_resumes_and_its_rule_base_loads(tmp_path, capsys):
    out = tmp_path / "tune"
    # The first generation through the command line, as a user starts it; its last lines are the verdict.
    assert main(["tune", "default", "--scenarios", "moving", "--worlds", "1", "--generations", "1", "--population", "4",
                 "--holdout", "1", "--seed", "7", "--workers", "2", "--out", str(out)]) == 0  # fmt: skip
    first = json.loads((out / "result.json").read_text())
    assert first["generations"] == 1 and (out / "checkpoint.pkl").exists()
    printed = capsys.readouterr().err
    assert f"verdict: {HEADLINES[first['verdict']]}" in printed and first["verdict_lines"][0] in printed
    options = TuneOptions(rulebase="default", scenarios=["moving"], out=out, worlds=1, generations=1, population=4, holdout=1,
                          seed=7, workers=2, command="rover-ctl tune default --scenarios moving ...")  # fmt: skip
    # The same run, longer, resumed from its checkpoint on an existing cluster (--scheduler).
    options.generations, options.workers = 2, None
    with LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as cluster:  # fmt: skip
        options.scheduler = cluster.scheduler_address
        result = tune(options)
    assert result["history"][1]["workers"] == 1
    assert [h["generation"] for h in result["history"]] == [1, 2]
    assert result["history"][0] == first["history"][0]
    assert result["episodes"] == 2 * 4 * 1 + 1  # four candidates a generation (two parents: a mean no candidate is), and the source in generation 1
    assert not set(result["training_seeds"]) & set(result["holdout_seeds"])
    assert result["best"]["score"] <= min(h["best"] for h in result["history"])
    for row in result["holdout"]:
        assert row["source"]["episodes"] == row["tuned"]["episodes"] == 1

    tuned = out / "tuned.toml"
    rulebase = load_rulebase(tuned)
    # tuned.toml is the search distribution's final mean, not the luckiest sampled candidate
    with open(out / "checkpoint.pkl", "rb") as f:
        es = pickle.load(f)["es"]
    genome = Genome(*load_document("default"))
    assert result["tuned"]["x"] == [float(v) for v in genome.repaired(np.asarray(es.mean))]
    assert load_rulebase(tuned).inputs == parse_rulebase(genome.decode_document(np.asarray(es.mean)), "mean").inputs
    with open(out / "checkpoint.pkl", "rb") as f:
        best_document = pickle.load(f)["best"]["document"]
    assert load_rulebase(tuned).inputs != parse_rulebase(best_document, "best").inputs  # the check above tells them apart
    assert [v.name for v in rulebase.inputs] == [v.name for v in load_rulebase("default").inputs]
    assert main(["fuzzy", "show", str(tuned)]) == 0  # --rulebase FILE takes it as it takes a shipped name
    report = (out / "report.md").read_text()
    assert "rover-ctl tune default" in report and str(result["holdout_seeds"][0]) in report
    assert result["verdict"] == "not shown" and "## Verdict on the held-out worlds" in report  # one world shows nothing
    assert result["verdict_lines"][0].startswith("moving: ") and result["verdict_lines"][0] in report
    assert (out / "convergence.png").stat().st_size > 1000
    assert json.loads((out / "result.json").read_text())["generations"] == 2


def test_a_checkpoint_of_another_run_is_refused(tmp_path, capsys):
    out = tmp_path / "tune"
    args = ["tune", "default", "--scenarios", "moving", "--worlds", "1", "--generations", "1", "--population", "2",
            "--holdout", "1", "--workers", "1", "--out", str(out)]  # fmt: skip
    out.mkdir()
    (out / "checkpoint.pkl").write_bytes(b"not a pickle")
    assert main(args) == 2
    assert "not a readable checkpoint" in capsys.readouterr().err


def _states():
    """Well-formed pickles that are not checkpoints ``tune`` can resume (its settings: SMALL, open)."""
    settings = TuneOptions(rulebase="default", scenarios=["open"], out=None, worlds=1, population=2, holdout=1).settings()
    size = Genome(*load_document("default")).size
    es = cma.CMAEvolutionStrategy(np.zeros(size), 0.1, {"popsize": 2, "seed": 1, "verbose": -9})
    row = {"generation": 1, "best": 70.0, "median": 75.0, "source": 80.0, "best_so_far": 70.0, "success": 1.0, "episodes": 3,
           "wall_s": 1.0, "sim_s": 60.0, "workers": 1}  # fmt: skip
    good = {"version": 1, "settings": settings, "es": es, "history": [row], "episodes": 3, "sim_s": 60.0, "wall_s": 1.0,
            "source_score": 80.0, "best": {"score": 70.0, "generation": 1, "x": [0.0] * size, "document": load_document("default")[0]}}  # fmt: skip
    return [
        ({"version": 1, "settings": 5}, "not a usable checkpoint (no settings)"),
        ([1, 2], "not a checkpoint of this version"),
        ({**good, "es": None}, "no CMA-ES state"),
        ({**good, "es": cma.CMAEvolutionStrategy(np.zeros(size + 1), 0.1, {"verbose": -9})}, "the rule base now has"),
        ({**good, "history": 5}, "no history"),
        ({**good, "history": [{**row, "median": "x"}]}, "history row 1"),
        ({**good, "history": [row, row]}, "history row 2"),
        ({**good, "best": None}, "no usable best candidate"),
        ({**good, "best": {**good["best"], "x": [0.0]}}, "no usable best candidate"),
        ({**good, "best": {**good["best"], "document": {"inputs": 3}}}, "not a valid rule base"),
        ({**good, "source_score": None}, "no score of the source"),
        ({**good, "settings": {**settings, "seed": 2}}, "another run (different seed)"),
    ]


@pytest.mark.parametrize("state, message", _states())
def test_a_checkpoint_of_the_wrong_shape_is_refused_and_kept(tmp_path, capsys, no_cluster, state, message):
    out = tmp_path / "tune"
    out.mkdir()
    data = pickle.dumps(state)
    (out / "checkpoint.pkl").write_bytes(data)
    assert main(["tune", "default", "--scenarios", "open", *SMALL, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "checkpoint.pkl" in err and len(err.strip().splitlines()) == 1, err
    assert "choose another --out" in err and ("another run" in err or "to start over, delete it" in err)
    assert (out / "checkpoint.pkl").read_bytes() == data and [p.name for p in out.iterdir()] == ["checkpoint.pkl"]


def test_a_rule_base_that_does_not_navigate_is_refused_as_sim_refuses_it(tmp_path, capsys, no_cluster):
    toy = tmp_path / "toy.toml"
    toy.write_text(TOY)
    assert main(["tune", str(toy), "--scenarios", "open", *SMALL, "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert "toy.toml: not a navigation rule base (missing target_distance" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "t").exists()


def test_an_error_after_the_progress_table_starts_on_its_own_line(tmp_path, capsys, monkeypatch):
    def unreachable(*args):
        raise TuneError("--scheduler tcp://127.0.0.1:1: cannot connect: refused")

    monkeypatch.setattr(app_tune, "Cluster", unreachable)
    assert main(["tune", "default", "--scenarios", "open", *SMALL[:-2], "--scheduler", "tcp://127.0.0.1:1", "--out", str(tmp_path / "t")]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert "generation" in "".join(lines)  # the table was shown
    assert lines[-1] == "rover-ctl: error: --scheduler tcp://127.0.0.1:1: cannot connect: refused", lines[-3:]


def test_run_sizes_are_bounded_by_the_seeds_and_the_batch():
    def check(cores=2, **kw):
        check_options(TuneOptions(**{"rulebase": "default", "scenarios": ["open"], "out": None, "population": 2, **kw}), cores)

    def refused(match, **kw):
        with pytest.raises(TuneError, match=match):
            check(**kw)

    check(generations=MAX_GENERATIONS)
    refused(f"--generations {MAX_GENERATIONS + 1}: at most", generations=MAX_GENERATIONS + 1)
    refused(f"more than the {SEED_SPACE} distinct world seeds", worlds=SEED_SPACE, holdout=1)
    refused("distinct world seeds", worlds=10**26)
    check(worlds=MAX_BATCH // 3)  # (2 candidates + the source) x 1 scenario x worlds
    refused("episodes a generation", worlds=MAX_BATCH // 3 + 1)
    refused("episodes a generation", population=10**20)
    check(holdout=MAX_BATCH // 2)  # source and tuned
    refused("held-out episodes", holdout=MAX_BATCH // 2 + 1)
    check(workers=8, cores=2)
    refused(r"--workers 9: expected a whole number in 1\.\.8", workers=9, cores=2)
    refused("open given more than once", scenarios=["open", "moving", "open"])


@pytest.mark.parametrize("flags, message", [
    (["--scenarios", "moon"], "unknown moon"),
    (["--scenarios", "moving", "--population", "1"], "at least 2"),
    (["--scenarios", "moving", "--scheduler", "8786"], "tcp://HOST:PORT"),
    (["--scenarios", "moving", "--scheduler", "tcp://127.0.0.1:99999"], "PORT in 1..65535"),
    (["--scenarios", "moving", "--scheduler", "tcp://127.0.0.1:0"], "PORT in 1..65535"),
    (["--scenarios", "moving", "--worlds", "99999999999999999999999999"], "1000000 distinct world seeds"),
    (["--scenarios", "moving", "--holdout", "60000"], "held-out episodes"),
    (["--scenarios", "moving", "--generations", "10001"], "at most 10000"),
    (["--scenarios", "moving,moving"], "more than once"),
    (["--scenarios", "moving", "--workers", "100000"], "per core"),
    (["--scenarios", "moving", "--generations", "zero"], "whole number"),
    (["--scenarios", "moving", "--set", "nosuch.key=1"], "nosuch"),
])  # fmt: skip
def test_bad_flags_are_one_line_and_exit_2(tmp_path, capsys, no_cluster, flags, message):
    try:
        code = main(["tune", "default", "--out", str(tmp_path / "t"), *flags])
    except SystemExit as exc:  # argparse's refusal
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "t" / "checkpoint.pkl").exists()


def test_the_help_names_every_scenario(capsys):
    with pytest.raises(SystemExit):
        main(["tune", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in scenarios.NAMES), (scenarios.NAMES, text)


def test_the_local_cluster_listens_on_loopback_only():
    cluster = Cluster(None, 1)
    try:
        pids = {psutil.Process().pid, *(p.pid for p in psutil.Process().children(recursive=True))}
        listening = [c for c in psutil.net_connections("inet") if c.status == psutil.CONN_LISTEN and c.pid in pids]
        assert listening, "no listening socket found for the cluster"
        assert all(c.laddr.ip == "127.0.0.1" for c in listening), listening
        assert cluster.workers == 1
    finally:
        cluster.close()
    # The workers are gone (multiprocessing's resource tracker lives as long as this process).
    left = [p for p in psutil.Process().children(recursive=True) if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    assert not [p for p in left if "resource_tracker" not in " ".join(p.cmdline())], [p.cmdline() for p in left]


def test_held_out_seeds_never_overlap_the_training_seeds():
    for seed in range(20):
        training, holdout = draw_seeds(seed, 50, 50)
        assert len(set(training)) == 50 and not set(training) & set(holdout)
    assert draw_seeds(3, 4, 2) == draw_seeds(3, 4, 2)
