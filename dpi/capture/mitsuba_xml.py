"""Cameras and meshes from Mitsuba scene XML, as in the DPI authors' reference data layout.

The reference captures ship a `scene.xml` (shapes with mesh files, maybe a preview sensor) and
a `camera.xml` holding one `<sensor type="perspective">` per input image. This module reads
both with `xml.etree` (no Mitsuba needed): it expands `$variables` from `<default>` entries,
composes `<transform name="to_world">` chains exactly as Mitsuba does (each child multiplies
on the left), turns the field of view into pixel intrinsics and converts each sensor into a
dpi `Camera` through `dpi.capture.cameras.from_mitsuba_matrix`.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpi.capture.cameras import Camera, from_mitsuba_matrix

SENSOR_TYPES = ("perspective", "thinlens")
MESH_SHAPE_TYPES = ("obj", "ply")
DEFAULT_FILM_SIZE = (768, 576)  # Mitsuba's hdrfilm default (width, height)
DEFAULT_FOCAL_LENGTH_MM = 50.0  # Mitsuba's default when neither fov nor focal_length is given
_VARIABLE = re.compile(r"\$(\w+)")
SENSOR_PROPERTIES = {"fov": "float", "principal_point_offset_x": "float", "principal_point_offset_y": "float",
                     "fov_axis": "string", "focal_length": "string"}
"""the sensor properties dpi reads, with the tag (type) Mitsuba requires"""
FILM_PROPERTIES = {"width": "integer", "height": "integer"}


class MitsubaXMLError(ValueError):
    """A Mitsuba XML file cannot be read or holds something dpi does not support; names the file."""


@dataclass
class XMLShape:
    """A mesh shape of a scene file: its plugin type, resolved mesh path and optional id."""

    type: str
    filename: Path
    id: str


def _parse(path: Path) -> ET.Element:
    """Root element of an XML file with `$variables` replaced by their `<default>` values."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise MitsubaXMLError(f"{path}: not a readable XML file ({exc})") from exc
    defaults = {d.get("name"): d.get("value", "") for d in root.iter("default")}

    def value(match: re.Match) -> str:
        """The default value of one `$name`."""
        if match.group(1) not in defaults:
            raise MitsubaXMLError(f"{path}: variable ${match.group(1)} has no <default> value")
        return defaults[match.group(1)]

    for element in root.iter():
        element.attrib.update({key: _VARIABLE.sub(value, text) for key, text in element.attrib.items()})
    return root


def _numbers(path: Path, text: str, count: int) -> np.ndarray:
    """`count` floats from a space- or comma-separated attribute value."""
    try:
        values = np.array([float(v) for v in text.replace(",", " ").split()], dtype=np.float64)
    except ValueError as exc:
        raise MitsubaXMLError(f"{path}: cannot read numbers from {text!r}") from exc
    if values.size != count or not np.isfinite(values).all():
        raise MitsubaXMLError(f"{path}: expected {count} finite numbers, got {text!r}")
    return values


def _vector(path: Path, element: ET.Element, default: float) -> np.ndarray:
    """A 3-vector given as `value="x y z"` (one number: all three) or x/y/z attributes (missing = default)."""
    if "value" in element.attrib:
        text = element.get("value")
        values = _numbers(path, text, 1 if len(text.replace(",", " ").split()) == 1 else 3)
        return np.full(3, values[0]) if values.size == 1 else values
    try:
        return np.array([float(element.get(axis, default)) for axis in "xyz"])
    except ValueError as exc:
        raise MitsubaXMLError(f"{path}: cannot read <{element.tag}> {dict(element.attrib)}") from exc


def default_up(direction: np.ndarray) -> np.ndarray:
    """Mitsuba's up vector for a <lookat> without one: the first axis of coordinate_system(direction)."""
    x, y, z = direction
    sign = math.copysign(1.0, z)
    a = -1.0 / (sign + z)
    return np.array([1.0 + sign * x * x * a, sign * x * y * a, -sign * x])


