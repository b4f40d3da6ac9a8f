"""Capture folder loading and validation: valid captures, one test per error, JSON round trip."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
from capture_helpers import NAMES, SIZE, cameras, edit_transforms, garbage, image, make_capture, raw_exr

from dpi.capture import Capture, CaptureError, inspect_capture, load_capture, read_capture_json, write_capture_json
from dpi.capture.cameras import look_at
from dpi.io.exr import write_exr
from dpi.io.images import write_mask, write_srgb


@pytest.fixture
def capture_root(tmp_path: Path) -> Path:
    """A complete valid capture folder."""
    return make_capture(tmp_path / "scene")


def write_mitsuba_uv_ply(path: Path) -> None:
    """A one-triangle PLY with per-vertex UVs, written by Mitsuba."""
    from dpi.render.backend import mitsuba

    mi = mitsuba()
    mesh = mi.Mesh("uv_triangle", 3, 1, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], np.float32))
    params["faces"] = mi.UInt32(np.array([0, 1, 2], np.uint32))
    params["vertex_texcoords"] = mi.Float(np.array([0, 0, 1, 0, 0, 1], np.float32))
    params.update()
    mesh.write_ply(str(path))


# --- valid captures -------------------------------------------------------------------------


def test_full_capture_loads_views_split_and_provenance(capture_root):
    """Every input given: views in order, frame flag holds r_3 out, everything is 'given'."""
    capture = load_capture(capture_root)
    assert [v.name for v in capture.views] == list(NAMES)
    assert [v.image.suffix for v in capture.views] == [".png", ".png", ".exr", ".exr"]
    assert [v.name for v in capture.train_views] == ["r_0", "r_1", "r_2"]
    assert [v.name for v in capture.held_out_views] == ["r_3"]
    assert capture.provenance == {"cameras": "given", "masks": "given", "mesh": "given", "uv": "derived"}
    assert capture.image_size == (SIZE, SIZE)
    assert capture.mesh == capture_root.resolve() / "mesh.ply" and not capture.mesh_has_uv
    assert set(capture.gt) == {"envmap", "albedo"}
    for view, camera in zip(capture.views, cameras()):
        assert view.mask == capture_root.resolve() / "masks" / f"{view.name}.png"
        np.testing.assert_array_equal(view.camera.c2w, camera.c2w)
        assert view.camera.name == view.name


def test_images_only_capture_derives_everything(tmp_path):
    """A folder with only images loads, and every other input is marked 'derived'."""
    capture = load_capture(make_capture(tmp_path / "s", transforms=False, masks=False, mesh=False, gt=False))
    assert capture.provenance == dict.fromkeys(("cameras", "masks", "mesh", "uv"), "derived")
    assert all(v.camera is None and v.mask is None and not v.held_out for v in capture.views)
    assert capture.mesh is None and capture.gt == {} and capture.options == {}


def test_scene_yaml_held_out_overrides_frame_flags(capture_root):
    """scene.yaml's held_out list wins over transforms.json flags; options are kept."""
    (capture_root / "scene.yaml").write_text("prior: indoor\nheld_out: [r_0, r_1]\nradiance_scale: 2.5\n")
    capture = load_capture(capture_root)
    assert [v.name for v in capture.held_out_views] == ["r_0", "r_1"]
    assert capture.options == {"prior": "indoor", "held_out": ["r_0", "r_1"], "radiance_scale": 2.5}


def test_nerf_synthetic_intrinsics_use_the_image_size(capture_root):
    """camera_angle_x alone (NeRF-synthetic) gives intrinsics for the actual image size."""
    def to_synthetic(data: dict) -> None:
        for frame in data["frames"]:
            for key in ("w", "h", "fl_x", "fl_y", "cx", "cy"):
                frame.pop(key)
        data["camera_angle_x"] = np.radians(40.0)
    edit_transforms(capture_root, to_synthetic)
    view = load_capture(capture_root).views[0]
    assert (view.camera.width, view.camera.height) == (SIZE, SIZE)
    assert view.camera.fov_x_deg == pytest.approx(40.0)


def test_exr_wins_over_ldr_copy_of_the_same_view(capture_root):
    """The reference data ships 0.exr and 0.png; the linear EXR is the input."""
    write_srgb(capture_root / "images" / "r_2.png", image())
    assert load_capture(capture_root).views[2].image.name == "r_2.exr"


