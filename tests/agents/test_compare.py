"""quad-uneven compare: paired episodes of two evaluations, on hand-made result files."""

from __future__ import annotations

import json

import pytest

from agents.cli import main
from agents.evaluation.compare import ComparisonError, compare_runs, failure_kind, shared_push_factors


def _episode(entry, seed, success, end="goal", index=50.0, neg=0.1, residual=None, friction=1.0):
    return {
        "entry": entry,
        "seed": seed,
        "success": success,
        "end_reason": end,
        "mean_stability_index": index,
        "min_stability_index": index - 60.0,
        "time_index_negative": neg,
        "fraction_index_nonnegative": 1.0 - neg / 30.0,
        "mean_speed": 0.1,
        "mean_residual_torque": residual,
        "factors": {"friction": friction},
    }


def _run(folder, policy, episodes, entries=("rough", "stairs")):
    folder.mkdir()
    results = {
        "suite": "s",
        "policy": policy,
        "episodes": episodes,
        "meta": {"entries": list(entries), "seed_offset": 100},
    }
    (folder / "results.json").write_text(json.dumps(results))
    return folder


def test_counts_rates_and_changed_episodes(tmp_path):
    base = _run(tmp_path / "a", "expert", [
        _episode(0, 100, True, friction=0.3),
        _episode(0, 101, False, "time_limit", friction=0.4, neg=3.0),
        _episode(1, 100, False, "fall", friction=0.9),
        _episode(1, 101, True, friction=1.1),
    ])  # fmt: skip
    cand = _run(tmp_path / "b", "model.zip", [
        _episode(1, 101, True, residual=1.5, friction=1.1),
        _episode(0, 100, True, residual=0.5, friction=0.3),
        _episode(0, 101, True, residual=1.0, friction=0.4, neg=0.3),
        _episode(1, 100, False, "diverged", residual=2.0, friction=0.9),
    ])  # fmt: skip
    comp = compare_runs(base, cand)
    a, b = comp["overall"]["baseline"], comp["overall"]["candidate"]
    assert (a["successes"], a["stalls"], a["falls"], a["divergences"]) == (2, 1, 1, 0)
    assert (b["successes"], b["stalls"], b["falls"], b["divergences"]) == (3, 0, 0, 1)
    assert a["failure_rate"] == 0.5 and b["failure_rate"] == 0.25
    assert b["mean_residual_torque"] == pytest.approx(1.25) and a["mean_residual_torque"] is None
    assert a["mean_time_index_negative"] == pytest.approx((0.1 + 3.0 + 0.1 + 0.1) / 4)
    assert [(e["entry"], e["seed"], e["baseline"], e["candidate"]) for e in comp["changed"]] == [
        (0, 101, "stall", "success"),
        (1, 100, "fall", "diverged"),
    ]
    assert [r["candidate"]["successes"] for r in comp["by_entry"]] == [2, 1]
    friction = [r for r in comp["by_factor"] if r["factor"] == "friction"]
    assert [(r["bin"], r["low"]) for r in friction] == [
        ("< 0.35", 0.3),
        ("0.35-0.45", 0.4),
        ("0.8-1", 0.9),
        (">= 1", 1.1),
    ]
    assert [r["baseline"]["successes"] for r in friction] == [1, 0, 0, 1]
    assert [r["candidate"]["successes"] for r in friction] == [1, 1, 0, 1]


def _pushed(episode, impulses, received):
    """``episode`` with the first ``received`` of the world's pushes (impulses in N s, one every 5 s)."""
    pushes = [{"start": 5.0 * (k + 1), "impulse": imp} for k, imp in enumerate(impulses[:received])]
    factors = {
        **episode["factors"],
        "push_count": float(received),
        "push_impulse_max": max(impulses[:received], default=0.0),
    }
    return {**episode, "pushes": pushes, "factors": factors}


def test_pairs_are_binned_by_the_pushes_both_episodes_received(tmp_path):
    """The baseline falls after its first push in three worlds where the candidate walks on through four more:
    binned by the baseline's own count those would be "its fewest pushes", all candidate successes; binned by
    the pushes both received, each pair sits where the shorter episode ended, for both policies."""
    world = [10.0, 3.0, 24.0, 5.0, 8.0]
    base_eps, cand_eps = [], []
    for seed in range(6):
        early = seed < 3
        base_eps.append(
            _pushed(_episode(0, seed, not early, "goal" if not early else "fall"), world, 1 if early else 5)
        )
        cand_eps.append(_pushed(_episode(0, seed, True), world, 5))
    comp = compare_runs(_run(tmp_path / "a", "expert", base_eps), _run(tmp_path / "b", "model.zip", cand_eps))
    counts = [r for r in comp["by_factor"] if r["factor"] == "push_count"]
    assert [(r["low"], r["baseline"]["episodes"]) for r in counts] == [(1.0, 3), (5.0, 3)]
    assert [r["baseline"]["successes"] for r in counts] == [0, 3]
    assert [r["candidate"]["successes"] for r in counts] == [3, 3]
    impulses = [r for r in comp["by_factor"] if r["factor"] == "push_impulse_max"]
    assert [(r["low"], r["high"]) for r in impulses] == [(10.0, 10.0), (24.0, 24.0)]
    # the same pairs with the roles swapped: the same groups (binning by the baseline's own pushes would not)
    swapped = compare_runs(tmp_path / "b", tmp_path / "a")
    assert [(r["low"], r["baseline"]["episodes"]) for r in swapped["by_factor"] if r["factor"] == "push_count"] == [
        (1.0, 3),
        (5.0, 3),
    ]


