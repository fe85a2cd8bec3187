"""vr_driver.kinematics.scene: the cell file's validation (every error names the entry and the key,
nothing changes on an error), poses (rpy / quaternion), the add / remove / list API, the example cell.
Needs neither pinocchio nor coal."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest
import yaml

from vr_driver.errors import SceneError, VrDriverError
from vr_driver.kinematics.scene import Scene, SceneObject, load_scene, parse_scene, scene_from_dict
from vr_driver.poses import rpy_to_matrix

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
EXAMPLE = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")

BOX = {"name": "table", "type": "box", "size": [0.7, 1.0, 0.3], "position": [1.1, 0.0, 0.15]}
CYL = {"name": "pillar", "type": "cylinder", "radius": 0.1, "length": 2.2, "position": [0.6, 0.6, 1.1]}
SPH = {"name": "ball", "type": "sphere", "radius": 0.05, "position": [0.5, -0.5, 0.2]}


def cell(*entries, **top):
    data = {"frame": "base_link", "objects": [dict(e) if isinstance(e, dict) else e for e in entries]}
    data.update(top)
    return data


def with_(entry, **changes):
    out = dict(entry)
    for k, v in changes.items():
        if v is None:
            out.pop(k, None)
        else:
            out[k] = v
    return out


def test_a_valid_cell_gives_each_object_with_its_shape_size_and_pose():
    scene = scene_from_dict(cell(BOX, CYL, SPH))
    assert scene.names() == ["table", "pillar", "ball"]
    table, pillar, ball = scene.objects()
    assert (table.shape, table.size, table.position) == ("box", (0.7, 1.0, 0.3), (1.1, 0.0, 0.15))
    assert (pillar.shape, pillar.size) == ("cylinder", (0.1, 2.2))
    assert (ball.shape, ball.size) == ("sphere", (0.05,))
    assert table.quaternion == (0.0, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(table.transform, [[1, 0, 0, 1.1], [0, 1, 0, 0], [0, 0, 1, 0.15], [0, 0, 0, 1]])


@pytest.mark.parametrize("rpy", [(0.3, 0.0, 0.0), (0.0, -0.7, 0.0), (0.0, 0.0, 2.0), (0.4, -1.1, 2.9)])
def test_rpy_is_the_urdf_convention(rpy):
    obj = SceneObject.from_dict(with_(BOX, rpy=list(rpy)))
    np.testing.assert_allclose(obj.rotation, rpy_to_matrix(*rpy), atol=1e-12)


def test_a_quaternion_is_normalised_and_gives_the_same_rotation_as_rpy():
    half = math.sin(math.pi / 8), math.cos(math.pi / 8)
    obj = SceneObject.from_dict(with_(BOX, quaternion=[0.0, 0.0, 2 * half[0], 2 * half[1]]))   # yaw 45 deg, x2
    np.testing.assert_allclose(obj.quaternion, (0.0, 0.0, half[0], half[1]), atol=1e-12)
    np.testing.assert_allclose(obj.rotation, rpy_to_matrix(0.0, 0.0, math.pi / 4), atol=1e-12)


@pytest.mark.parametrize("entry, words", [
    (with_(BOX, colour="red"), ["objects[0] (table)", "unknown key colour"]),
    (with_(BOX, radius=0.1), ["objects[0] (table)", "unknown key radius"]),
    (with_(BOX, size=None), ["objects[0] (table)", "missing key size"]),
    (with_(BOX, position=None), ["objects[0] (table)", "missing key position"]),
    (with_(BOX, size=[0.7, float("nan"), 0.3]), ["table", "size[1]", "finite"]),
    (with_(BOX, size=[0.7, -1.0, 0.3]), ["table", "size[1]", "> 0"]),
    (with_(BOX, size=[0.7, 0.0, 0.3]), ["table", "size[1]", "> 0"]),
    (with_(BOX, size=[0.7, 1.0]), ["table", "size", "3 numbers"]),
    (with_(BOX, size=[0.7, True, 0.3]), ["table", "size[1]", "finite"]),
    (with_(BOX, position=[1.0, float("inf"), 0.0]), ["table", "position[1]", "finite"]),
    (with_(BOX, position=[1.0, "0", 0.0]), ["table", "position[1]", "finite"]),
    (with_(BOX, rpy=[0.0, float("nan"), 0.0]), ["table", "rpy[1]", "finite"]),
    (with_(BOX, rpy=[0, 0, 0], quaternion=[0, 0, 0, 1]), ["table", "rpy or quaternion, not both"]),
    (with_(BOX, quaternion=[0, 0, 0, 0]), ["table", "quaternion", "all zero"]),
    (with_(BOX, quaternion=[0, 0, 1]), ["table", "quaternion", "4 numbers"]),
    (with_(CYL, radius=-0.1), ["objects[0] (pillar)", "radius", "> 0"]),
    (with_(CYL, length=float("nan")), ["pillar", "length", "finite"]),
    (with_(CYL, length=None), ["pillar", "missing key length"]),
    (with_(SPH, radius=0.0), ["ball", "radius", "> 0"]),
    (with_(SPH, name="a: b", radius=-1), ["objects[0] (a: b): radius must be > 0"]),
    (with_(SPH, type="cone"), ["objects[0] (ball)", "type", "box, cylinder, sphere"]),
    (with_(SPH, name=""), ["objects[0]", "name"]),
    (with_(SPH, name=None), ["objects[0]", "name"]),
    ("table", ["objects[0]", "mapping"]),
])
def test_a_bad_entry_is_refused_naming_the_entry_and_the_key(entry, words):
    with pytest.raises(SceneError) as err:
        scene_from_dict(cell(entry), source="cell.yaml")
    text = str(err.value)
    assert text.startswith("cell.yaml: "), text
    for w in words:
        assert w in text, text


def test_a_duplicate_name_names_both_entries():
    with pytest.raises(SceneError, match=r"objects\[2\] \(table\): duplicate name, already used by objects\[0\]"):
        scene_from_dict(cell(BOX, CYL, with_(SPH, name="table")))


@pytest.mark.parametrize("data, words", [
    (cell(BOX, colour="red"), ["unknown key colour"]),
    (cell(BOX, frame="world"), ["frame must be base_link", "'world'"]),
    ({"objects": {"table": BOX}}, ["objects must be a list"]),
    ([BOX], ["must be a mapping"]),
])
def test_a_bad_cell_file_is_refused(data, words):
    with pytest.raises(SceneError) as err:
        scene_from_dict(data)
    for w in words:
        assert w in str(err.value)


def test_an_empty_file_or_list_is_an_empty_scene():
    assert len(parse_scene("")) == 0
    assert len(parse_scene("objects: []\n")) == 0


def test_yaml_and_file_errors_name_the_file(tmp_path):
    with pytest.raises(SceneError, match="not valid YAML"):
        parse_scene("objects: [\n", "x.yaml")
    missing = str(tmp_path / "none.yaml")
    with pytest.raises(SceneError, match="cannot read cell file .*none.yaml"):
        load_scene(missing)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cell(BOX, with_(CYL, radius=float("nan")))))
    with pytest.raises(SceneError) as err:
        load_scene(str(path))
    assert str(err.value).startswith(str(path) + ": objects[1] (pillar): radius")


def test_scene_errors_are_value_errors_of_the_driver_tree():
    assert issubclass(SceneError, VrDriverError) and issubclass(SceneError, ValueError)


def test_add_remove_list_and_a_refused_change_changes_nothing():
    scene = Scene()
    scene.add(SceneObject.from_dict(BOX))
    scene.add(SceneObject("ball", "sphere", (0.05,), (0.5, -0.5, 0.2)))
    assert scene.names() == ["table", "ball"] and "ball" in scene and len(scene) == 2
    version = scene.version
    with pytest.raises(SceneError, match="'table' is already in the scene"):
        scene.add(SceneObject("table", "sphere", (0.1,)))
    with pytest.raises(SceneError, match="no object named 'shelf'.*objects: table, ball"):
        scene.remove("shelf")
    with pytest.raises(SceneError, match="already in the scene"):
        scene.add_all([SceneObject("a", "sphere", (0.1,)), SceneObject("ball", "sphere", (0.1,))])
    assert scene.names() == ["table", "ball"] and scene.version == version
    assert scene.get("table").size == (0.7, 1.0, 0.3)
    removed = scene.remove("table")
    assert removed.name == "table" and scene.names() == ["ball"] and scene.version == version + 1
    scene.replace(SceneObject("ball", "sphere", (0.2,), (0.0, 0.0, 2.0)))
    assert scene.get("ball").size == (0.2,)
    snapshot = scene.copy()
    scene.clear()
    assert len(scene) == 0 and snapshot.names() == ["ball"]


def test_objects_are_immutable_and_checked_when_built_in_code():
    obj = SceneObject("b", "box", (1.0, 2.0, 3.0))
    with pytest.raises(AttributeError):
        obj.size = (1.0, 1.0, 1.0)
    for bad in [dict(shape="box", size=(1.0, 2.0)), dict(shape="cylinder", size=(0.1,)),
                dict(shape="sphere", size=(-0.1,)), dict(shape="cone", size=(0.1,)),
                dict(shape="sphere", size=(0.1,), position=(0.0, math.nan, 0.0))]:
        with pytest.raises(SceneError, match="'b'"):
            SceneObject("b", **bad)


def test_to_dict_round_trips_through_yaml():
    scene = scene_from_dict(cell(with_(BOX, rpy=[0.1, 0.2, 0.3]), CYL, SPH))
    again = parse_scene(yaml.safe_dump(scene.to_dict()))
    assert again.names() == scene.names()
    for a, b in zip(scene, again):
        assert (a.shape, a.size, a.position) == (b.shape, b.size, b.position)
        np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-12)


def test_the_example_cell_has_a_table_a_pillar_and_a_shelf():
    scene = load_scene(EXAMPLE)
    assert scene.names() == ["table", "pillar", "shelf"]
    assert [o.shape for o in scene] == ["box", "cylinder", "box"]
