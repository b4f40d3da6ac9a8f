"""Mitsuba XML cameras and shapes: agreement with Mitsuba's own parser and with dpi.capture.cameras."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from dpi.capture.cameras import from_mitsuba_matrix, look_at
from dpi.capture.mitsuba_xml import MitsubaXMLError, read_mesh_shapes, read_sensors, transform_matrix

LOOKATS = [((0.0, 0.5, 4.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
           ((-1.2, 0.5, 1.2), (0.4, 0.45, 0.5), (0.0, 1.0, 0.0)),
           ((3.0, -2.0, 1.0), (0.1, 0.2, -0.3), (0.0, 0.0, 1.0))]


@pytest.fixture(scope="module")
def mi():
    """Mitsuba with dpi's variant choice (imported once per module: it takes seconds)."""
    from dpi.render.backend import mitsuba

    return mitsuba()


def sensor_xml(transform: str, extra: str = "", width: str = "32", height: str = "24") -> str:
    """One perspective sensor element with the given to_world body and extra properties."""
    return (f'<sensor type="perspective">{extra}<transform name="to_world">{transform}</transform>'
            f'<film type="hdrfilm"><integer name="width" value="{width}"/>'
            f'<integer name="height" value="{height}"/></film></sensor>')


def lookat_xml(origin, target, up) -> str:
    """A <lookat> element with comma-separated vectors, as in the authors' files."""
    return (f'<lookat origin="{", ".join(map(str, origin))}" target="{", ".join(map(str, target))}" '
            f'up="{", ".join(map(str, up))}"/>')


def write_scene(path: Path, body: str, defaults: str = "") -> Path:
    """Write a <scene> file with optional <default> entries."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f'<scene version="3.0.0">{defaults}{body}</scene>')
    return path


def mitsuba_matrix(mi, sensor) -> np.ndarray:
    """A loaded Mitsuba sensor's to_world as a float64 (4, 4) array."""
    return np.asarray(mi.traverse(sensor)["to_world"].matrix, dtype=np.float64).reshape(4, 4)


def test_lookat_cameras_round_trip_to_known_c2w(tmp_path, mi):
    """camera.xml written from known look-at cameras reads back to dpi's and Mitsuba's c2w."""
    body = "".join(sensor_xml(lookat_xml(*args), '<float name="fov" value="39"/>') for args in LOOKATS)
    cameras = read_sensors(write_scene(tmp_path / "camera.xml", body))
    assert len(cameras) == len(LOOKATS)
    for camera, (origin, target, up) in zip(cameras, LOOKATS):
        sensor = mi.load_dict({"type": "perspective", "fov": 39.0,
                               "to_world": mi.ScalarTransform4f().look_at(origin=origin, target=target, up=up)})
        np.testing.assert_allclose(camera.c2w, look_at(origin, target, up), atol=1e-6)
        np.testing.assert_allclose(camera.c2w, from_mitsuba_matrix(mitsuba_matrix(mi, sensor)), atol=1e-6)
        assert (camera.width, camera.height) == (32, 24)
        assert camera.fov_x_deg == pytest.approx(39.0)


@pytest.mark.parametrize("transform", [
    '<rotate x="1" angle="-150"/><rotate y="1" angle="-6"/><rotate z="1" angle="-180"/>'
    '<translate value="0.362097 2.000000 3.445125"/>',
    '<matrix value="0 0 1 1  0 1 0 2  -1 0 0 3  0 0 0 1"/><scale x="-1"/><rotate value="0 1 0" angle="30"/>',
    lookat_xml(*LOOKATS[1]) + '<translate value="0, 1, 0"/>',
    '<lookat origin="1 2 3" target="0 0 0"/>',
])
def test_sensor_transform_chains_match_mitsuba(tmp_path, mi, transform):
    """Sensor to_world chains compose exactly as Mitsuba's XML parser does."""
    xml = sensor_xml(transform, '<float name="fov" value="40"/>')
    (camera,) = read_sensors(write_scene(tmp_path / "camera.xml", xml))
    expected = mitsuba_matrix(mi, mi.load_string(xml.replace("<sensor ", '<sensor version="3.0.0" ', 1)))
    np.testing.assert_allclose(camera.c2w, from_mitsuba_matrix(expected), atol=1e-6)


def test_scale_steps_match_mitsuba(tmp_path, mi):
    """Non-uniform and uniform scales (allowed on shapes) compose as in Mitsuba."""
    chain = '<scale x="2"/><rotate value="0 1 1" angle="30"/><translate x="1" z="-2"/><scale value="0.5"/>'
    xml = f'<shape type="rectangle"><transform name="to_world">{chain}</transform></shape>'
    shape = mi.load_string(xml.replace("<shape ", '<shape version="3.0.0" ', 1))
    ours = transform_matrix(tmp_path, ET.fromstring(xml).find("transform"))
    np.testing.assert_allclose(ours, mitsuba_matrix(mi, shape), atol=1e-6)


