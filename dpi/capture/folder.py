"""A capture folder's files: images (views named by stem, ordered naturally, EXR over LDR), masks and ground truth,
each checked once."""

from __future__ import annotations

import hashlib
import os
import re
import unicodedata
import warnings
from pathlib import Path

import numpy as np

from dpi.capture.model import CaptureError, CaptureWarning, inside_capture
from dpi.io.exr import EXRError, read_exr
from dpi.io.images import (HDR_SUFFIXES, IMAGE_SUFFIXES, LDR_SUFFIXES, ImageError, decode_ldr, ldr_header_size,
                            mask_values, read_image, read_mask)
from dpi.light.envmap import EnvmapLayoutError, read_envmap

CLIPPED_WARNING_FRACTION = 0.01
"""an LDR image with at least this fraction of pixels at white gets a warning"""


MIN_IMAGE_SIZE = 8
"""an image smaller than this (px) on either side holds no shading to fit"""


GT_NAMES = ("envmap", "albedo", "roughness", "metallic")
MAX_VIEW_NAME_BYTES = 160
"""longest view name (UTF-8 bytes): a job writes files named after a view with a prefix and a suffix around it
(relit views, atomic writes' temporary names), and file systems stop at 255 bytes a name"""


def check_root(root: Path) -> None:
    """Fail unless the capture folder exists."""
    if not root.is_dir():
        raise CaptureError(f"{root}: capture folder does not exist")


OS_CLUTTER = ("thumbs.db", "ehthumbs.db", "desktop.ini", "icon\r")
"""files operating systems leave in a folder of photos (besides dot files such as .DS_Store), skipped"""


def view_name(name: str) -> str:
    """A view's name in one Unicode normal form (NFC): macOS writes file names decomposed, JSON files composed."""
    return unicodedata.normalize("NFC", name)