def look_at_matrix(origin: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """Mitsuba's look_at to_world: columns (left, up, dir, origin), the camera looking along +Z."""
    direction = target - origin
    direction = direction / np.linalg.norm(direction)
    up = default_up(direction) if up is None else up
    left = np.cross(up, direction)
    if np.linalg.norm(left) < 1e-12:
        raise ValueError("look_at: view direction is parallel to the up vector")
    left /= np.linalg.norm(left)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = left, np.cross(direction, left), direction, origin
    return matrix


def _rotation(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """4x4 rotation by `angle_deg` degrees about a unit `axis` (Rodrigues; like Mitsuba, not normalised)."""
    x, y, z = axis
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    matrix = np.eye(4)
    matrix[:3, :3] = [
        [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
        [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
        [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
    ]
    return matrix


def transform_matrix(path: Path, transform: ET.Element) -> np.ndarray:
    """4x4 matrix of a `<transform>` element; each child multiplies the chain from the left."""
    result = np.eye(4)
    for step in transform:
        if step.tag == "translate":
            matrix = np.eye(4)
            matrix[:3, 3] = _vector(path, step, 0.0)
        elif step.tag == "scale":
            matrix = np.diag([*_vector(path, step, 1.0), 1.0])
        elif step.tag == "rotate":
            axis = _vector(path, step, 0.0)
            if np.linalg.norm(axis) == 0:
                raise MitsubaXMLError(f"{path}: <rotate> without an axis")
            matrix = _rotation(axis, float(step.get("angle", 0.0)))
        elif step.tag == "matrix":
            matrix = _numbers(path, step.get("value", ""), 16).reshape(4, 4)
        elif step.tag == "lookat":
            origin, target = (_numbers(path, step.get(k, ""), 3) for k in ("origin", "target"))
            up = _numbers(path, step.get("up"), 3) if "up" in step.attrib else None
            try:
                matrix = look_at_matrix(origin, target, up)
            except ValueError as exc:
                raise MitsubaXMLError(f"{path}: invalid <lookat>: {exc}") from exc
        else:
            raise MitsubaXMLError(f"{path}: unsupported transform step <{step.tag}>")
        result = matrix @ result
    return result


def _properties(element: ET.Element, tag: str) -> dict[str, str]:
    """name -> value of the direct `<tag name=.. value=..>` children of an element."""
    return {p.get("name"): p.get("value") for p in element.findall(tag)}


def _typed(path: Path, owner: str, element: ET.Element | None, spec: dict[str, str]) -> dict[str, float | int | str]:
    """name -> value of the properties of `element` that `spec` names, each of its type as Mitsuba requires
    (an <integer> where a float is due is a float, as in Mitsuba); anything else is an error naming the file,
    the owner (sensor), the property, its value and the type expected."""
    values: dict[str, float | int | str] = {}
    for child in [] if element is None else element:
        name, text = child.get("name"), child.get("value", "")
        if name not in spec:
            continue
        expected = spec[name]
        wanted = f"{'an' if expected == 'integer' else 'a'} {expected}"
        shown = f'<{child.tag} name="{name}" value="{text}"/>'
        if child.tag != expected and (expected, child.tag) != ("float", "integer"):
            raise MitsubaXMLError(f"{path}: {owner}: {name} must be {wanted} (<{expected}>), got {shown}")
        try:
            values[name] = {"float": float, "integer": int, "string": str}[expected](text)
        except ValueError as exc:
            raise MitsubaXMLError(f"{path}: {owner}: {name} must be {wanted}, got {shown}") from exc
        if expected == "float" and not math.isfinite(values[name]):
            raise MitsubaXMLError(f"{path}: {owner}: {name} must be a finite number, got {shown}")
    return values


def x_fov_deg(path: Path, properties: dict, width: int, height: int) -> float:
    """Horizontal field of view of a sensor (its `_typed` properties), following Mitsuba's fov / fov_axis /
    focal_length rules."""
    aspect = width / height
    if "fov" in properties:
        fov = properties["fov"]
        axis = properties.get("fov_axis", "x").lower()
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
    else:
        focal = properties.get("focal_length", f"{DEFAULT_FOCAL_LENGTH_MM}mm").strip().removesuffix("mm")
        try:
            fov = math.degrees(2 * math.atan(math.hypot(36.0, 24.0) / (2 * float(focal))))
        except ValueError as exc:
            raise MitsubaXMLError(f"{path}: cannot read focal_length {focal!r}") from exc
        axis = "diagonal"
    if not 0 < fov < 180:
        raise MitsubaXMLError(f"{path}: field of view {fov} is not in (0, 180) degrees")
    half_tan = math.tan(math.radians(fov) / 2)
    if axis == "x":
        return fov
    if axis == "y":
        return math.degrees(2 * math.atan(half_tan * aspect))
    if axis == "diagonal":
        return math.degrees(2 * math.atan(half_tan / math.sqrt(1 + 1 / aspect**2)))
    raise MitsubaXMLError(f"{path}: unsupported fov_axis {axis!r}")


def sensor_camera(path: Path, sensor: ET.Element, name: str = "") -> Camera:
    """dpi Camera (OpenGL c2w, pixel intrinsics) of one `<sensor>` element."""
    sizes = _typed(path, f"sensor {name!r} film", sensor.find("film"), FILM_PROPERTIES)
    width, height = sizes.get("width", DEFAULT_FILM_SIZE[0]), sizes.get("height", DEFAULT_FILM_SIZE[1])
    properties = _typed(path, f"sensor {name!r}", sensor, SENSOR_PROPERTIES)
    transform = sensor.find("transform[@name='to_world']")
    to_world = np.eye(4) if transform is None else transform_matrix(path, transform)
    if not np.allclose(np.linalg.norm(to_world[:3, :3], axis=0), 1.0, atol=1e-3):
        raise MitsubaXMLError(f"{path}: sensor {name!r} has scale factors in its to_world transform "
                              f"(Mitsuba does not allow them)")
    fx = width / (2 * math.tan(math.radians(x_fov_deg(path, properties, width, height)) / 2))
    # Mitsuba shifts the film window by offset * size, which moves the principal point the other way.
    cx = width / 2 - properties.get("principal_point_offset_x", 0.0) * width
    cy = height / 2 - properties.get("principal_point_offset_y", 0.0) * height
    return Camera(from_mitsuba_matrix(to_world), width, height, fx, fx, cx, cy, name)


def read_sensors(path: str | os.PathLike) -> list[Camera]:
    """Cameras of all perspective sensors of an XML file, in file order."""
    path = Path(path)
    cameras = []
    for i, sensor in enumerate(_parse(path).iter("sensor")):
        kind = sensor.get("type", "")
        if kind not in SENSOR_TYPES:
            raise MitsubaXMLError(f"{path}: sensor {i} has unsupported type {kind!r} (use perspective)")
        try:
            cameras.append(sensor_camera(path, sensor, sensor.get("id", f"sensor_{i}")))
        except MitsubaXMLError:
            raise
        except ValueError as exc:
            raise MitsubaXMLError(f"{path}: sensor {i}: {exc}") from exc
    return cameras


def read_mesh_shapes(path: str | os.PathLike) -> list[XMLShape]:
    """obj/ply shapes of an XML file with their mesh paths resolved relative to the file."""
    path = Path(path)
    shapes = []
    for i, shape in enumerate(_parse(path).iter("shape")):
        kind = shape.get("type", "")
        if kind not in MESH_SHAPE_TYPES:
            continue
        filename = _properties(shape, "string").get("filename")
        if not filename:
            raise MitsubaXMLError(f"{path}: {kind} shape {i} has no filename")
        shapes.append(XMLShape(kind, (path.parent / filename).resolve(), shape.get("id", "")))
    return shapes
