"""Foreground masks: colour keying on a plain background, GrabCut from the sphere and sparse-point
hull prior on a textured one, consensus rounds from the views' visual hull, outlier points, the
hull's projection, the clean-up (largest part, small holes), the masks' witnesses (points, edges, other views) and
a segmenter the user brings."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.capture.cameras import from_fov, orbit, pixel_rays
from dpi.capture.consistency import mask_iou
from dpi.io.images import read_mask, srgb_to_linear
from dpi.preprocess.hull import visible_sphere
from dpi.preprocess.masks import (SPHERE_FRACTION, MaskConfig, clean_mask, derive_masks, drop_outliers,
                                  mesh_silhouette, object_mask, refine_masks)
from dpi.synth.backdrop import backdrop_texture

SIZE = 64


def sphere_view(camera, background: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Linear image and true mask of a textured unit sphere at the origin seen by `camera`."""
    origins, dirs = pixel_rays(camera)
    o, d = origins[:, :, 0], dirs[:, :, 0]
    b = (o * d).sum(-1)
    disc = b * b - ((o * o).sum(-1) - 1.0)
    mask = disc > 0
    t = -b - np.sqrt(np.maximum(disc, 0))
    p = o + t[..., None] * d
    shade = 0.35 + 0.65 * np.clip(p @ np.array([0.3, 0.8, 0.5]), 0, 1)
    checker = (np.sin(6 * p[..., 0]) * np.sin(6 * p[..., 1] + 1) > 0)[..., None]
    albedo = np.where(checker, [0.95, 0.45, 0.2], [0.85, 0.75, 0.3])
    if background == "plain":
        back = np.full((camera.height, camera.width, 3), 0.5)
    else:
        yy, xx = np.mgrid[: camera.height, : camera.width]
        back = backdrop_texture(xx / 5.0 + 7 * seed, yy / 5.0, seed=seed) * 0.8
    image = np.where(mask[..., None], albedo * shade[..., None], back)
    return srgb_to_linear(np.clip(image, 0, 1)), mask


@pytest.fixture(scope="module")
def cameras():
    return [from_fov(c2w, SIZE, SIZE, 40.0, f"v{i}") for i, c2w in enumerate(orbit(12, 4.0, (10.0, 35.0)))]


@pytest.fixture(scope="module")
def sphere(cameras):
    centre, radius = visible_sphere(cameras)
    return centre, SPHERE_FRACTION * radius


