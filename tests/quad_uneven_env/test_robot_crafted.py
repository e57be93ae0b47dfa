"""Crafted robot files, as a user might write them: each wrong one is refused in one message naming the file and
the field (never accepted, never a raw traceback), and an edited file is read again.

The URDF robots are Go1's URDF and SRDF (example-robot-data, the ``robots`` extra) beside a YAML in a temporary
folder, edited per case; the Table-1 robots are configs/robot/paper.yaml, edited.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from quad_uneven_env.config import CONFIG_DIR
from quad_uneven_env.robot.description import load_robot, robot_data_dir

GO1_URDF = robot_data_dir() / "go1_description" / "urdf" / "go1.urdf"
GO1_SRDF = robot_data_dir() / "go1_description" / "srdf" / "go1.srdf"
GO1_LEGS = {
    "LF": ["FL", "FL"],
    "RF": ["FR", "FR"],
    "LH": ["RL", "RL"],
    "RH": ["RR", "RR"],
}
"""Per leg, the URDF prefix of its joints and of its foot frame."""
TRUNK_BOX = '<box size="0.3762 0.0935 0.114"/>'


def _legs(prefixes: dict[str, list[str]]) -> dict[str, dict]:
    return {
        leg: {"joints": [f"{j}_hip_joint", f"{j}_thigh_joint", f"{j}_calf_joint"], "foot": f"{f}_foot"}
        for leg, (j, f) in prefixes.items()
    }


def urdf_robot(folder: Path, edit_urdf=None, srdf_text: str | None = None, **fields) -> Path:
    """A YAML naming Go1's URDF (copied, edited by ``edit_urdf``) and SRDF (or ``srdf_text``), with ``fields`` over
    the defaults; returns the YAML's path."""
    folder.mkdir(parents=True, exist_ok=True)
    text = GO1_URDF.read_text()
    (folder / "mine.urdf").write_text(edit_urdf(text) if edit_urdf else text)
    (folder / "mine.srdf").write_text(GO1_SRDF.read_text() if srdf_text is None else srdf_text)
    raw = {"name": "mine", "urdf": "mine.urdf", "srdf": "mine.srdf", "legs": _legs(GO1_LEGS), "foot_radius": 0.02}
    raw.update(fields)
    path = folder / "mine.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def table1_robot(folder: Path, **edits) -> Path:
    """configs/robot/paper.yaml with ``edits`` (``"thigh.com": value`` sets a nested field)."""
    raw = yaml.safe_load((CONFIG_DIR / "robot" / "paper.yaml").read_text())
    for key, value in edits.items():
        *parents, last = key.split(".")
        node = raw
        for p in parents:
            node = node[p]
        node[last] = value
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "table1.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def test_the_crafted_files_start_from_a_robot_that_loads(tmp_path):
    """The unedited copies load (so a refusal below is the edit's)."""
    mine, table1 = load_robot(urdf_robot(tmp_path / "u")), load_robot(table1_robot(tmp_path / "t"))
    assert mine.total_mass == pytest.approx(load_robot("go1").total_mass, rel=1e-12)
    assert table1.total_mass == load_robot("paper").total_mass


# ---------------------------------------------------------------------- types: a bool is not a number
@pytest.mark.parametrize(
    ("kind", "fields", "message"),
    [
        ("urdf", {"foot_radius": True}, r"mine\.yaml\.foot_radius must be a number .* got True of type bool"),
        ("urdf", {"torque_limit": True}, r"mine\.yaml\.torque_limit must be a number .* got True of type bool"),
        ("urdf", {"torque_limit": {"KFE": True}}, r"torque_limit\.KFE must be a number .* got True of type bool"),
        ("urdf", {"armature": False}, r"mine\.yaml\.armature must be a number .* got False of type bool"),
        ("urdf", {"friction": "1"}, r"mine\.yaml\.friction must be a number .* got '1' of type str"),
        (
            "urdf",
            {"standing_joints": {leg: [0, True, -1.6] for leg in GO1_LEGS}},
            r"standing_joints\.LF\[1\] must be a number .* got True of type bool",
        ),
        ("table1", {"body.size": [True, 0.37, 0.1]}, r"table1\.yaml\.body\.size\[0\] must be a number .* got True"),
        ("table1", {"thigh.com": True}, r"table1\.yaml\.thigh\.com must be a number .* got True of type bool"),
        ("table1", {"shank.inertia": [0.0, "0.002", 0.002]}, r"shank\.inertia\[1\] must be a number .* got '0\.002'"),
    ],
    ids=[
        "foot_radius",
        "torque_limit",
        "torque_limit_kfe",
        "armature",
        "friction_text",
        "standing",
        "size",
        "com",
        "inertia",
    ],
)
def test_a_bool_or_a_text_is_not_a_number(tmp_path, kind, fields, message):
    if kind == "urdf":
        path = urdf_robot(tmp_path, **fields)
    else:
        path = table1_robot(tmp_path, **fields)
    with pytest.raises(ValueError, match=message):
        load_robot(path)