def test_shared_pushes_stop_where_the_lists_differ():
    a = {"pushes": [{"start": 5.0, "impulse": 10.0}, {"start": 10.0, "impulse": 20.0}]}
    b = {"pushes": [{"start": 5.0, "impulse": 10.0}, {"start": 10.5, "impulse": 30.0}, {"start": 15.0, "impulse": 1}]}
    assert shared_push_factors(a, b) == {"push_count": 1.0, "push_impulse_max": 10.0}
    assert shared_push_factors(a, {"pushes": []}) == {"push_count": 0.0, "push_impulse_max": 0.0}
    assert shared_push_factors(a, {}) is None


def test_runs_of_other_episodes_are_refused_and_the_cli_writes_files(tmp_path, capsys):
    base = _run(tmp_path / "a", "expert", [_episode(0, 100, True), _episode(0, 101, True)])
    other = _run(tmp_path / "b", "expert", [_episode(0, 100, True), _episode(0, 102, True)])
    with pytest.raises(ComparisonError, match="do not hold the same"):
        compare_runs(base, other)
    assert main(["compare", "--baseline", str(base), "--candidate", str(other), "--out", str(tmp_path / "c")]) == 2
    assert "do not hold the same" in capsys.readouterr().err
    assert main(["compare", "--baseline", str(base), "--candidate", str(base), "--out", str(tmp_path / "c")]) == 0
    text = (tmp_path / "c" / "comparison.md").read_text()
    assert "every episode ended the same way" in text
    assert (tmp_path / "c" / "comparison.png").stat().st_size > 1000
    assert json.loads((tmp_path / "c" / "comparison.json").read_text())["changed"] == []


def test_failure_kinds():
    assert failure_kind({"success": True, "end_reason": "goal"}) is None
    assert failure_kind({"success": False, "end_reason": "left_terrain"}) == "fall"
    assert failure_kind({"success": False, "end_reason": "wall_time_limit"}) == "stall"
    assert failure_kind({"success": False, "end_reason": "error"}) == "error"


def test_mcnemar_exact_p_against_scipy_and_by_hand():
    from scipy.stats import binomtest

    from agents.evaluation.compare import mcnemar_exact_p

    assert mcnemar_exact_p(0, 0) == 1.0
    assert mcnemar_exact_p(3, 0) == pytest.approx(2 * 1 / 8)  # by hand: 2 x P(0 of 3)
    assert mcnemar_exact_p(1, 1) == 1.0  # capped: the doubled tail of an even split exceeds 1
    for fixed, broken in [(25, 9), (23, 10), (37, 12), (0, 7), (12, 12), (1, 30)]:
        expected = binomtest(min(fixed, broken), fixed + broken, 0.5).pvalue
        assert mcnemar_exact_p(fixed, broken) == pytest.approx(expected, rel=1e-12)
        assert mcnemar_exact_p(fixed, broken) == mcnemar_exact_p(broken, fixed)
    with pytest.raises(ValueError, match="fixed and broken"):
        mcnemar_exact_p(-1, 2)


