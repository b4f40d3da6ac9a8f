"""The capture folder: one validation pass that turns raw inputs into one normalised `Capture`.

A capture folder holds `images/` (required) and optionally `transforms.json`, `masks/`, a mesh, `scene.xml` +
`camera.xml` (the DPI authors' reference layout), `gt/` and `scene.yaml`; one parser module reads each format.
`load_capture` reads and checks everything once and stops at the first problem with one `CaptureError` whose
message starts with the offending file; stages downstream only see the resulting `Capture` (capture.json).
"""

from dpi.capture.folder import read_ground_truth
from dpi.capture.load import (camera_fit_problem, capture_warnings, complete_capture, derived_inputs, inspect_capture,
                              load_capture)
from dpi.capture.meshes import GLTF_SUFFIXES, mesh_has_uv
from dpi.capture.model import (Capture, CaptureError, CaptureWarning, View, camera_from_json, camera_to_json,
                               read_capture_json, write_capture_json)
from dpi.capture.scene_yaml import PRIORS, read_scene_options

__all__ = ["GLTF_SUFFIXES", "PRIORS", "Capture", "CaptureError", "CaptureWarning", "View", "camera_fit_problem",
           "camera_from_json", "camera_to_json", "capture_warnings", "complete_capture", "derived_inputs",
           "inspect_capture", "load_capture", "mesh_has_uv", "read_capture_json", "read_ground_truth",
           "read_scene_options", "write_capture_json"]