# ---------------------------------------------------------------------- sizes in proportion to the robot
def _shank_of_zero_length(text: str) -> str:
    """Go1's LF foot joint moved onto its knee (the foot frame at the KFE origin)."""
    start = text.index('<joint name="FL_foot_fixed"')
    end = text.index("</joint>", start)
    joint = text[start:end]
    return text[:start] + joint.replace('xyz="0 0 -0.213"', 'xyz="0 0 0"') + text[end:]


@pytest.mark.parametrize(
    ("kind", "urdf", "fields", "message"),
    [
        (
            "urdf",
            lambda s: s.replace('effort="23.7"', 'effort="1e12"'),
            {},
            r"mine\.yaml\.LF\.HAA\.torque_limit \(FL_hip_joint\) must be at most 547\.5 N m .* got 1e\+12",
        ),
        ("urdf", None, {"torque_limit": 1e12}, r"LF\.HAA\.torque_limit .* must be at most 547\.5 N m"),
        ("urdf", _shank_of_zero_length, {}, r"mine\.yaml\.legs\.LF: its shank must be at least 0\.25 of the leg"),
        (
            "urdf",
            lambda s: s.replace(TRUNK_BOX, '<box size="60 0.0935 0.114"/>'),
            {},
            r"mine\.yaml: the trunk's collision box must span at most 1\.278 m .* got sizes \[60\.0, ",
        ),
        ("urdf", None, {"foot_radius": 5}, r"mine\.yaml\.foot_radius must be at most 0\.5 of the shortest shank"),
        ("urdf", None, {"link_radius": 1.0}, r"mine\.yaml\.link_radius must be at most 0\.5 of the shortest thigh"),
        ("table1", None, {"body.size": [60.0, 0.37, 0.1]}, r"table1\.yaml: the hips must lie within 0\.63 m"),
        (
            "table1",
            None,
            {"shank.length": 0.001, "shank.com": 0.0, "standing_hip_height": 0.15},
            r"legs\.LF: its shank must be at least 0\.25",
        ),
        ("table1", None, {"torque_limit.KFE": 1e12}, r"table1\.yaml\.LF\.KFE\.torque_limit .* at most 2060 N m"),
    ],
    ids=[
        "urdf_effort",
        "yaml_torque",
        "zero_shank",
        "trunk_60m",
        "foot_5m",
        "link_1m",
        "table1_trunk_60m",
        "table1_shank_1mm",
        "table1_torque",
    ],
)
def test_sizes_out_of_proportion_are_refused(tmp_path, kind, urdf, fields, message):
    """Bounds scaled to the robot (its mass and leg length): each would diverge or mislead a simulation."""
    path = urdf_robot(tmp_path, urdf, **fields) if kind == "urdf" else table1_robot(tmp_path, **fields)
    with pytest.raises(ValueError, match=message):
        load_robot(path)


def test_a_huge_foot_is_the_robots_field_not_the_envs(tmp_path):
    """``foot_radius: 5`` is refused naming the field the user wrote, not a base-height limit derived from it."""
    path = urdf_robot(tmp_path, foot_radius=5)
    with pytest.raises(ValueError, match=r"foot_radius") as err:
        gym.make("QuadUneven-v0", robot=str(path))
    assert "termination" not in str(err.value)


# ---------------------------------------------------------------------- each leg where its name says, once
@pytest.mark.parametrize(
    ("prefixes", "message"),
    [
        (
            {"LF": ["FR", "FR"], "RF": ["FL", "FL"], "LH": ["RL", "RL"], "RH": ["RR", "RR"]},
            r"mine\.yaml\.legs\.LF: its hip \(FR_hip_joint\) must lie at the front \(x > 0\) left \(y > 0\) of the "
            r"trunk, got x = 0\.1881 m, y = -0\.04675 m",
        ),
        (
            {"LF": ["RL", "RL"], "RF": ["FR", "FR"], "LH": ["FL", "FL"], "RH": ["RR", "RR"]},
            r"legs\.LF: its hip \(RL_hip_joint\) must lie at the front \(x > 0\) left",
        ),
        (
            {"LF": ["FL", "FL"], "RF": ["FL", "FL"], "LH": ["RL", "RL"], "RH": ["RR", "RR"]},
            r"mine\.yaml\.legs\.RF: HAA joint 'FL_hip_joint' is given twice \(also to LF",
        ),
        (
            {"LF": ["FL", "FL"], "RF": ["FR", "FL"], "LH": ["RL", "RL"], "RH": ["RR", "RR"]},
            r"mine\.yaml\.legs\.RF: foot 'FL_foot' is given twice",
        ),
    ],
    ids=["left_right_swapped", "front_hind_swapped", "one_leg_twice", "one_foot_twice"],
)
def test_each_leg_on_its_side_and_end_and_every_joint_once(tmp_path, prefixes, message):
    with pytest.raises(ValueError, match=message):
        load_robot(urdf_robot(tmp_path, legs=_legs(prefixes)))


