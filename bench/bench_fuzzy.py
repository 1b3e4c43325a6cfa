"""Fuzzy engine speed against pyfuzzylite 8 and scikit-fuzzy on the paper's 972-rule base, and a
quick closed-loop navigation bench of the paper and default rule bases in the kinematic rover.

Speed: our compiled single evaluation (``evaluate_one``) and vectorised batch (``evaluate``), both
with the paper's area-weighted defuzzifier and with a sampled centroid (1001 points, like
fuzzylite's), against pyfuzzylite (Mamdani, min/max, Centroid 1001, numpy-vectorised batch) on
the same rules, whose outputs are also compared with ours. scikit-fuzzy takes minutes to build a
972-rule system, so it is built on subsets of the rules and its build time extrapolated with a
power law fitted to them (capped at ``SKFUZZY_BUILD_CAP_S``). Libraries that are not installed
(``pip install .[bench]``) are recorded as skipped.

Navigation: seeded worlds of scattered circles and boxes between a start and a target 25 m
away; the paper's base on its four rangefinders, ours on six; success = reached within 1 m
without collision inside the time limit; path ratio = path length / straight-line distance.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

from rover_ctl.config import NavigatorParams
from rover_ctl.fuzzy import load_rulebase
from rover_ctl.navigation.navigator import Navigator

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from navigator.kinematic import PAPER_ORIENTATIONS, Circle, box, drive  # noqa: E402  (test helper, pure)

SKFUZZY_BUILD_CAP_S = 40.0
"""Stop building larger scikit-fuzzy subsets once the build time spent reaches this."""
SEED = 2017
FUZZYLITE_CHUNK_ROWS = 500
"""Rows per pyfuzzylite process() call in the batch timing (its fastest size here)."""


def random_inputs(rb, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {v.name: rng.uniform(v.low, v.high, n) for v in rb.inputs}


def time_ours(quick: bool) -> dict:
    rng = np.random.default_rng(SEED)
    paper = load_rulebase("paper")
    result = {}
    for defuzzifier in ("area_centre", "centroid"):
        rb = dataclasses.replace(paper, defuzzifier=defuzzifier, warnings=[])
        singles = 300 if quick else (3000 if defuzzifier == "area_centre" else 500)
        rows = random_inputs(rb, singles, rng)
        calls = [{k: float(v[i]) for k, v in rows.items()} for i in range(singles)]
        times = []
        cpu_start = time.process_time()
        for kwargs in calls:
            start = time.perf_counter()
            rb.evaluate_one(**kwargs)
            times.append(time.perf_counter() - start)
        single_cpu_s = (time.process_time() - cpu_start) / singles
        n_batch = 200_000 if quick else (1_000_000 if defuzzifier == "area_centre" else 100_000)
        batch = random_inputs(rb, n_batch, rng)
        best = best_cpu = math.inf
        for _ in range(1 if quick else 3):
            start, cpu_start = time.perf_counter(), time.process_time()
            rb.evaluate(batch)
            best = min(best, time.perf_counter() - start)
            best_cpu = min(best_cpu, time.process_time() - cpu_start)
        result[defuzzifier] = {
            "single_median_us": float(np.median(times) * 1e6),
            "single_mean_us": float(np.mean(times) * 1e6),
            "single_cpu_us": single_cpu_s * 1e6,
            "batch_rows": n_batch,
            "batch_per_s": n_batch / best,
            "batch_per_cpu_s": n_batch / best_cpu,
        }
    return result


def build_fuzzylite(rb):
    import fuzzylite as fl

    def term(name, points, period):
        a, b, c, d = points
        if period is not None and a < 0.0:  # circular set crossing 0: spell it on [0, period]
            return fl.Discrete(name, [0.0, 1.0, d, 0.0, period + a, 0.0, period, 1.0])
        if math.isinf(d):
            return fl.Ramp(name, a, b)
        return fl.Trapezoid(name, a, b, c, d)

    inputs = [
        fl.InputVariable(name=v.name, minimum=v.low, maximum=v.high, terms=[term(s.name, s.points, v.period) for s in v.sets])
        for v in rb.inputs
    ]
    outputs = [
        fl.OutputVariable(name=v.name, minimum=v.low, maximum=v.high, default_value=0.0, aggregation=fl.Maximum(),
                          defuzzifier=fl.Centroid(rb.resolution), terms=[term(s.name, s.points, None) for s in v.sets])
        for v in rb.outputs
    ]  # fmt: skip
    rules = [fl.Rule.create(r.text) for r in rb.rules]
    block = fl.RuleBlock(conjunction=fl.Minimum(), implication=fl.Minimum(), activation=fl.General(), rules=rules)
    engine = fl.Engine(name="paper", input_variables=inputs, output_variables=outputs, rule_blocks=[block])
    for rule in rules:
        rule.load(engine)
    return engine


def time_fuzzylite(quick: bool) -> dict:
    try:
        import fuzzylite as fl
    except ImportError:
        return {"skipped": "pyfuzzylite not installed (pip install .[bench])"}
    rb = dataclasses.replace(load_rulebase("paper"), defuzzifier="centroid", warnings=[])
    start = time.perf_counter()
    engine = build_fuzzylite(rb)
    build_s = time.perf_counter() - start
    rng = np.random.default_rng(SEED + 1)

    def run(rows):
        for v in rb.inputs:
            engine.input_variable(v.name).value = rows[v.name]
        engine.process()
        return {v.name: np.asarray(engine.output_variable(v.name).value) for v in rb.outputs}

    singles = random_inputs(rb, 5 if quick else 30, rng)
    times = []
    for i in range(len(singles["target_distance"])):
        row = {k: float(v[i]) for k, v in singles.items()}
        start = time.perf_counter()
        run(row)
        times.append(time.perf_counter() - start)
    n_batch = 1000 if quick else 4000  # pyfuzzylite manages a few hundred rows/s here: keep the bench short
    batch = random_inputs(rb, n_batch, rng)
    # pyfuzzylite's vectorised process() is fastest at a few hundred rows per call and slows down on
    # larger arrays (measured: 200-1000 rows ~350/s, 3000 rows ~200/s), so give it its best chunk size.
    chunk = FUZZYLITE_CHUNK_ROWS
    start = time.perf_counter()
    parts = [run({k: v[i : i + chunk] for k, v in batch.items()}) for i in range(0, n_batch, chunk)]
    batch_s = time.perf_counter() - start
    theirs = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    ours = rb.evaluate(batch)
    agreement = max(float(np.nanmax(np.abs(ours[k] - theirs[k]))) for k in ours)
    return {
        "version": fl.__version__,
        "build_s": build_s,
        "single_median_us": float(np.median(times) * 1e6),
        "batch_rows": n_batch,
        "batch_per_s": n_batch / batch_s,
        "max_abs_diff_vs_ours_centroid_rpm": agreement,
    }


def time_skfuzzy(quick: bool) -> dict:
    try:
        import skfuzzy
        from skfuzzy import control as ctrl
    except ImportError:
        return {"skipped": "scikit-fuzzy not installed (pip install .[bench])"}
    rb = load_rulebase("paper")

    def build(n_rules: int):
        antecedents = {}
        for v in rb.inputs:
            universe = np.linspace(v.low, v.high, 201)
            variable = ctrl.Antecedent(universe, v.name)
            mu = v.memberships(universe)
            for k, s in enumerate(v.sets):
                variable[s.name] = mu[:, k]
            antecedents[v.name] = variable
        consequents = {}
        for v in rb.outputs:
            variable = ctrl.Consequent(np.linspace(v.low, v.high, 1001), v.name)
            mu = v.memberships(variable.universe)
            for k, s in enumerate(v.sets):
                variable[s.name] = mu[:, k]
            consequents[v.name] = variable
        rules = []
        for r in rb.rules[:n_rules]:
            term = None
            for v, j in zip(rb.inputs, r.antecedent):
                clause = antecedents[v.name][v.sets[j].name]
                term = clause if term is None else term & clause
            outs = [consequents[v.name][v.sets[k].name] for v, k in zip(rb.outputs, r.consequent) if k is not None]
            rules.append(ctrl.Rule(term, outs))
        return ctrl.ControlSystemSimulation(ctrl.ControlSystem(rules))

    sizes, builds, computes = [], [], []
    spent = 0.0
    for n_rules in (12, 24, 48, 96) if not quick else (12, 24):
        start = time.perf_counter()
        simulation = build(n_rules)
        build_s = time.perf_counter() - start
        # inputs inside the first rules' cells (target_distance near, direction ahead)
        simulation.inputs({"target_distance": 2.0, "target_direction": 10.0, "obstacle_left": 3.0,
                           "obstacle_front": 3.0, "obstacle_right": 3.0, "obstacle_back": 3.0})  # fmt: skip
        start = time.perf_counter()
        simulation.compute()
        compute_s = time.perf_counter() - start
        sizes.append(n_rules)
        builds.append(build_s)
        computes.append(compute_s)
        spent += build_s + compute_s
        if spent > SKFUZZY_BUILD_CAP_S:
            break
    exponent, log_scale = np.polyfit(np.log(sizes), np.log(np.maximum(builds, 1e-6)), 1) if len(sizes) > 1 else (1.0, 0.0)
    return {
        "version": skfuzzy.__version__,
        "rules_built": sizes,
        "build_s": builds,
        "single_compute_s": computes,
        "build_exponent": float(exponent),
        "build_972_s_extrapolated": float(math.exp(log_scale) * 972**exponent),
    }


def scattered_world(rng: np.random.Generator):
    heading = rng.uniform(-math.pi, math.pi)
    target = (25.0 * math.cos(heading), 25.0 * math.sin(heading))
    obstacles = []
    while len(obstacles) < 8:
        along, across = rng.uniform(4.0, 21.0), rng.normal(0.0, 2.5)
        x = along * math.cos(heading) - across * math.sin(heading)
        y = along * math.sin(heading) + across * math.cos(heading)
        if rng.random() < 0.5:
            candidate = Circle(x, y, rng.uniform(0.3, 1.2))
        else:
            half_w, half_h = rng.uniform(0.25, 1.0, 2)
            candidate = box(x - half_w, y - half_h, x + half_w, y + half_h)
        if all(candidate.clearance(*p) > 1.5 for p in ((0.0, 0.0), target)):
            obstacles.append(candidate)
    return target, obstacles, rng.uniform(-math.pi, math.pi)


def navigation(quick: bool) -> dict:
    worlds = 20 if quick else 100
    navigators = {
        "paper (4 sensors)": (Navigator(load_rulebase("paper"), NavigatorParams(), 200.0), PAPER_ORIENTATIONS),
        "default (6 sensors)": (Navigator(load_rulebase("default"), NavigatorParams(), 200.0), (0, 1, 2, 4, 6, 7)),
    }
    result = {}
    for name, (nav, orientations) in navigators.items():
        rng = np.random.default_rng(SEED)
        reached = collided = 0
        ratios, times = [], []
        for _ in range(worlds):
            target, obstacles, start_heading = scattered_world(rng)
            run = drive(nav, target, obstacles, start=(0.0, 0.0, start_heading), orientations=orientations, time_limit_s=90.0)
            collided += run.collided
            if run.reached:
                reached += 1
                ratios.append(run.length_m / (math.dist((0.0, 0.0), target) - 1.0))
                times.append(run.time_s)
        result[name] = {
            "worlds": worlds,
            "success_rate": reached / worlds,
            "collision_rate": collided / worlds,
            "timeout_rate": (worlds - reached - collided) / worlds,
            "path_ratio_mean": float(np.mean(ratios)) if ratios else math.nan,
            "time_s_mean": float(np.mean(times)) if times else math.nan,
        }
    return result


def run(quick: bool) -> dict:
    ours = time_ours(quick)
    fuzzylite = time_fuzzylite(quick)
    skfuzzy = time_skfuzzy(quick)
    nav = navigation(quick)
    a, c = ours["area_centre"], ours["centroid"]
    lines = [
        "Paper rule base (972 rules, 6 inputs, 2 outputs), random inputs over the universes.",
        "",
        "Wall-clock figures, and in brackets per CPU second (the run's machine may be shared).",
        "",
        "| engine | defuzzifier | single evaluation | batch evaluations/s |",
        "|---|---|---|---|",
        f"| rover_ctl (compiled) | paper area-centre | {a['single_median_us']:.1f} us ({a['single_cpu_us']:.1f} us CPU) "
        f"| {a['batch_per_s']:,.0f} ({a['batch_per_cpu_s']:,.0f}) |",
        f"| rover_ctl (compiled) | centroid, 1001 samples | {c['single_median_us']:.1f} us ({c['single_cpu_us']:.1f} us CPU) "
        f"| {c['batch_per_s']:,.0f} ({c['batch_per_cpu_s']:,.0f}) |",
    ]
    if "skipped" in fuzzylite:
        lines.append(f"| pyfuzzylite | - | {fuzzylite['skipped']} | |")
    else:
        lines.append(f"| pyfuzzylite {fuzzylite['version']} | centroid, 1001 samples | {fuzzylite['single_median_us'] / 1000:.1f} ms "
                     f"| {fuzzylite['batch_per_s']:,.0f} |")  # fmt: skip
    if "skipped" in skfuzzy:
        lines.append(f"| scikit-fuzzy | - | {skfuzzy['skipped']} | |")
    else:
        lines.append(f"| scikit-fuzzy {skfuzzy['version']} | centroid | {skfuzzy['single_compute_s'][-1] * 1000:.0f} ms "
                     f"({skfuzzy['rules_built'][-1]} rules) | build of 972 rules: ~{skfuzzy['build_972_s_extrapolated']:.0f} s (extrapolated) |")  # fmt: skip
    lines.append("")
    if "skipped" not in fuzzylite:
        ratio = a["batch_per_s"] / fuzzylite["batch_per_s"]
        lines.append(f"Batch rate vs pyfuzzylite: {ratio:,.0f}x (area-centre), {c['batch_per_s'] / fuzzylite['batch_per_s']:,.0f}x "
                     f"(same centroid defuzzifier); outputs agree within {fuzzylite['max_abs_diff_vs_ours_centroid_rpm']:.3f} rpm.")  # fmt: skip
        fuzzylite["ratio_batch_ours_area_centre"] = ratio
    if "skipped" not in skfuzzy:
        lines.append(f"scikit-fuzzy builds: " + ", ".join(f"{n} rules {s:.1f} s" for n, s in zip(skfuzzy["rules_built"], skfuzzy["build_s"]))
                     + f" (build time ~ rules^{skfuzzy['build_exponent']:.2f}).")  # fmt: skip
    lines += [
        "",
        f"Navigation in the kinematic rover ({nav['paper (4 sensors)']['worlds']} seeded worlds, 8 scattered obstacles, target 25 m):",
        "",
        "| rule base | success | collision | timeout | path / straight line | mean time |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in nav.items():
        lines.append(f"| {name} | {r['success_rate']:.0%} | {r['collision_rate']:.0%} | {r['timeout_rate']:.0%} "
                     f"| {r['path_ratio_mean']:.2f} | {r['time_s_mean']:.1f} s |")  # fmt: skip
    return {
        "title": "Fuzzy engine and navigator",
        "markdown": "\n".join(lines),
        "quick": quick,
        "ours": ours,
        "pyfuzzylite": fuzzylite,
        "scikit_fuzzy": skfuzzy,
        "navigation": nav,
    }
