"""The DPI authors' reference layout: cameras from camera.xml (or scene.xml) sensors, matched in file order to the
images."""

from __future__ import annotations

from pathlib import Path

from dpi.capture.cameras import Camera
from dpi.capture.mitsuba_xml import MitsubaXMLError, read_sensors
from dpi.capture.model import CaptureError, inside_capture
from dpi.capture.transforms import fit_camera


def camera_xml(root: Path) -> Path | None:
    """The Mitsuba XML that holds the cameras: camera.xml, else scene.xml when it has sensors."""
    for name in ("camera.xml", "scene.xml"):
        path = root / name
        if path.is_file() and (name == "camera.xml" or xml_sensors(path)):
            return path
    return None


def xml_sensors(path: Path) -> list[Camera]:
    """Cameras of a Mitsuba XML file, as CaptureError on failure."""
    inside_capture(path.parent, path, "the camera file")
    try:
        return read_sensors(path)
    except MitsubaXMLError as exc:
        raise CaptureError(str(exc)) from exc


def xml_cameras(path: Path, names: list[str], size: tuple[int, int]) -> dict[str, Camera]:
    """view name -> camera from the sensors of a Mitsuba XML, matched in file order to the sorted images."""
    cameras = xml_sensors(path)
    if len(cameras) != len(names):
        raise CaptureError(f"{path}: camera count {len(cameras)} != image count {len(names)} "
                           f"(sensors are matched to images in sorted order)")
    return {n: fit_camera(path, c, size, n) for n, c in zip(names, cameras)}
