"""Accuracy and run time of the preprocessing stages on synthetic photo captures.

Renders photo-only captures (PNG images, no cameras, masks or mesh; ground truth hidden in gt/)
of a convex blob and a bumpy torus (a hole, self-occlusion) in front of a textured or a plain
backdrop, runs poses -> masks -> geometry -> uv as the workflow does, and prints one row per
capture: pose errors after Umeyama alignment, mask IoU, Chamfer distance (% of the bounding-box
diagonal) and the seconds of every stage. Not a timed test: numbers depend on the machine.

    .venv/bin/python benchmarks/preprocess_accuracy.py                     # defaults below
    .venv/bin/python benchmarks/preprocess_accuracy.py --views 40 --size 400 --backgrounds textured
    .venv/bin/python benchmarks/preprocess_accuracy.py --captures /tmp/pp   # keep the renders, reuse them
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from tabulate import tabulate

from dpi.images import read_mask
from dpi.preprocess.accuracy import align_mesh, chamfer, mask_iou, pose_errors
from dpi.preprocess.geometry import read_mesh
from dpi.preprocess.sfm import SfMError
from dpi.cameras import read_cameras
from dpi.preprocess.stages import capture_stage, geometry_stage, masks_stage, poses_stage, uv_stage
from dpi.layout import SYNTH_MARKER, SceneLayout
from dpi.synth.capture import SynthConfig, make_synthetic_capture


def run_capture(root: Path, work: Path, threads: int) -> dict:
    """Run the four stages on one photo capture; accuracy and seconds per stage."""
    scene = SceneLayout(work)
    capture_stage(root, scene.capture_json)
    row, capture_json = {}, scene.capture_json
    truth = read_cameras(root / "gt" / "transforms.json")
    start = time.perf_counter()
    try:
        poses_stage(capture_json, scene.poses_dir, {"max_features": 2048}, threads=threads)
        cameras_json, points = scene.poses["cameras"], scene.poses["points"]
        cameras = read_cameras(cameras_json)
        errors = pose_errors(cameras, truth)
        row.update(registered=f"{errors['views']}/{len(truth)}", rot_deg_mean=errors["rotation_error_deg_mean"],
                   rot_deg_max=errors["rotation_error_deg_max"], centre_pct_mean=100 * errors["centre_error_mean"])
    except SfMError as exc:  # e.g. a plain background: measure the other stages with the true cameras
        row["registered"] = f"failed ({exc.summary.get('registered', 0)}/{len(truth)}), true cameras used"
        cameras_json, points, cameras = root / "gt" / "transforms.json", None, truth
    row["poses_s"] = time.perf_counter() - start
    start = time.perf_counter()
    summary = masks_stage(capture_json, scene.masks, {}, cameras_json, points)
    row["masks_s"] = time.perf_counter() - start
    ious = [mask_iou(read_mask(scene.masks / f"{n}.png"), read_mask(root / "gt" / "masks" / f"{n}.png"))
            for n in truth if n in cameras]
    methods = {v["method"] for v in summary["views"].values()}
    row.update(mask_prior=summary["prior"] if "grabcut" in methods else "key", iou_mean=np.mean(ious),
               iou_min=np.min(ious))
    start = time.perf_counter()
    geometry_stage(capture_json, scene.geometry_dir, {}, cameras_json, scene.masks)
    row["geometry_s"] = time.perf_counter() - start
    vertices, faces = read_mesh(scene.geometry["mesh"])
    error = chamfer(align_mesh(vertices, cameras, truth), faces, *read_mesh(root / "gt" / "mesh.ply"))
    row["chamfer_pct"] = 100 * error["chamfer_rel"]
    start = time.perf_counter()
    uv_stage(capture_json, scene.geometry_dir, {}, scene.geometry["mesh"])
    row["uv_s"] = time.perf_counter() - start
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=["blob", "bumpy_torus"])
    parser.add_argument("--backgrounds", nargs="+", default=["textured", "plain"])
    parser.add_argument("--views", type=int, default=32)
    parser.add_argument("--size", type=int, default=240)
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--captures", help="render the captures into this folder and reuse those already there "
                        "(default: a temporary folder)")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for shape in args.shapes:
            for background in args.backgrounds:
                name = f"{shape}_{background}_{args.views}x{args.size}_{args.spp}spp"
                root = Path(args.captures or tmp) / name
                cfg = SynthConfig(shape=shape, views=args.views, held_out_every=8, width=args.size, height=args.size,
                                  spp=args.spp, texture_size=256, camera_distance=6.0, elevations_deg=(15.0, 30.0),
                                  albedo_detail=0.6, background=background, image_format="png", photos_only=True)
                start = time.perf_counter()
                if not (root / SYNTH_MARKER).is_file():
                    make_synthetic_capture(root, cfg, threads=args.threads, progress=False)
                render_s = time.perf_counter() - start
                try:
                    row = run_capture(root, Path(tmp) / f"work_{name}", args.threads)
                except Exception as exc:  # a failing stage is a result too
                    row = {"error": f"{type(exc).__name__}: {str(exc)[:80]}"}
                rows.append({"shape": shape, "background": background, "render_s": render_s, **row})
                print(tabulate([rows[-1]], headers="keys", floatfmt=".3g"), flush=True)
    print(f"\n{args.views} views of {args.size}x{args.size}, {args.spp} spp, {args.threads} threads")
    print(tabulate(rows, headers="keys", floatfmt=".3g"))


if __name__ == "__main__":
    main()
