"""``python -m bench navigation --scheduler``: worlds run as Dask tasks on an existing cluster
(a LocalCluster on 127.0.0.1 here), each a real emulator + daemon run on the worker."""

from __future__ import annotations

import pytest
from distributed import LocalCluster

from bench import bench_navigation

pytestmark = pytest.mark.sitl


def test_a_world_runs_as_a_task_on_the_cluster_and_its_figures_come_back():
    with LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as cluster:  # fmt: skip
        result = bench_navigation.run(quick=True, only=["open"], worlds=1, variants=["default"], scheduler=cluster.scheduler_address)
    (run,) = [r for r in result["runs"] if r["scenario"] == "open" and r["rulebase"] == "default"]
    assert run["success"] and run["collisions"] == 0 and 0.9 <= run["path_ratio"] < 1.2, run  # the acceptance radius cuts the last metre
    (row,) = [r for r in result["rows"] if r["scenario"] == "open" and r["rulebase"] == "default"]
    assert row["runs"] == 1 and row["success_rate"] == 1.0


def test_an_unreachable_scheduler_is_one_line_of_error(capsys, monkeypatch):
    from bench.__main__ import main
    from rover_ctl.app import tune

    monkeypatch.setattr(tune, "SCHEDULER_TIMEOUT_S", 1.0)  # refused at once, retried until then

    with pytest.raises(SystemExit) as exit_info:
        main(["navigation", "--only", "open", "--worlds", "1", "--scheduler", "tcp://127.0.0.1:9"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("python -m bench: error: --scheduler tcp://127.0.0.1:9: cannot connect"), err
