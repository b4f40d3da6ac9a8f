"""A real object in front of a busy street (tests/data/saharov32_small: 11 of the saharov32 photos at 160 x 240, with
the cameras and a sample of the sparse points the poses stage found on the full photos; MIT, its LICENSE): the masks
stage finds the statue and its boulder by parallax where colour alone takes the facade behind them."""

from pathlib import Path

import numpy as np
import pytest

from dpi.capture.cameras import read_cameras
from dpi.capture.consistency import mask_iou
from dpi.io.images import read_mask
from dpi.preprocess.masks import MaskConfig, derive_masks

BUSY = Path(__file__).parent / "data" / "saharov32_small"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def masks(tmp_path_factory):
    cameras = read_cameras(BUSY / "transforms.json")
    points = np.load(BUSY / "points.npz")
    images = {p.stem: p for p in sorted((BUSY / "images").glob("*.jpg"))}
    out = {}
    for parallax in (True, False):
        folder = tmp_path_factory.mktemp(f"parallax_{parallax}")
        summary = derive_masks(images, cameras, folder, MaskConfig(parallax=parallax),
                               points["xyz"][points["on_object"]], points["xyz"])
        out[parallax] = {p.stem: (mask_iou(read_mask(folder / p.name), read_mask(p)), p.stem in summary["unreliable"])
                         for p in sorted((BUSY / "reference_masks").glob("*.png"))}
    return out


def test_parallax_finds_the_statue_where_colour_takes_the_facade(masks):
    for view, (iou, flagged) in masks[True].items():
        assert iou >= 0.7 or flagged, view  # at 160 px; the full photos reach 0.89-0.92
        assert iou > masks[False][view][0] + 0.3, view