def surface_points(count: int = 200, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(count, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_uniform_background_is_keyed(cameras, sphere):
    image, truth = sphere_view(cameras[0], "plain")
    mask, method = object_mask(image, cameras[0], MaskConfig(), sphere, surface_points())
    assert method == "key"
    assert mask_iou(mask, truth) > 0.97


def test_textured_background_uses_grabcut_from_the_sphere_and_points_hull(cameras, sphere):
    ious = []
    for i, cam in enumerate(cameras[:4]):
        image, truth = sphere_view(cam, "textured", seed=i)
        mask, method = object_mask(image, cam, MaskConfig(), sphere, surface_points(60, seed=i))
        assert method == "grabcut"
        ious.append(mask_iou(mask, truth))
    assert np.mean(ious) > 0.95, ious


def test_stray_points_do_not_become_foreground(cameras, sphere):
    image, truth = sphere_view(cameras[1], "textured", seed=1)
    points = np.concatenate([surface_points(60), [[2.5, 2.0, 0.0]]])  # one far-off point widens the hull
    mask, _ = object_mask(image, cameras[1], MaskConfig(), sphere, points)
    assert mask_iou(mask, truth) > 0.9


def test_outlier_points_are_dropped():
    points = np.concatenate([surface_points(60), [[2.5, 2.0, 0.0]]])
    kept = drop_outliers(points, 2.0)
    assert len(kept) >= 55 and not (np.linalg.norm(kept, axis=1) > 1.5).any()
    assert len(drop_outliers(points, 0.0)) == len(points)


def test_mesh_silhouette_matches_the_true_outline(cameras):
    import trimesh

    icosphere = trimesh.creation.icosphere(subdivisions=5)
    for cam in cameras[:3]:
        outline = mesh_silhouette(cam, np.asarray(icosphere.vertices), np.asarray(icosphere.faces))
        assert mask_iou(outline, sphere_view(cam, "plain")[1]) > 0.97


def test_consensus_round_removes_one_views_background_patch(cameras):
    images, truths = zip(*(sphere_view(cam, "textured", seed=i) for i, cam in enumerate(cameras)))
    masks = [t.copy() for t in truths]
    masks[2][:28, :28] = True  # a patch of background taken for the object (joined to it below)
    masks[2][20:40, 15:25] = True
    from dpi.io.images import to_uint8

    refined, methods = refine_masks([to_uint8(im) for im in images], list(cameras), masks, rounds=((0.25, 0.08),),
                                    resolution=48)
    assert mask_iou(masks[2], truths[2]) < 0.8
    assert mask_iou(refined[2], truths[2]) > 0.9 and methods[2] == "grabcut"
    assert np.mean([mask_iou(m, t) for m, t in zip(refined, truths)]) > 0.93


@pytest.mark.parametrize("max_size", [None, 60])
def test_consensus_prior_without_points(cameras, tmp_path, max_size):
    """Masks from the sphere prior and two consensus rounds; computed on smaller images (max_size) they
    come back at the photos' size and as accurate."""
    from dpi.io.images import read_mask, write_srgb

    images, truths = {}, {}
    for i, cam in enumerate(cameras):
        image, truths[cam.name] = sphere_view(cam, "textured", seed=i)
        images[cam.name] = tmp_path / f"{cam.name}.png"
        write_srgb(images[cam.name], image)
    summary = derive_masks(images, {c.name: c for c in cameras}, tmp_path / "masks",
                           MaskConfig(method="grabcut", max_size=max_size))
    assert summary["prior"] == "sphere" and summary["consensus_rounds"] == 2
    masks = {n: read_mask(tmp_path / "masks" / f"{n}.png") for n in truths}
    assert all(masks[n].shape == truths[n].shape for n in truths)
    ious = [mask_iou(masks[n], truths[n]) for n in truths]
    assert np.mean(ious) > 0.9, ious


def test_clean_mask_keeps_the_largest_part_and_big_holes():
    mask = np.zeros((40, 40), bool)
    mask[5:35, 5:35] = True
    mask[10:12, 10:12] = False  # small hole: filled
    mask[18:28, 18:28] = False  # large hole (a torus' opening): kept
    mask[0:2, 38:40] = True  # speck: dropped
    out = clean_mask(mask, fill_holes_below=0.05)
    assert out[10:12, 10:12].all() and not out[18:28, 18:28].any() and not out[0:2, 38:40].any()


def test_a_mask_that_disagrees_with_the_others_is_found():
    """Masks of a sphere from eight views agree with the hull they carve; one shifted mask does not."""
    import trimesh

    from dpi.capture.cameras import from_fov, orbit
    from dpi.preprocess.masks import MASK_AGREEMENT, mask_agreement, mesh_silhouette

    sphere = trimesh.creation.icosphere(subdivisions=3)
    cameras = [from_fov(c2w, 48, 48, 40.0) for c2w in orbit(8, 4.0, (15.0, 35.0))]
    masks = [mesh_silhouette(c, np.asarray(sphere.vertices), np.asarray(sphere.faces)) for c in cameras]
    masks[3] = np.roll(masks[3], 12, axis=1)
    agreement = np.array(mask_agreement(cameras, masks, 48))
    relative = agreement / np.median(agreement)  # as derive_masks judges a view: against its peers
    assert relative[3] < 0.6 * MASK_AGREEMENT
    assert (np.delete(relative, 3) >= MASK_AGREEMENT).all(), agreement


def test_points_outside_a_cut_mask_are_counted(cameras):
    """Every point of the sphere projects inside its true silhouette; a mask without its left half loses about the
    points that project there."""
    from dpi.preprocess.mask_confidence import point_coverage

    camera, points = cameras[0], surface_points(400)
    _, truth = sphere_view(camera, "plain")
    assert point_coverage(camera, truth, points) == 1.0
    cut = truth.copy()
    xy, _ = camera.project(points)
    middle = int(np.median(xy[:, 0]))
    cut[:, :middle] = False
    assert point_coverage(camera, cut, points) == pytest.approx((xy[:, 0] >= middle + 1).mean(), abs=0.08)
    assert point_coverage(camera, truth, points[:5]) is None  # too few points witness nothing


def test_an_outline_through_the_object_or_the_background_has_no_edge_under_it(cameras):
    from dpi.io.images import to_uint8
    from dpi.preprocess.mask_confidence import EDGE_SUPPORT_MIN, edge_support

    big = from_fov(cameras[0].c2w, 96, 96, 40.0)
    image, truth = sphere_view(big, "textured")
    image8 = to_uint8(image)
    assert edge_support(image8, truth) > 0.9
    yy, xx = np.mgrid[:96, :96]
    centre = np.array(np.nonzero(truth)).mean(1)
    inner = (yy - centre[0]) ** 2 + (xx - centre[1]) ** 2 < (0.6 * np.sqrt(truth.sum() / np.pi)) ** 2
    assert edge_support(image8, inner) < EDGE_SUPPORT_MIN  # a disc inside the sphere: an outline over smooth shading
    assert edge_support(image8, np.zeros_like(truth)) is None


def test_a_mask_that_runs_out_of_the_frame_is_counted(cameras):
    """The sphere whole in frame touches no edge; the same mask with a stand running down out of the frame does, by
    the stand's width."""
    from dpi.preprocess.mask_confidence import frame_contact, verdict

    _, truth = sphere_view(cameras[0], "plain")
    assert frame_contact(truth) == 0 and not verdict({"frame_contact": 0}, None)
    rows, cols = np.nonzero(truth)
    middle = int(np.median(cols))
    stand = truth.copy()
    stand[int(np.median(rows)):, middle - 2:middle + 3] = True
    assert frame_contact(stand) == 5
    why, = verdict({"frame_contact": 5}, None)
    assert "reaches the frame's edge (5 px)" in why


def test_the_verdict_names_each_failed_witness_and_a_mostly_unreliable_capture_stops():
    from dpi.preprocess.mask_confidence import check_usable, verdict

    assert verdict({"method": "grabcut", "point_coverage": 0.99, "edge_support": 0.9, "agreement": 0.9}, 0.8) == []
    why = verdict({"method": "grabcut", "point_coverage": 0.6, "edge_support": 0.2, "agreement": 0.5}, 0.8)
    assert len(why) == 3 and "40% of the object's points" in why[0] and "80% of its outline" in why[1]
    assert verdict({"method": "consensus hull"}, None) == ["segmentation lost the object (the hull's projection "
                                                           "stands in)"]
    check_usable({"views": {"a": {}, "b": {}}, "unreliable": ["a"]}, "masks")  # half: goes on
    with pytest.raises(ValueError, match=r"^masks: the derived masks of 2 of 3 views are unreliable \(a, b\);.*"
                                         r"mask_path.*weights") as error:
        check_usable({"views": {"a": {}, "b": {}, "c": {}}, "unreliable": ["a", "b"]}, "masks")
    assert "\n" not in str(error.value)


class RedFromBlue(torch.nn.Module):
    """A tiny segmenter: foreground where red exceeds blue, inside the prompt's probable region."""

    def __init__(self):
        super().__init__()
        self.mix = torch.nn.Conv2d(4, 1, 1)
        with torch.no_grad():
            self.mix.weight.copy_(torch.tensor([20.0, 0.0, -20.0, 5.0]).reshape(1, 4, 1, 1))
            self.mix.bias.fill_(-2.0)

    def forward(self, image: torch.Tensor, prompt: torch.Tensor) -> torch.Tensor:
        return self.mix(torch.cat([image, prompt], 1))


def red_sphere_photos(cameras, folder) -> tuple[dict, list[np.ndarray]]:
    """Photos of a red sphere on a blue wall; the true masks."""
    from dpi.io.images import write_srgb

    images, truths = {}, []
    for camera in cameras:
        _, truth = sphere_view(camera, "plain")
        image = np.where(truth[..., None], [0.6, 0.1, 0.05], [0.1, 0.15, 0.5])
        write_srgb(folder / f"{camera.name}.png", image)
        images[camera.name] = folder / f"{camera.name}.png"
        truths.append(truth)
    return images, truths


def test_a_segmenter_the_user_brings_cuts_the_masks(cameras, tmp_path, monkeypatch):
    images, truths = red_sphere_photos(cameras[:4], tmp_path)
    weights = tmp_path / "weights" / "red.pt2"
    weights.parent.mkdir()
    h, w = torch.export.Dim("h", min=8, max=4096), torch.export.Dim("w", min=8, max=4096)
    example = (torch.rand(1, 3, 32, 24), torch.rand(1, 1, 32, 24))
    torch.export.save(torch.export.export(RedFromBlue(), example, dynamic_shapes=({2: h, 3: w}, {2: h, 3: w})),
                      str(weights))
    monkeypatch.setenv("DPI_WEIGHTS", str(weights.parent))
    summary = derive_masks(images, {c.name: c for c in cameras[:4]}, tmp_path / "masks",
                           MaskConfig(weights="red.pt2"), surface_points())
    assert summary["segmenter"] == str(weights)
    for camera, truth in zip(cameras[:4], truths):
        assert summary["views"][camera.name]["method"] == "learned"
        assert mask_iou(read_mask(tmp_path / "masks" / f"{camera.name}.png"), truth) > 0.95


class RedSalient(torch.nn.Module):
    """A salient-object network of rembg's signature (a fixed 64 x 64 input normalised as rembg does, a probability
    out): red against blue."""

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(8.0 * (image[:, :1] - image[:, 2:]))


def test_a_salient_object_onnx_model_cuts_the_masks_on_the_crop_of_the_object(cameras, tmp_path, monkeypatch):
    """rembg's kind of model, run through onnxruntime on the crop round where the object probably is and pasted back:
    the red sphere's masks, background outside the crop."""
    pytest.importorskip("onnx")  # to write the model; onnxruntime reads it
    images, truths = red_sphere_photos(cameras[:4], tmp_path)
    torch.onnx.export(RedSalient(), (torch.rand(1, 3, 64, 64),), str(tmp_path / "red.onnx"), dynamo=False,
                      input_names=["input.1"])
    summary = derive_masks(images, {c.name: c for c in cameras[:4]}, tmp_path / "masks",
                           MaskConfig(segmenter="rembg", weights=str(tmp_path / "red.onnx")), surface_points())
    assert summary["segmenter_kind"] == "rembg"
    for camera, truth in zip(cameras[:4], truths):
        assert summary["views"][camera.name]["method"] == "learned"
        assert mask_iou(read_mask(tmp_path / "masks" / f"{camera.name}.png"), truth) > 0.9


def test_masks_cut_without_any_sparse_point_say_so_when_they_fail(cameras, tmp_path):
    """A photo that is all object (one colour up to its edges) leaves GrabCut nothing: with no sparse points to
    start from, the error names their absence as the likely cause, not the mask settings."""
    from dpi.io.images import write_srgb

    images = {}
    for camera in cameras[:3]:
        write_srgb(tmp_path / f"{camera.name}.png", np.full((camera.height, camera.width, 3), 0.3))
        images[camera.name] = tmp_path / f"{camera.name}.png"
    with pytest.raises(ValueError, match=r"empty foreground mask \(grabcut\); no sparse point of the object"):
        derive_masks(images, {c.name: c for c in cameras[:3]}, tmp_path / "masks", MaskConfig(method="grabcut",
                                                                                              parallax=False))


def test_a_missing_or_broken_segmenter_is_one_line(cameras, tmp_path):
    images, _ = red_sphere_photos(cameras[:3], tmp_path)
    views = {c.name: c for c in cameras[:3]}
    with pytest.raises(ValueError, match=r"preprocess.masks.weights: .*nowhere.pt2 is not a file"):
        derive_masks(images, views, tmp_path / "masks", MaskConfig(weights=str(tmp_path / "nowhere.pt2")))
    (tmp_path / "junk.pt2").write_bytes(b"not a network")
    with pytest.raises(ValueError, match=r"junk.pt2: not a segmenter saved with torch.export.save"):
        derive_masks(images, views, tmp_path / "masks", MaskConfig(weights=str(tmp_path / "junk.pt2")))
    with pytest.raises(ValueError, match="method learned needs preprocess.masks.weights"):
        derive_masks(images, views, tmp_path / "masks", MaskConfig(method="learned"))


def test_the_consensus_hull_is_cut_where_the_object_stands():
    """A sphere's masks carve a hull whose projection, cut at a support plane through its equator, is the
    silhouette of the half above the plane, not the whole sphere's."""
    import trimesh

    from dpi.preprocess.masks import consensus_outlines

    def above_the_plane(camera, height: float) -> np.ndarray:
        """Pixels whose ray crosses the unit sphere somewhere above y = height (the cut sphere's silhouette)."""
        origins, dirs = pixel_rays(camera)
        o, d = origins[:, :, 0], dirs[:, :, 0]
        b = (o * d).sum(-1)
        disc = b * b - ((o * o).sum(-1) - 1.0)
        ends = [o[..., 1] + (-b + sign * np.sqrt(np.maximum(disc, 0))) * d[..., 1] for sign in (-1, 1)]
        return (disc > 0) & (np.maximum(*ends) > height)

    sphere = trimesh.creation.icosphere(subdivisions=4)
    up, height = np.array([0.0, 1.0, 0.0]), 0.0
    cameras = [from_fov(c2w, 48, 48, 40.0) for c2w in orbit(8, 4.0, (15.0, 35.0))]
    masks = [mesh_silhouette(c, np.asarray(sphere.vertices), np.asarray(sphere.faces)) for c in cameras]
    outlines = consensus_outlines(cameras, masks, 2, 48, (up, height))
    for camera, mask, outline in zip(cameras, masks, outlines):
        truth = above_the_plane(camera, height)
        assert mask_iou(outline, truth) > 0.9 and mask_iou(outline, truth) > mask_iou(mask, truth) + 0.05


def test_the_capture_geometry_that_cannot_give_masks_is_named():
    """Too few views, cameras at one spot, or a baseline whose parallax at the scene's depth is under 2 px: named;
    an orbit around the object passes."""
    from dpi.preprocess.masks import capture_geometry_problem

    ring = [from_fov(c2w, 96, 96, 40.0) for c2w in orbit(8, 3.0, (20.0, 35.0))]
    points = np.random.default_rng(0).normal(scale=0.3, size=(200, 3))
    assert capture_geometry_problem(ring, points) is None
    assert "only 2 photo(s) have cameras" in capture_geometry_problem(ring[:2], points)
    one_spot = [from_fov(ring[0].c2w, 96, 96, 40.0) for _ in range(6)]
    assert "every camera is at the same place" in capture_geometry_problem(one_spot, None)
    assert "shifts by 0 px" in capture_geometry_problem(one_spot, points)
    shifted = []
    for k in range(4):
        c2w = ring[0].c2w.copy()
        c2w[0, 3] += 0.01 * k  # 3 cm apart, 3 m from the object: under a pixel of parallax at 96 px
        shifted.append(from_fov(c2w, 96, 96, 40.0))
    assert "walk around the object" in capture_geometry_problem(shifted, points)