# ---------------------------------------------------------------------- the URDF's and SRDF's own errors
SRDF_WITHOUT_STANDING = '<?xml version="1.0"?>\n<robot name="go1">\n  <group name="all"/>\n</robot>\n'


@pytest.mark.parametrize(
    ("urdf", "srdf", "fields", "message"),
    [
        (
            None,
            SRDF_WITHOUT_STANDING,
            {},
            r"mine\.yaml\.standing_state 'standing' is not a group state of mine\.srdf; "
            r"it has \[\]",
        ),
        (None, None, {"standing_state": "crouch"}, r"standing_state 'crouch' .* it has \['standing'\]"),
        (None, "garbage <<<", {}, r"mine\.yaml\.srdf: file '.*mine\.srdf' cannot be read by Pinocchio: .*expected <"),
        (lambda s: "garbage <<<", None, {}, r"mine\.yaml\.urdf: file '.*mine\.urdf' cannot be read by Pinocchio"),
        (
            lambda s: s.replace(TRUNK_BOX, "<box/>"),
            None,
            {},
            r"mine\.yaml\.urdf: 1 of the 18 collision boxes of '.*mine\.urdf' cannot be read by Pinocchio \(a box "
            r'needs size="x y z", m\)',
        ),
        (None, None, {"srdf": {"package": "example-robot-data", "path": 3}}, r"mine\.yaml\.srdf must be a path"),
        (None, None, {"urdf": "missing.urdf"}, r"mine\.yaml\.urdf: file '.*missing\.urdf' does not exist"),
    ],
    ids=[
        "srdf_without_the_state",
        "state_not_in_srdf",
        "garbage_srdf",
        "garbage_urdf",
        "box_without_size",
        "srdf_spec",
        "missing_urdf",
    ],
)
def test_model_file_errors_are_one_message_naming_the_file_and_field(tmp_path, urdf, srdf, fields, message):
    with pytest.raises(ValueError, match=message):
        load_robot(urdf_robot(tmp_path, urdf, srdf, **fields))


def test_the_trunk_box_is_pinocchios_placement_of_the_urdfs_box(tmp_path):
    """A box on a link fixed to the trunk, both placements offset: its centre is the fixed joint's origin plus the
    collision's origin, its half sizes half the URDF's sizes (Go1's own box, 0.3762 m x 0.0935 m x 0.114 m, is
    smaller and loses)."""
    extra = textwrap.dedent("""
      <joint name="bumper_fixed" type="fixed">
        <origin rpy="0 0 0" xyz="0.1 0 0.02"/>
        <parent link="trunk"/>
        <child link="bumper"/>
      </joint>
      <link name="bumper">
        <collision>
          <origin rpy="0 0 0" xyz="0.05 0.01 -0.03"/>
          <geometry><box size="0.5 0.2 0.12"/></geometry>
        </collision>
      </link>
    """)
    path = urdf_robot(tmp_path, lambda s: s.replace("</robot>", extra + "</robot>"))
    centre, half = load_robot(path).trunk_box
    np.testing.assert_allclose(centre, [0.15, 0.01, -0.01], atol=1e-15)
    np.testing.assert_allclose(half, [0.25, 0.1, 0.06], atol=1e-15)
    centre, half = load_robot("go1").trunk_box
    np.testing.assert_allclose(half, np.array([0.3762, 0.0935, 0.114]) / 2, atol=1e-15)


# ---------------------------------------------------------------------- the cache keyed by content
def test_an_edited_robot_file_is_read_again(tmp_path):
    """The same files give the same description; an edited YAML, URDF or SRDF gives a new one, in one process."""
    path = urdf_robot(tmp_path)
    first = load_robot(path)
    assert load_robot(path) is first and load_robot(str(path)) is first
    raw = yaml.safe_load(path.read_text())
    path.write_text(yaml.safe_dump({**raw, "foot_radius": 0.025}))
    assert load_robot(path).foot_radius == 0.025
    urdf = tmp_path / "mine.urdf"
    urdf.write_text(urdf.read_text().replace('<mass value="5.204"/>', '<mass value="6.204"/>', 1))
    assert load_robot(path).trunk.mass == pytest.approx(first.trunk.mass + 1.0, abs=1e-12)
    table1 = table1_robot(tmp_path / "t")
    assert load_robot(table1).friction == 1.0
    table1_robot(tmp_path / "t", friction=0.7)
    assert load_robot(table1).friction == 0.7
