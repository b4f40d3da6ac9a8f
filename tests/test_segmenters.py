"""The segmenters a user brings (dpi.preprocess.segmenter): the prompt a view gets from what the cameras know, and
Segment Anything and SAM 2 built by their packages with random weights (no checkpoint), fed that prompt, their masks
following their logits."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from dpi.capture.cameras import from_fov, look_at
from dpi.preprocess.masks import PROMPT_POINTS, first_prior, view_prompt
from dpi.preprocess.segmenter import (PointPrompted, learned_mask, load_segmenter, sam2_config, sam_variant,
                                      weights_file)
from torchvision_standin import install


@pytest.fixture(scope="module")
def view():
    """A camera looking at a ball of sparse points (radius 0.5) in front of a wall of them, its GrabCut labels and a
    picture that is not symmetric (a red disc on blue, a green corner top left)."""
    camera = from_fov(look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0)), 64, 48, 40.0, name="v")
    rng = np.random.default_rng(0)
    ball = rng.normal(size=(300, 3))
    ball = 0.5 * ball / np.linalg.norm(ball, axis=1, keepdims=True)
    wall = np.column_stack([rng.uniform(-3, 3, 200), rng.uniform(-2, 2, 200), np.full(200, -2.0)])
    labels = first_prior(camera, (np.zeros(3), 0.6), ball)
    image = np.zeros((48, 64, 3), np.uint8)
    image[:] = (30, 40, 160)
    cv2.circle(image, (32, 24), 12, (200, 30, 20), -1)
    image[:8, :8] = (20, 200, 30)
    return camera, labels, ball, np.concatenate([ball, wall]), image


def test_the_prompt_puts_the_objects_points_on_its_core_and_the_walls_off_it(view):
    camera, labels, ball, scene, _ = view
    prompt = view_prompt(camera, labels, ball, scene)
    assert 1 <= len(prompt.positive) <= PROMPT_POINTS and 1 <= len(prompt.negative) <= PROMPT_POINTS
    at = lambda xy: labels[xy[:, 1].astype(int), xy[:, 0].astype(int)]  # noqa: E731
    assert np.isin(at(prompt.positive), [cv2.GC_FGD]).all()
    assert np.isin(at(prompt.negative), [cv2.GC_BGD, cv2.GC_PR_BGD]).all()
    ys, xs = np.nonzero((labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD))
    assert prompt.box.tolist() == [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]
    assert np.linalg.norm(prompt.positive - prompt.positive.mean(0), axis=1).max() > 3  # spread, not one clump
    without = view_prompt(camera, labels, None, None)  # no sparse points: the middle of the region, no negatives
    assert len(without.positive) == 1 and len(without.negative) == 0
    assert abs(without.positive[0, 0] - 32) < 2 and abs(without.positive[0, 1] - 24) < 2


def sam_model(kind: str):
    """(The package's predictor over its real architecture with random weights, the variant dpi reads from it.)"""
    torch.manual_seed(0)
    if kind == "sam":
        from segment_anything import SamPredictor, sam_model_registry

        model = sam_model_registry["vit_b"]().eval()
        return SamPredictor(model), sam_variant(model.state_dict())
    from sam2.build_sam import build_sam2
    from sam2.sam2_image_predictor import SAM2ImagePredictor

    model = build_sam2("configs/sam2.1/sam2.1_hiera_t.yaml", None, device="cpu")
    return SAM2ImagePredictor(model), sam2_config(model.state_dict())


@pytest.mark.parametrize("kind, variant", [("sam", "vit_b"), ("sam2", "configs/sam2.1/sam2.1_hiera_t.yaml")])
def test_segment_anything_takes_the_views_prompt_and_its_mask_follows_its_logits(view, monkeypatch, kind, variant):
    install(monkeypatch)
    camera, labels, ball, scene, image = view
    predictor, read = sam_model(kind)
    assert read == variant  # the variant is read back from the architecture's own weights
    calls = {}
    set_image, predict = predictor.set_image, predictor.predict

    def spy_set_image(image8):
        calls["image"] = image8.copy()
        return set_image(image8)

    def spy_predict(**kwargs):
        calls["prompt"] = kwargs
        calls["out"] = predict(**kwargs)
        return calls["out"]

    monkeypatch.setattr(predictor, "set_image", spy_set_image)
    monkeypatch.setattr(predictor, "predict", spy_predict)
    prompt = view_prompt(camera, labels, ball, scene)
    mask = learned_mask(PointPrompted(predictor), image, prompt)
    assert np.array_equal(calls["image"], image)  # rows are y, columns x, channels RGB: as the photo is
    sent = calls["prompt"]
    assert np.allclose(sent["point_coords"], np.concatenate([prompt.positive, prompt.negative]))
    assert sent["point_labels"].tolist() == [1] * len(prompt.positive) + [0] * len(prompt.negative)
    assert np.allclose(sent["box"], prompt.box) and sent["return_logits"]
    logits = np.asarray(calls["out"][0])
    assert logits.shape[-2:] == image.shape[:2] and mask.shape == image.shape[:2]
    assert np.array_equal(mask, logits[int(np.argmax(calls["out"][1]))] > 0)


def test_a_sam2_checkpoint_is_built_at_its_size(tmp_path, monkeypatch):
    install(monkeypatch)
    from sam2.build_sam import build_sam2

    torch.manual_seed(1)
    model = build_sam2("configs/sam2.1/sam2.1_hiera_t.yaml", None, device="cpu")
    path = tmp_path / "sam2.1_hiera_tiny.pt"
    torch.save({"model": model.state_dict()}, path)
    segmenter = load_segmenter("sam2", path)
    loaded = segmenter.predictor.model.state_dict()
    key = "image_encoder.trunk.patch_embed.proj.weight"
    assert torch.equal(loaded[key], model.state_dict()[key])
    legacy = {k: v for k, v in model.state_dict().items() if k != "no_obj_embed_spatial"}
    assert sam2_config(legacy) == "configs/sam2/sam2_hiera_t.yaml"


def test_a_wrong_file_or_a_missing_package_is_one_line(tmp_path, monkeypatch):
    install(monkeypatch)
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match=r"junk.pth: not a sam checkpoint"):
        load_segmenter("sam", junk)
    with pytest.raises(ValueError, match=r"junk.pth: not an ONNX model"):
        load_segmenter("rembg", junk)
    monkeypatch.setitem(__import__("sys").modules, "segment_anything", None)
    with pytest.raises(ValueError, match=r"segmenter sam needs the segment_anything package: pip install"):
        load_segmenter("sam", junk)
    torch.save({"model": {"image_encoder.trunk.patch_embed.proj.weight": torch.zeros(80, 3, 7, 7)}}, tmp_path / "x.pt")
    with pytest.raises(ValueError, match=r"x.pt: not a SAM 2 checkpoint"):
        load_segmenter("sam2", tmp_path / "x.pt")
    with pytest.raises(ValueError, match=r"weights: .*none.pt is not a file"):
        weights_file(str(tmp_path / "none.pt"))