def test_pooled_folders_pair_per_set_and_test_the_paired_successes(tmp_path, capsys):
    """Two seed sets pooled: counts add up, fixed/broken and the failure ratio are over all episodes."""
    base1 = _run(tmp_path / "e1", "expert", [_episode(0, 100, False, "fall"), _episode(1, 100, True)])
    cand1 = _run(tmp_path / "r1", "m.zip", [_episode(0, 100, True), _episode(1, 100, True)])
    base2 = _run(tmp_path / "e2", "expert", [_episode(0, 300, False, "fall"), _episode(1, 300, False, "fall")])
    cand2 = _run(tmp_path / "r2", "m.zip", [_episode(0, 300, True), _episode(1, 300, False, "time_limit")])
    for path, offset in ((base2, 300), (cand2, 300)):
        results = json.loads((path / "results.json").read_text())
        results["meta"]["seed_offset"] = offset
        (path / "results.json").write_text(json.dumps(results))
    comp = compare_runs([base1, base2], [cand1, cand2])
    assert comp["overall"]["baseline"]["successes"] == 1 and comp["overall"]["candidate"]["successes"] == 3
    assert comp["overall"]["paired"] == {"fixed": 2, "broken": 0, "mcnemar_p": 0.5, "failure_ratio": 1 / 3}
    assert comp["seed_offset"] == [100, 300] and comp["baseline"]["dir"] == [str(base1), str(base2)]
    assert [(e["seed"], e["baseline"], e["candidate"]) for e in comp["changed"]] == [
        (100, "fall", "success"),
        (300, "fall", "success"),
        (300, "fall", "stall"),
    ]
    single = compare_runs(base1, cand1)
    assert single["overall"]["paired"]["fixed"] == 1 and single["seed_offset"] == 100
    out = tmp_path / "c"
    argv = ["compare", "--baseline", str(base1), str(base2), "--candidate", str(cand1), str(cand2), "--out", str(out)]
    assert main(argv) == 0
    assert "2 baseline failures fixed, 0 baseline successes lost (McNemar p = 0.5)" in capsys.readouterr().out
    assert "seed offsets 100, 300" in (out / "comparison.md").read_text()


def test_pooled_folders_that_cannot_be_pooled_are_refused_by_name(tmp_path, capsys):
    base = _run(tmp_path / "e1", "expert", [_episode(0, 100, True)])
    cand = _run(tmp_path / "r1", "m.zip", [_episode(0, 100, True)])
    other = _run(tmp_path / "o", "other.zip", [_episode(0, 300, True)])
    base_b = _run(tmp_path / "e2", "expert", [_episode(0, 300, True)])
    stairs = _run(tmp_path / "s", "expert", [_episode(0, 300, True)], entries=("stairs",))
    with pytest.raises(ComparisonError, match="1 folder\\(s\\) for 2 baseline"):
        compare_runs([base, base_b], [cand])
    with pytest.raises(ComparisonError, match="both hold entry 0, seed 100"):
        compare_runs([base, base], [cand, cand])
    assert compare_runs([base, base_b], [cand, other])["candidate"]["policy"] == ["m.zip", "other.zip"]
    with pytest.raises(ComparisonError, match="different suite entries"):
        compare_runs([base, stairs], [cand, stairs])
    argv = ["compare", "--baseline", str(base), str(base_b), "--candidate", str(cand), "--out", str(tmp_path / "c")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "candidate: 1 folder(s) for 2 baseline folder(s)" in err and "Traceback" not in err


def test_the_comparison_says_when_the_runs_were_made_on_different_machines(tmp_path, capsys):
    from agents.evaluation.machine import machine_info

    here = machine_info()
    there = {**here, "cpu": "another CPU", "mujoco": "0.0.1"}
    eps = [_episode(0, 100, True), _episode(0, 101, False, "fall")]
    same_a = _run(tmp_path / "a", "expert", [{**e, "machine": here} for e in eps])
    same_b = _run(tmp_path / "b", "m.zip", [{**e, "machine": here} for e in eps])
    other = _run(tmp_path / "c", "m.zip", [{**eps[0], "machine": here}, {**eps[1], "machine": there}])
    old = _run(tmp_path / "d", "m.zip", eps)  # written before records had a machine

    assert compare_runs(same_a, same_b)["machines_differ"] == []
    assert compare_runs(same_a, other)["machines_differ"] == ["cpu", "mujoco"]
    assert compare_runs(same_a, old)["machines_differ"] is None
    assert main(["compare", "--baseline", str(same_a), "--candidate", str(other), "--out", str(tmp_path / "o")]) == 0
    assert "different machines (cpu, mujoco)" in capsys.readouterr().out
    assert "**Machines differ** (cpu, mujoco)" in (tmp_path / "o" / "comparison.md").read_text()
    assert main(["compare", "--baseline", str(same_a), "--candidate", str(same_b), "--out", str(tmp_path / "s")]) == 0
    assert "warning" not in capsys.readouterr().out
    assert "one machine kind" in (tmp_path / "s" / "comparison.md").read_text()


def test_machine_info_matches_the_libraries_themselves():
    import platform

    import mujoco
    import numpy as np
    import scipy

    from agents.evaluation.machine import machine_info

    m = machine_info()
    assert m["numpy"] == np.__version__ and m["scipy"] == scipy.__version__ and m["mujoco"] == mujoco.__version__
    assert m["python"] == platform.python_version() and m["arch"] == platform.machine()
    assert m["cpu"] and set(m["simd"].split()) <= {"avx512f", "avx2", "fma", "avx", "sse4_2", "neon", "asimd"}
    assert m["stable-baselines3"] != "absent" and m["torch"].startswith("2.")