def test_scaled_sensor_is_an_error(tmp_path):
    """Mitsuba refuses scale factors in a camera transform, and so does the reader."""
    path = write_scene(tmp_path / "camera.xml", sensor_xml('<scale value="2"/>', '<float name="fov" value="40"/>'))
    with pytest.raises(MitsubaXMLError, match=r"camera\.xml.*scale"):
        read_sensors(path)


@pytest.mark.parametrize("fov", [
    '<float name="fov" value="30"/><string name="fov_axis" value="y"/>',
    '<float name="fov" value="50"/><string name="fov_axis" value="diagonal"/>',
    '<float name="fov" value="35"/><string name="fov_axis" value="smaller"/>',
    '<float name="fov" value="35"/><string name="fov_axis" value="larger"/>',
    '<string name="focal_length" value="35mm"/>',
])
def test_field_of_view_rules_match_mitsuba(tmp_path, mi, fov):
    """fov_axis and focal_length give Mitsuba's horizontal field of view."""
    xml = sensor_xml("", fov)
    (camera,) = read_sensors(write_scene(tmp_path / "camera.xml", xml))
    sensor = mi.load_string(xml.replace("<sensor ", '<sensor version="3.0.0" ', 1))
    assert camera.fov_x_deg == pytest.approx(float(np.ravel(mi.traverse(sensor)["x_fov"])[0]), abs=1e-4)


def test_principal_point_offset_matches_mitsuba_rays(tmp_path, mi):
    """A ray Mitsuba traces through a film position projects back onto that pixel."""
    extra = ('<float name="fov" value="40"/><float name="principal_point_offset_x" value="0.1"/>'
             '<float name="principal_point_offset_y" value="-0.2"/>')
    xml = sensor_xml(lookat_xml(*LOOKATS[0]), extra, width="64", height="32")
    (camera,) = read_sensors(write_scene(tmp_path / "camera.xml", xml))
    sensor = mi.load_string(xml.replace("<sensor ", '<sensor version="3.0.0" ', 1))
    for u, v in [(0.5, 0.5), (0.2, 0.7), (0.9, 0.1)]:
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(u, v), mi.Point2f(0.5, 0.5))
        point = np.ravel(np.asarray(ray.o, dtype=np.float64)) + np.ravel(np.asarray(ray.d, dtype=np.float64))
        pixel, depth = camera.project(point[None])
        np.testing.assert_allclose(pixel[0], [u * 64, v * 32], atol=1e-3)
        assert depth[0] > 0


def test_variables_take_their_default_values(tmp_path):
    """$resx/$resy resolve through <default> entries, as in the authors' camera.xml."""
    defaults = '<default name="resx" value="40"/><default name="resy" value="20"/>'
    sensor = sensor_xml(lookat_xml(*LOOKATS[0]), '<float name="fov" value="39"/>', "$resx", "$resy")
    path = write_scene(tmp_path / "camera.xml", sensor, defaults)
    (camera,) = read_sensors(path)
    assert (camera.width, camera.height) == (40, 20)


def test_undefined_variable_names_file_and_variable(tmp_path):
    """A $variable without <default> is an error naming the file and the variable."""
    path = write_scene(tmp_path / "camera.xml", sensor_xml("", "", "$resx", "24"))
    with pytest.raises(MitsubaXMLError, match=r"camera\.xml.*\$resx"):
        read_sensors(path)


def test_unreadable_xml_names_file(tmp_path):
    """Malformed XML is an error naming the file."""
    path = tmp_path / "camera.xml"
    path.write_text("<scene><sensor></scene>")
    with pytest.raises(MitsubaXMLError, match=r"camera\.xml.*XML"):
        read_sensors(path)


def test_unsupported_sensor_type_is_an_error(tmp_path):
    """Only perspective (pinhole) sensors become cameras."""
    path = write_scene(tmp_path / "camera.xml", '<sensor type="orthographic"/>')
    with pytest.raises(MitsubaXMLError, match="orthographic"):
        read_sensors(path)


def test_mesh_paths_resolve_relative_to_the_xml_file(tmp_path):
    """Shape filenames are relative to the scene file's folder; non-mesh shapes are skipped."""
    body = ('<default name="name" value="hotdog"/><shape type="sphere"/>'
            '<shape type="obj" id="food"><string name="filename" value="meshes/$name.obj"/></shape>')
    path = write_scene(tmp_path / "data" / "scene.xml", body)
    (shape,) = read_mesh_shapes(path)
    assert shape.filename == (tmp_path / "data" / "meshes" / "hotdog.obj").resolve()
    assert (shape.type, shape.id) == ("obj", "food")