def natural_key(name: str) -> tuple:
    """Sort key that orders digit runs by value, so "2" sorts before "10"."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name))


def stems(folder: Path, what: str) -> dict[str, Path]:
    """view name (the stem, NFC) -> file of the images in a folder; EXR wins over an LDR copy, other duplicates
    are errors; dot files and OS_CLUTTER are skipped."""
    found: dict[str, Path] = {}
    inside_capture(folder.parent, folder, f"the {what} folder")  # before listing it: a link to / lists nothing
    for path in sorted(folder.iterdir()):
        if path.name.startswith(".") or path.name.lower() in OS_CLUTTER or path.is_dir():
            continue
        if path.suffix.lower() not in IMAGE_SUFFIXES:
            raise CaptureError(f"{path}: unsupported {what} suffix {path.suffix!r} (use {', '.join(IMAGE_SUFFIXES)})")
        inside_capture(folder.parent, path, f"the {what}")
        if not path.is_file():
            raise CaptureError(f"{path}: the {what} is not a regular file (a pipe, a socket, a device or a broken "
                               "link)")
        if "{" in path.name or "}" in path.name:
            raise CaptureError(f"{folder}: an {what} name holds a brace ({{ or }}), which workflow paths read as a "
                               "wildcard: rename it")
        stem = view_name(path.stem)
        other = found.get(stem)
        if other is None:
            found[stem] = path
        elif (path.suffix.lower() in HDR_SUFFIXES) == (other.suffix.lower() in HDR_SUFFIXES):
            raise CaptureError(f"{path}: ambiguous {what}: {other.name} has the same name")
        elif path.suffix.lower() in HDR_SUFFIXES:
            found[stem] = path
    return found


def image_files(root: Path) -> dict[str, Path]:
    """view name -> image file, in natural order; fails on a missing or empty images/ folder."""
    folder = root / "images"
    if not folder.is_dir():
        raise CaptureError(f"{folder}: missing images folder (required)")
    images = stems(folder, "image")
    for name, path in images.items():
        if len(name.encode("utf-8")) > MAX_VIEW_NAME_BYTES:
            raise CaptureError(f"{folder}: the image named {name[:24]}... has a name of {len(name.encode('utf-8'))} "
                               f"bytes; dpi names files after views and takes at most {MAX_VIEW_NAME_BYTES}: "
                               "shorten it")
    if not images:
        raise CaptureError(f"{folder}: images folder is empty (expected {', '.join(IMAGE_SUFFIXES)} files)")
    return {name: images[name] for name in sorted(images, key=natural_key)}


def named_files(folder: Path, names: tuple[str, ...]) -> list[Path]:
    """The files of `folder` named one of `names` when case is ignored (mesh.PLY for mesh.ply), in that order."""
    files = [p for p in sorted(folder.iterdir()) if p.is_file()] if folder.is_dir() else []
    return [p for name in names for p in files if p.name.lower() == name]


def check_image_size(path: Path, width: int, height: int) -> None:
    """One CaptureError naming the image unless it has MIN_IMAGE_SIZE px on each side."""
    if min(width, height) < MIN_IMAGE_SIZE:
        raise CaptureError(f"{path}: image is {width}x{height} px; dpi needs at least {MIN_IMAGE_SIZE} px on each "
                           "side (a photo or a render of the object, not a thumbnail)")


def check_header_sizes(images: dict[str, Path]) -> None:
    """The PNG/JPG images' sizes as their headers declare them (turned by their EXIF orientation) all agree: else one
    CaptureError naming the first that differs, before any image is decoded."""
    size, first = None, None
    for path in (p for p in images.values() if p.suffix.lower() in LDR_SUFFIXES):
        try:
            width, height = ldr_header_size(path)
        except ImageError as exc:
            raise CaptureError(str(exc)) from None
        check_image_size(path, width, height)
        if size is None:
            size, first = (width, height), path
        elif (width, height) != size:
            raise CaptureError(f"{path}: image size {width}x{height} differs from {first.name} ({size[0]}x{size[1]}) "
                               "(as the files' headers declare them)")


def check_images(images: dict[str, Path], distinct: bool = False) -> tuple[int, int]:
    """Decode every image (finite, non-negative, with signal, all the same size, the headers compared first; with
    `distinct`, no two with the same pixels: photos that must give their own cameras); returns (width, height)."""
    check_header_sizes(images)
    size, first = None, None
    seen: dict[str, Path] = {}
    for path in images.values():
        try:
            image = read_image(path)
        except ImageError as exc:
            raise CaptureError(str(exc)) from exc
        height, width = image.shape[:2]
        check_image_size(path, width, height)
        check_signal(path, image)
        if distinct:
            digest = hashlib.blake2b(np.ascontiguousarray(image).tobytes(), digest_size=16).hexdigest()
            if digest in seen:
                raise CaptureError(f"{path}: the same photo as {seen[digest].name} (identical pixels): the cameras "
                                   "come from the photos, which must be taken from different places")
            seen[digest] = path
        if size is None:
            size, first = (width, height), path
        elif (width, height) != size:
            raise CaptureError(f"{path}: image size {width}x{height} differs from {first.name} ({size[0]}x{size[1]})")
    return size


def check_signal(path: Path, image: np.ndarray) -> None:
    """Fail on an image without signal (all black, or every pixel clipped: at white for PNG/JPG, at one value
    for EXR); warn with the fraction when at least CLIPPED_WARNING_FRACTION of an LDR image's pixels are white. A
    cut-out (a PNG whose alpha varies) counts only its opaque pixels: its transparent background is no photo."""
    peak = float(image.max())
    if peak == 0:
        raise CaptureError(f"{path}: image is all black (every pixel 0): nothing to fit")
    ldr = path.suffix.lower() in LDR_SUFFIXES
    white = 1.0 if ldr else peak
    shown = cut_out(path)
    at_white = (image >= white).any(axis=-1)
    clipped = float(at_white[shown].mean()) if shown is not None and shown.any() else float(at_white.mean())
    if clipped == 1.0:
        raise CaptureError(f"{path}: every pixel is clipped at {white:g} (saturated): no shading to fit")
    if ldr and clipped >= CLIPPED_WARNING_FRACTION:
        warnings.warn(f"{path}: {100 * clipped:.1f}% of the pixels are clipped at white; the fit takes them as "
                      "exact, so shading there is underestimated", CaptureWarning, stacklevel=2)


def cut_out(path: Path) -> np.ndarray | None:
    """The opaque pixels (H, W) of a PNG whose alpha varies (a cut-out); None for other images."""
    if path.suffix.lower() != ".png" or not png_has_alpha(path):
        return None
    alpha = decode_ldr(path)[..., -1]
    return alpha > 0.5 if alpha.min() < alpha.max() else None


PNG_ALPHA_TYPES = (4, 6)
"""PNG colour types with an alpha channel (grey + alpha, RGBA)"""


def png_has_alpha(path: Path) -> bool:
    """Whether a PNG's header declares an alpha channel (its IHDR colour type, byte 25)."""
    with open(path, "rb") as handle:
        head = handle.read(26)
    return head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) == 26 and head[25] in PNG_ALPHA_TYPES


def alpha_masks(images: dict[str, Path]) -> dict[str, Path] | None:
    """The images as their own masks (read_mask takes a varying alpha) when every one is a PNG with an alpha
    channel and the first one's alpha varies: cut-outs, as NeRF-synthetic renders are; else None."""
    paths = list(images.values())
    if not paths or any(p.suffix.lower() != ".png" or not png_has_alpha(p) for p in paths):
        return None
    return dict(images) if cut_out(paths[0]) is not None else None


