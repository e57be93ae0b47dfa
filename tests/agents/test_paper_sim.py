"""``quad-uneven paper``: the simulated §6 run, its figures and paper.json (shortened horizon)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from agents.cli import main
from agents.paper.animation import frame_indices
from agents.paper.metrics import time_to_switch
from agents.paper.simulation import PaperRunConfig
from quad_uneven_env.constants import JOINT_NAMES, LEG_NAMES


@pytest.fixture(scope="module")
def paper_out(tmp_path_factory):
    """Run the command for 1.3 s of the cycle (four-leg support, RH lift-off and swing)."""
    out = tmp_path_factory.mktemp("paper")
    rc = main(["paper", "--out", str(out), "--duration", "1.3", "--fps", "5", "--no-progress"])
    assert rc == 0
    return out, json.loads((out / "paper.json").read_text())


def test_every_file_is_written(paper_out):
    out, info = paper_out
    expected = ["fig4_swing_paths.png", "fig5_cog.png", "fig6_stability.png", "fig7_torques.png",
                "fig8_contact_forces.png", "fig9_stick.gif"]  # fmt: skip
    assert info["figures"] == expected
    for name in expected:
        data = (out / name).read_bytes()
        assert len(data) > 5000, name
        assert data[:4] in (b"\x89PNG", b"GIF8"), name


def test_paper_json_numbers_are_plausible(paper_out):
    _, info = paper_out
    assert info["fell"] is False and info["fall_reason"] is None
    assert info["simulated_time_s"] == pytest.approx(1.3, abs=0.003)
    # the robot starts on the start blocks: foot sites 0.02 m above the tops
    assert info["start_foot_site_error_max_m"] < 1e-6
    assert info["min_stability_index_planned_Nm"] >= info["epsilon_Nm"] - 1e-6
    assert math.isfinite(info["min_stability_index_measured_Nm"]) and info["min_stability_index_measured_Nm"] > 0
    assert info["time_without_support_s"] == 0.0
    # positive in stance, zero in swing (away from the lift-off / touch-down instants)
    assert info["min_normal_force_stance_settled_N"] > 0.0
    assert info["max_normal_force_swing_settled_N"] == 0.0
    assert 0.0 <= info["max_normal_force_swing_N"] < 20.0  # the lifting foot unloads within a few ms
    assert 0.0 < info["cog_tracking_error_rms_m"] <= info["cog_tracking_error_max_m"] < 0.02
    assert set(info["torque_peaks_Nm"]) == set(JOINT_NAMES)
    peaks = np.array(list(info["torque_peaks_Nm"].values()))
    assert np.all(np.isfinite(peaks)) and np.all(peaks > 0) and np.all(peaks <= info["torque_limit_Nm"] + 1e-9)
    assert max(peaks) == pytest.approx(info["torque_peak_max_Nm"])
    assert set(info["stance_foot_xy_error_max_m"]) == set(LEG_NAMES)
    assert max(info["stance_foot_xy_error_max_m"].values()) < 0.02


def test_time_to_switch_hand_computed():
    t = np.arange(6) * 0.5
    stance = np.array([[1, 1], [1, 1], [0, 1], [0, 1], [1, 1], [1, 1]], dtype=bool)
    d = time_to_switch(t, stance)
    np.testing.assert_allclose(d[:, 0], [1.0, 0.5, 0.0, 0.5, 0.0, 0.5])
    assert np.all(np.isinf(d[:, 1]))


def test_frame_indices():
    t = np.arange(0, 1.0, 0.002)
    ks = frame_indices(t, 10.0)
    np.testing.assert_allclose(t[ks], np.arange(0, 1.0, 0.1), atol=1e-9)
    with pytest.raises(ValueError, match="fps"):
        frame_indices(t, 0.0)


@pytest.mark.parametrize(
    ("field", "value"),
    [("distribution", "lstsq"), ("epsilon", -1.0), ("duration", 0.0), ("hold", float("nan"))],
)
def test_config_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=field):
        PaperRunConfig(**{field: value})


def test_cli_rejects_bad_epsilon(tmp_path, capsys):
    assert main(["paper", "--out", str(tmp_path), "--epsilon", "-2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "epsilon" in err and err.count("\n") == 1


def test_plan_paper_command_writes_pngs_and_json(tmp_path):
    import json

    from agents.cli import main

    assert main(["plan-paper", "--out", str(tmp_path / "figs")]) == 0
    for name in ("fig4_swing_paths.png", "fig5_cog.png", "fig6_stability.png"):
        data = (tmp_path / "figs" / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    info = json.loads((tmp_path / "figs" / "plan.json").read_text())
    assert info["min_stability_index_Nm"] >= info["epsilon_Nm"]
    assert max(info["junction_jump_max"].values()) <= 1e-9
    assert min(info["swing_min_clearance_m"].values()) >= 0.05 - 1e-3
