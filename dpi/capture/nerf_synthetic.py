"""The NeRF-synthetic layout: cameras in transforms_train.json, transforms_val.json and transforms_test.json, each
frame's `file_path` naming its image relative to the capture (often without its extension: "./train/r_0"), and
the images' alpha as the masks. The test split is held out; train and val are fitted."""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from dpi.capture.folder import view_name
from dpi.capture.model import CaptureError, inside_capture
from dpi.capture.transforms import read_transforms_json
from dpi.io.images import IMAGE_SUFFIXES

SPLITS = {"train": False, "val": False, "test": True}
"""the layout's splits and whether each is held out"""


def split_files(root: Path) -> dict[str, Path]:
    """split -> its transforms_{split}.json, for the splits the capture has."""
    return {split: root / f"transforms_{split}.json" for split in SPLITS
            if (root / f"transforms_{split}.json").is_file()}


def frame_image(root: Path, source: Path, index: int, file_path: object) -> Path:
    """The image a frame's `file_path` names, relative to the capture: as written, else with an image suffix."""
    if not isinstance(file_path, str):
        raise CaptureError(f"{source}: frame {index}: 'file_path' must be a string")
    given = root / PurePosixPath(file_path.replace("\\", "/"))
    candidates = [given] + [given.with_name(given.name + s) for s in IMAGE_SUFFIXES]
    found = next((p for p in candidates if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES), None)
    if found is None:
        raise CaptureError(f"{source}: frame {index}: no image {file_path!r} in the capture (tried "
                           f"{', '.join(IMAGE_SUFFIXES)})")
    inside_capture(root, found, f"the image of frame {index}")
    return found


def read_splits(root: Path) -> tuple[dict[str, Path], dict]:
    """view name ({split}_{stem}) -> image file, and one transforms dict over the splits whose frames carry the view
    names as file paths, their file's intrinsics, and `held_out` for the test split."""
    images: dict[str, Path] = {}
    frames = []
    splits_of: dict[Path, tuple[str, Path]] = {}
    for split, path in split_files(root).items():
        data = read_transforms_json(path)
        shared = {k: v for k, v in data.items() if k != "frames"}
        for i, frame in enumerate(data["frames"]):
            image = frame_image(root, path, i, frame["file_path"])
            name = view_name(f"{split}_{image.stem}")
            if name in images:
                raise CaptureError(f"{path}: frame {i}: a second frame for image {image.name!r} of the {split} split")
            first = splits_of.setdefault(image.resolve(), (split, path))
            if SPLITS[first[0]] != SPLITS[split]:
                raise CaptureError(f"{path}: frame {i}: image {image.name!r} is in the {split} split and in the "
                                   f"{first[0]} split ({first[1].name}): a view cannot be both fitted and held out")
            images[name] = image
            frames.append({**shared, **frame, "file_path": name, "held_out": SPLITS[split]})
    if not images:
        raise CaptureError(f"{root}: the transforms_*.json files hold no frames")
    return images, {"frames": frames}
