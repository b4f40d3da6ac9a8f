"""Accuracy and run time of the preprocessing stages on synthetic photo captures.

Renders photo-only captures (PNG images, no cameras, masks or mesh; ground truth hidden in gt/)
of a convex blob, a bumpy torus (a hole, self-occlusion) and a bowl (a cavity, a flat foot) in front
of a textured or a plain backdrop, seen from the upper hemisphere only (`--elevations`, like a
table-top capture) all around or on an arc (`--arc 180`: a half circle in front of the object, whose hull is
open behind it; `--wall-behind 2`: the backdrop a flat wall close behind the object, as a head on a wall), runs
poses -> masks -> geometry -> uv as the workflow does, and prints one row
per capture: pose errors after Umeyama alignment, mask IoU, what the masks' witnesses flagged (views under 0.8
IoU and how many of them were flagged; views over 0.9 IoU flagged), Chamfer distance (% of the bounding-box
diagonal) and the seconds of every stage; rows (shape, views, size, rotation_deg, mask_iou,
chamfer_pct, poses_s, ..., seconds) are appended to notebook/results/preprocess.csv. Not a timed
test: numbers depend on the machine.

    .venv/bin/python benchmarks/preprocess/preprocess.py                     # defaults below
    .venv/bin/python benchmarks/preprocess/preprocess.py --views 40 --size 400 --backgrounds textured
    .venv/bin/python benchmarks/preprocess/preprocess.py --captures /tmp/pp   # keep the renders, reuse them
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from tabulate import tabulate

from dpi.capture import read_capture_json
from dpi.capture.cameras import read_cameras
from dpi.capture.consistency import mask_iou
from dpi.capture.load import complete_capture
from dpi.config.pipeline import resolve_config
from dpi.io.images import read_mask
from dpi.io.layout import SYNTH_MARKER, SceneLayout
from dpi.preprocess.accuracy import align_mesh, chamfer, flag_counts, pose_errors
from dpi.preprocess.derive import derive_geometry, derive_poses, derive_uv, derive_view_masks, normalise_capture
from dpi.preprocess.geometry import read_mesh
from dpi.preprocess.sfm import SfMError
from dpi.solve.problem import SolveConfig, texture_size_for
from dpi.studies.engine import append_row, settings_hash
from dpi.synth.capture import SynthConfig, make_synthetic_capture
from dpi.synth.shapes import SHAPES

CSV = Path(__file__).resolve().parents[2] / "notebook" / "results" / "preprocess.csv"


def run_capture(root: Path, work: Path, threads: int, sfm: dict, geometry: dict, masks: dict) -> dict:
    """Run the four stages on one photo capture; accuracy and seconds per stage."""
    scene = SceneLayout(work)
    normalise_capture(root, scene.capture_json)
    row, capture_json = {}, scene.capture_json
    truth = read_cameras(root / "gt" / "transforms.json")
    start = time.perf_counter()
    try:
        derive_poses(capture_json, scene.poses_dir, sfm, threads=threads)
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
    summary = derive_view_masks(capture_json, scene.masks, masks, cameras_json, points)
    row["masks_s"] = time.perf_counter() - start
    ious = [mask_iou(read_mask(scene.masks / f"{n}.png"), read_mask(root / "gt" / "masks" / f"{n}.png"))
            for n in truth if n in cameras]
    methods = {v["method"] for v in summary["views"].values()}
    flagged = [summary["views"][n].get("reliable", True) is False for n in truth if n in cameras]
    row.update(mask_prior=summary["prior"] if "grabcut" in methods else "key", iou_mean=np.mean(ious),
               iou_min=np.min(ious), **flag_counts(ious, flagged))
    start = time.perf_counter()
    derive_geometry(capture_json, scene.geometry_dir, geometry, cameras_json, scene.masks)
    row["geometry_s"] = time.perf_counter() - start
    vertices, faces = read_mesh(scene.geometry["mesh"])
    error = chamfer(align_mesh(vertices, cameras, truth), faces, *read_mesh(root / "gt" / "mesh.ply"))
    row["chamfer_pct"] = 100 * error["chamfer_rel"]
    start = time.perf_counter()
    capture = complete_capture(read_capture_json(capture_json), scene, ("masks",))
    size = texture_size_for(capture, SolveConfig.from_config(resolve_config({})).problem)  # the workflow's rule
    derive_uv(capture_json, scene.geometry_dir, size, {}, scene.geometry["mesh"])
    row["uv_s"] = time.perf_counter() - start
    return row


def append_csv(path: Path, row: dict, views: int, size: int, elevations: list[float], arc: float) -> None:
    """One capture's row in the study CSV (a header when the file is new)."""
    record = {"shape": row["shape"], "background": row["background"], "views": views, "size": size,
              "elevations_deg": " ".join(f"{e:g}" for e in elevations), "arc_deg": arc,
              "support_plane": row["support_plane"], "stereo": row["stereo"], "matcher": row["matcher"],
              "max_features": row["max_features"], "rotation_deg": row.get("rot_deg_mean", ""),
              "mask_iou": row.get("iou_mean", ""), "mask_iou_min": row.get("iou_min", ""),
              **{k: row.get(k, "") for k in ("masks_below_08", "flagged_below_08", "flagged_above_09")},
              "chamfer_pct": row.get("chamfer_pct", ""),
              **{stage: row.get(stage, "") for stage in ("poses_s", "masks_s", "geometry_s", "uv_s")},
              "seconds": sum(v for k, v in row.items() if k.endswith("_s") and k != "render_s"),
              "error": row.get("error", "")}
    settings = {k: record[k] for k in ("shape", "background", "views", "size", "elevations_deg", "arc_deg",
                                       "support_plane", "stereo", "matcher", "max_features")}
    append_row(path, {k: f"{v:.4g}" if isinstance(v, float) else v for k, v in record.items()}, tuple(record),
               settings_hash(settings))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=list(SHAPES))
    parser.add_argument("--elevations", nargs="+", type=float, default=[15.0, 30.0],
                        help="camera ring elevations in degrees (all positive: nothing sees the underside)")
    parser.add_argument("--out", type=Path, default=CSV, help="CSV the rows are appended to")
    parser.add_argument("--support-plane", action=argparse.BooleanOptionalAction, default=True,
                        help="cut the hull at the plane under the object (GeometryConfig.support_plane)")
    parser.add_argument("--stereo", action=argparse.BooleanOptionalAction, default=True,
                        help="carve what multi-view stereo sees as empty inside the hull (GeometryConfig.stereo)")
    parser.add_argument("--parallax", action=argparse.BooleanOptionalAction, default=None,
                        help="seed the masks from the views' parallax (MaskConfig.parallax; default: the workflow's)")
    parser.add_argument("--backgrounds", nargs="+", default=["textured", "plain"])
    parser.add_argument("--arc", type=float, default=360.0, help="the cameras' sweep around the object, degrees")
    parser.add_argument("--wall-behind", type=float, default=None,
                        help="the textured backdrop's wall flat, this far behind the object (SynthConfig.wall_behind; "
                        "the object's radius is about 1, the cameras' distance 6)")
    parser.add_argument("--max-features", type=int, default=2048, help="SIFT features per image (SfMConfig)")
    parser.add_argument("--matcher", default="auto", help="SfMConfig.matcher: auto, exhaustive or sequential")
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
                wall = "" if args.wall_behind is None else f"_wall{args.wall_behind:g}"
                name = f"{shape}_{background}{wall}_{args.views}x{args.size}_{args.spp}spp_{args.arc:g}deg"
                root = Path(args.captures or tmp) / name
                cfg = SynthConfig(shape=shape, views=args.views, held_out_every=8, width=args.size, height=args.size,
                                  spp=args.spp, texture_size=256, camera_distance=6.0,
                                  elevations_deg=tuple(args.elevations), arc_deg=args.arc, albedo_detail=0.6,
                                  background=background, wall_behind=args.wall_behind, image_format="png",
                                  photos_only=True)
                start = time.perf_counter()
                if not (root / SYNTH_MARKER).is_file():
                    make_synthetic_capture(root, cfg, threads=args.threads, progress=False)
                render_s = time.perf_counter() - start
                try:
                    row = run_capture(root, Path(tmp) / f"work_{name}", args.threads,
                                      {"max_features": args.max_features, "matcher": args.matcher},
                                      {"support_plane": args.support_plane, "stereo": args.stereo},
                                      {} if args.parallax is None else {"parallax": args.parallax})
                except Exception as exc:  # a failing stage is a result too: its message, without the temporary folder
                    message = str(exc).replace(f"{tmp}/", "").replace(f"work_{name}/", "")
                    row = {"error": f"{type(exc).__name__}: {message[:160]}"}
                label = background if args.wall_behind is None else f"{background} wall {args.wall_behind:g} behind"
                rows.append({"shape": shape, "background": label, "render_s": render_s, **row})
                append_csv(args.out, {**rows[-1], "support_plane": args.support_plane, "stereo": args.stereo,
                                      "matcher": args.matcher, "max_features": args.max_features},
                           args.views, args.size, args.elevations, args.arc)
                print(tabulate([rows[-1]], headers="keys", floatfmt=".3g"), flush=True)
    print(f"\n{args.views} views of {args.size}x{args.size}, {args.spp} spp, {args.threads} threads")
    print(tabulate(rows, headers="keys", floatfmt=".3g"))


if __name__ == "__main__":
    main()