def test_ply_with_uvs_written_by_mitsuba_is_detected(tmp_path):
    """Vertex s/t properties in a PLY header mean the mesh has UVs (no masks: a triangle is not the sphere they show)."""
    root = make_capture(tmp_path / "scene", masks=False)
    write_mitsuba_uv_ply(root / "mesh.ply")
    capture = load_capture(root)
    assert capture.mesh_has_uv and capture.provenance["uv"] == "given"
    assert inspect_capture(root)["mesh_has_uv"]


def test_obj_with_texture_coordinates_is_detected(tmp_path):
    """`vt` lines in an OBJ mean the mesh has UVs (no masks: a triangle is not the sphere they show)."""
    root = make_capture(tmp_path / "s", mesh=False, masks=False)
    (root / "mesh.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    assert load_capture(root).mesh_has_uv and inspect_capture(root)["mesh_has_uv"]


def write_reference_layout(root: Path, names: list[str]) -> list[np.ndarray]:
    """Authors' layout: images, camera.xml (look-at sensors), scene.xml with meshes/object.obj."""
    (root / "images").mkdir(parents=True)
    for name in names:
        write_exr(root / "images" / f"{name}.exr", image())
    origins = [(3.0 * np.sin(a), 1.0, 3.0 * np.cos(a)) for a in np.linspace(0, 2, len(names))]
    sensors = "".join(
        f'<sensor type="perspective"><float name="fov" value="40"/><transform name="to_world">'
        f'<lookat origin="{o[0]}, {o[1]}, {o[2]}" target="0, 0, 0" up="0, 1, 0"/></transform>'
        f'<film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/></film>'
        f'</sensor>' for o in origins)
    (root / "camera.xml").write_text(f'<scene version="2.1.0"><default name="res" value="16"/>{sensors}</scene>')
    (root / "meshes").mkdir()
    trimesh.creation.icosphere(subdivisions=1).export(root / "meshes" / "object.obj")
    (root / "scene.xml").write_text('<scene version="3.0.0"><shape type="obj">'
                                    '<string name="filename" value="meshes/object.obj"/></shape></scene>')
    return [look_at(o, (0, 0, 0)) for o in origins]


def test_reference_layout_cameras_and_mesh_come_from_xml(tmp_path):
    """camera.xml sensors match images in natural order; scene.xml gives the mesh; intrinsics rescale."""
    names = ["0", "1", "2", "10"]
    expected = write_reference_layout(tmp_path / "s", names)
    capture = load_capture(tmp_path / "s")
    assert [v.name for v in capture.views] == names
    assert capture.provenance == {"cameras": "given", "masks": "derived", "mesh": "given", "uv": "derived"}
    assert capture.mesh == (tmp_path / "s" / "meshes" / "object.obj").resolve()
    for view, c2w in zip(capture.views, expected):
        np.testing.assert_allclose(view.camera.c2w, c2w, atol=1e-9)
        assert (view.camera.width, view.camera.height) == (SIZE, SIZE)
        assert view.camera.fov_x_deg == pytest.approx(40.0)


def test_json_round_trip_is_exact(capture_root, tmp_path):
    """to_json -> JSON file -> from_json gives back the same capture, cameras included."""
    capture = load_capture(capture_root)
    write_capture_json(capture, tmp_path / "capture.json")
    again = read_capture_json(tmp_path / "capture.json")
    assert isinstance(again, Capture) and again.to_json() == capture.to_json()
    assert again.image_size == capture.image_size and again.root == capture.root
    for a, b in zip(again.views, capture.views):
        assert (a.name, a.image, a.mask, a.held_out) == (b.name, b.image, b.mask, b.held_out)
        np.testing.assert_array_equal(a.camera.c2w, b.camera.c2w)
        assert (a.camera.fx, a.camera.cy, a.camera.extras) == (b.camera.fx, b.camera.cy, b.camera.extras)
    assert Path(capture.to_json()["views"][0]["image"]).is_absolute()


@pytest.mark.parametrize("parts", [
    dict(),
    dict(transforms=False, masks=False, mesh=False, gt=False),
    dict(transforms=True, masks=False, mesh=False),
    dict(transforms=False, masks=True, mesh=True),
])
def test_inspect_agrees_with_load(tmp_path, parts):
    """The cheap inspection reports exactly what full loading marks as given."""
    root = make_capture(tmp_path / "s", **parts)
    given = {k: v == "given" for k, v in load_capture(root).provenance.items()}
    assert inspect_capture(root) == {"cameras": given["cameras"], "masks": given["masks"],
                                     "mesh": given["mesh"], "mesh_has_uv": given["uv"]}


def test_inspect_agrees_with_load_on_reference_layout(tmp_path):
    """scene.xml / camera.xml count as given cameras and mesh for the cheap inspection too."""
    write_reference_layout(tmp_path / "s", ["a", "b"])
    assert inspect_capture(tmp_path / "s") == {"cameras": True, "masks": False, "mesh": True, "mesh_has_uv": False}


# --- one CaptureError per problem -----------------------------------------------------------


def _drop_frame(data: dict) -> None:
    """Remove the last frame."""
    data["frames"].pop()


def _rename_frame(data: dict) -> None:
    """Point a frame at an image that does not exist."""
    data["frames"][1]["file_path"] = "images/r_9.png"


def _nan_matrix(data: dict) -> None:
    """Put a NaN into a camera matrix."""
    data["frames"][0]["transform_matrix"][0][3] = float("nan")


def _no_focal(data: dict) -> None:
    """Drop the focal length of a frame."""
    data["frames"][2].pop("fl_x")
    data["frames"][2].pop("fl_y")


def _no_frames(data: dict) -> None:
    """Drop the frames list."""
    data.pop("frames")


def _mask_of_size(root: Path, height: int, width: int, value: bool) -> None:
    """Replace r_1's mask."""
    write_mask(root / "masks" / "r_1.png", np.full((height, width), value))


def _point_cloud_ply(path: Path) -> None:
    """A PLY with vertices and no faces."""
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n")


ERRORS = {
    "missing images folder": (lambda r: shutil.rmtree(r / "images"), "images", "missing"),
    "empty images folder": (lambda r: [p.unlink() for p in (r / "images").iterdir()], "images", "empty"),
    "unsupported suffix": (lambda r: garbage(r / "images" / "r_4.tiff"), "r_4.tiff", "unsupported"),
    "unreadable image": (lambda r: garbage(r / "images" / "r_0.png"), "r_0.png", "readable"),
    "unreadable exr": (lambda r: garbage(r / "images" / "r_2.exr"), "r_2.exr", "readable"),
    "nan in image": (lambda r: raw_exr(r / "images" / "r_2.exr", image() * np.nan), "r_2.exr", "NaN"),
    "inf in image": (lambda r: raw_exr(r / "images" / "r_3.exr", image() + np.inf), "r_3.exr", "Inf"),
    "negative image": (lambda r: raw_exr(r / "images" / "r_3.exr", image() - 1), "r_3.exr", "negative"),
    "image sizes differ": (lambda r: write_srgb(r / "images" / "r_1.png", image(height=12)), "r_1.png", "size"),
    "unreadable transforms": (lambda r: (r / "transforms.json").write_text("{frames: "), "transforms.json", "JSON"),
    "no frames": (lambda r: edit_transforms(r, _no_frames), "transforms.json", "frames"),
    "camera count": (lambda r: edit_transforms(r, _drop_frame), "transforms.json", "count"),
    "frame without image": (lambda r: edit_transforms(r, _rename_frame), "transforms.json", "r_9.png"),
    "image without frame": (lambda r: write_srgb(r / "images" / "r_4.png", image()), "transforms.json",
                            "images without frame: ['r_4']"),
    "non-finite matrix": (lambda r: edit_transforms(r, _nan_matrix), "transforms.json", "finite"),
    "missing intrinsics": (lambda r: edit_transforms(r, _no_focal), "transforms.json", "intrinsics"),
    "missing mask": (lambda r: (r / "masks" / "r_2.png").unlink(), "masks", "missing mask for image r_2"),
    "mask without image": (lambda r: write_mask(r / "masks" / "r_7.png", np.ones((8, 8), bool)), "r_7.png",
                           "no matching image"),
    "mask size": (lambda r: _mask_of_size(r, 6, 8, True), "r_1.png", "size"),
    "empty mask": (lambda r: _mask_of_size(r, 8, 8, False), "r_1.png", "empty"),
    "unreadable mask": (lambda r: garbage(r / "masks" / "r_0.png"), "r_0.png", "readable"),
    "unreadable mesh": (lambda r: garbage(r / "mesh.ply"), "mesh.ply", "unreadable"),
    "mesh without faces": (lambda r: _point_cloud_ply(r / "mesh.ply"), "mesh.ply", "no faces"),
    "two meshes": (lambda r: shutil.copy(r / "mesh.ply", r / "mesh.obj"), "mesh.obj", "ambiguous"),
    "unreadable gt": (lambda r: garbage(r / "gt" / "albedo.exr"), "albedo.exr", "readable"),
    "nan in gt": (lambda r: raw_exr(r / "gt" / "roughness.exr", image() * np.nan), "roughness.exr", "NaN"),
    "envmap shape": (lambda r: write_exr(r / "gt" / "envmap.exr", np.ones((4, 12, 3))), "envmap.exr",
                     "not an equirectangular"),
    "invalid yaml": (lambda r: (r / "scene.yaml").write_text("prior: [indoor\n"), "scene.yaml", "YAML"),
    "yaml not a mapping": (lambda r: (r / "scene.yaml").write_text("- a\n- b\n"), "scene.yaml", "mapping"),
    "unknown yaml key": (lambda r: (r / "scene.yaml").write_text("prior: indoor\nlight: 3\n"), "scene.yaml",
                         "unknown keys: light"),
    "bad prior": (lambda r: (r / "scene.yaml").write_text("prior: studio\n"), "scene.yaml", "prior"),
    "bad scale": (lambda r: (r / "scene.yaml").write_text("radiance_scale: -1\n"), "scene.yaml", "radiance_scale"),
    "held out unknown view": (lambda r: (r / "scene.yaml").write_text("held_out: [r_9]\n"), "scene.yaml", "r_9"),
    "all held out": (lambda r: (r / "scene.yaml").write_text(f"held_out: {list(NAMES)}\n"), "scene.yaml",
                     "none is left"),
}


@pytest.mark.parametrize("case", list(ERRORS))
def test_each_problem_raises_one_error_naming_the_file(capture_root, case):
    """A broken capture stops with a CaptureError that starts with the file and says the problem."""
    break_capture, file_name, keyword = ERRORS[case]
    break_capture(capture_root)
    with pytest.raises(CaptureError) as info:
        load_capture(capture_root)
    message = str(info.value)
    assert message.split(":")[0].endswith(file_name), message
    assert keyword in message, message


def test_missing_capture_folder(tmp_path):
    """A capture folder that does not exist is named in the error, by load and by inspect."""
    for check in (load_capture, inspect_capture):
        with pytest.raises(CaptureError, match=r"nowhere: capture folder does not exist"):
            check(tmp_path / "nowhere")


def test_xml_camera_count_must_match_images(tmp_path):
    """camera.xml with fewer sensors than images is an error naming camera.xml."""
    root = tmp_path / "s"
    write_reference_layout(root, ["a", "b"])
    write_exr(root / "images" / "c.exr", image())
    with pytest.raises(CaptureError, match=r"camera\.xml: camera count 2 != image count 3"):
        load_capture(root)


def test_unreadable_scene_xml_is_named(tmp_path):
    """A malformed scene.xml stops loading (and inspection) with its name."""
    root = tmp_path / "s"
    write_reference_layout(root, ["a", "b"])
    (root / "scene.xml").write_text("<scene><shape>")
    for check in (load_capture, inspect_capture):
        with pytest.raises(CaptureError, match=r"scene\.xml: not a readable XML"):
            check(root)


def test_scene_yaml_object_picks_one_of_several_xml_shapes(tmp_path):
    """With several mesh shapes in scene.xml, `object` names the one to use; without it, an error."""
    root = tmp_path / "s"
    write_reference_layout(root, ["a", "b"])
    shutil.copy(root / "meshes" / "object.obj", root / "meshes" / "floor.obj")
    (root / "scene.xml").write_text(
        '<scene version="3.0.0"><shape type="obj" id="floor"><string name="filename" value="meshes/floor.obj"/>'
        '</shape><shape type="obj"><string name="filename" value="meshes/object.obj"/></shape></scene>')
    with pytest.raises(CaptureError, match=r"scene\.xml: 2 mesh shapes"):
        load_capture(root)
    (root / "scene.yaml").write_text("object: object\n")
    assert load_capture(root).mesh == (root / "meshes" / "object.obj").resolve()
