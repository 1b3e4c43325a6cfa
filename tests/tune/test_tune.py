"""``rover-ctl tune`` end to end: a generation on its own LocalCluster, a second resumed from the
checkpoint on an existing cluster (``--scheduler``, 127.0.0.1), the tuned file loads."""

from __future__ import annotations

import json

import psutil
import pytest
from distributed import LocalCluster

from rover_ctl.app.tune import Cluster, TuneOptions, draw_seeds, tune
from rover_ctl.cli import main
from rover_ctl.fuzzy import load_rulebase
from rover_ctl.tuning import scenarios


def test_a_two_generation_tune_resumes_and_its_rule_base_loads(tmp_path, capsys):
    out = tmp_path / "tune"
    options = TuneOptions(rulebase="default", scenarios=["moving"], out=out, worlds=1, generations=1, population=2, holdout=1,
                          seed=7, workers=2, command="rover-ctl tune default --scenarios moving ...")  # fmt: skip
    first = tune(options)
    assert first["generations"] == 1 and (out / "checkpoint.pkl").exists()
    # The same run, longer, resumed from its checkpoint on an existing cluster (--scheduler).
    options.generations, options.workers = 2, None
    with LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as cluster:  # fmt: skip
        options.scheduler = cluster.scheduler_address
        result = tune(options)
    assert result["history"][1]["workers"] == 1
    assert [h["generation"] for h in result["history"]] == [1, 2]
    assert result["history"][0] == first["history"][0]
    assert result["episodes"] == 2 * 2 * 1 + 1  # two candidates a generation, and the source in generation 1
    assert not set(result["training_seeds"]) & set(result["holdout_seeds"])
    assert result["best"]["score"] <= min(h["best"] for h in result["history"])
    for row in result["holdout"]:
        assert row["source"]["episodes"] == row["tuned"]["episodes"] == 1

    tuned = out / "tuned.toml"
    rulebase = load_rulebase(tuned)
    assert [v.name for v in rulebase.inputs] == [v.name for v in load_rulebase("default").inputs]
    assert main(["fuzzy", "show", str(tuned)]) == 0  # --rulebase FILE takes it as it takes a shipped name
    report = (out / "report.md").read_text()
    assert "rover-ctl tune default" in report and str(result["holdout_seeds"][0]) in report
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


@pytest.mark.parametrize("flags, message", [
    (["--scenarios", "moon"], "unknown moon"),
    (["--scenarios", "moving", "--population", "1"], "at least 2"),
    (["--scenarios", "moving", "--scheduler", "8786"], "tcp://HOST:PORT"),
    (["--scenarios", "moving", "--generations", "zero"], "whole number"),
    (["--scenarios", "moving", "--set", "nosuch.key=1"], "nosuch"),
])  # fmt: skip
def test_bad_flags_are_one_line_and_exit_2(tmp_path, capsys, flags, message):
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