def by_view(masks: dict[str, Path], images: dict[str, Path]) -> dict[str, Path]:
    """masks/ keyed by view: a mask named like a view is that view's, one named like a view's image file (r_000 for
    the view train_r_000 of a NeRF-synthetic split) is that view's when no other image has the name."""
    owners: dict[str, list[str]] = {}
    for name, image in images.items():
        owners.setdefault(image.stem, []).append(name)
    return {name if name in images or len(owners.get(name, ())) != 1 else owners[name][0]: path
            for name, path in masks.items()}


def mask_files(root: Path, images: dict[str, Path], size: tuple[int, int],
                given: dict[str, Path] | None = None) -> dict[str, Path] | None:
    """view name -> mask file: `given` (transforms.json's mask_path) or masks/ (None without either), checking one
    non-empty mask of the right size per image."""
    folder = root / "masks"
    if given is None and not folder.is_dir():
        return None
    masks = given if given is not None else by_view(stems(folder, "mask"), images)
    for name in masks:
        if name not in images:
            raise CaptureError(f"{masks[name]}: mask has no matching image in images/")
    for name in images:
        if name not in masks:
            raise CaptureError(f"{folder}: missing mask for image {images[name].name} (expected {name}.png)")
        try:
            mask = read_mask(masks[name])
        except ImageError as exc:
            raise CaptureError(str(exc)) from exc
        if (mask.shape[1], mask.shape[0]) != size:
            raise CaptureError(f"{masks[name]}: mask size {mask.shape[1]}x{mask.shape[0]} != "
                               f"image size {size[0]}x{size[1]}")
        if not mask.any():
            top = float(mask_values(masks[name]).max()) if masks[name].suffix.lower() in LDR_SUFFIXES else 0.0
            hint = (f"; its largest value is {round(top * 255)} of 255: masks stored as 0/1 must be scaled to 0/255"
                    if 0 < top <= 1 / 255 + 1e-6 else "")
            raise CaptureError(f"{masks[name]}: empty mask (no foreground pixel){hint}")
        if mask.all():
            raise CaptureError(f"{masks[name]}: mask is all foreground (every pixel white): a mask is white on the "
                               "object and black on the background")
    return masks


def gt_files(root: Path) -> dict[str, Path]:
    """name -> ground-truth map (gt/{name}.exr, any case; the env map also as gt/envmap.hdr), each read as every stage
    reads it (`read_ground_truth`)."""
    gt, sizes = {}, {}
    for name in GT_NAMES:
        suffixes = (".exr", ".hdr") if name == "envmap" else (".exr",)
        for path in named_files(root / "gt", tuple(f"{name}{s}" for s in suffixes))[:1]:
            inside_capture(root, path, f"ground truth {name}")
            try:
                data = read_ground_truth(path, name)
            except (EXRError, EnvmapLayoutError, ImageError) as exc:
                raise CaptureError(str(exc)) from exc
            if name != "envmap":
                sizes[path] = check_truth_texture(path, data, sizes)
            gt[name] = path
    return gt


def check_truth_texture(path: Path, data: np.ndarray, earlier: dict[Path, tuple[int, int]]) -> tuple[int, int]:
    """A true texture's (width, height): square, as the atlas it is painted on, and the size of the `earlier` ones
    (one atlas holds them all); else one CaptureError naming it."""
    height, width = data.shape[:2]
    if height != width:
        raise CaptureError(f"{path}: ground truth texture is {width}x{height} px; a texture on the mesh's atlas is "
                           "square (R x R)")
    for other, size in earlier.items():
        if size != (width, height):
            raise CaptureError(f"{path}: ground truth texture is {width}x{height} px, {other.name} is "
                               f"{size[0]}x{size[1]}: the true textures share one atlas")
    return width, height


def read_ground_truth(path: str | os.PathLike, name: str, log: bool = False) -> np.ndarray:
    """A ground-truth map, the one reader of gt/*.exr: the envmap (H, 2H, 3) through `dpi.light.envmap.read_envmap`
    (any layout it reads; `log` prints its changes), a texture (albedo (H, W, 3), grey repeated; roughness,
    metallic (H, W, 1), the first channel, as `MaterialTextures.load`); NaN, Inf or negative values are an
    EXRError naming the file."""
    if name == "envmap":
        return read_envmap(path, log=log)
    data = read_exr(path)
    if not np.isfinite(data).all() or (data < 0).any():
        raise EXRError(f"{path}: ground truth {name} has NaN, Inf or negative values")
    channels = 3 if name == "albedo" else 1
    return np.repeat(data, 3, axis=-1) if data.shape[-1] < channels else data[..., :channels]
