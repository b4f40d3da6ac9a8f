"""The `dpi` command: every pipeline stage runnable without Snakemake.

    dpi synth captures/demo --shape blob --views 16
    dpi validate captures/demo --out results/demo/capture.json
    dpi init results/demo/capture.json results/demo/init
    dpi sample results/demo/capture.json results/demo/init results/demo/none/0 --method none --k 0
    dpi evaluate results/demo/capture.json results/demo/none/0 results/demo/eval/none/0.json
    dpi summary results/demo/eval/*/*.json --out results/eval/summary.csv
    dpi relight results/demo/capture.json results/demo/dps/0 results/demo/relit --envmap sky.exr --orbit 8
    dpi preprocess captures/myobject results/myobject --threads 2
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path

import yaml

from dpi.capture import CaptureError
from dpi.preprocess.sfm import SfMError
from dpi.prior.cli import register as register_prior_commands

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "config.yaml"


def _config(path: str | None) -> dict:
    """Parsed config.yaml (the workflow's) or {} when none is found."""
    candidate = Path(path) if path else DEFAULT_CONFIG
    return yaml.safe_load(candidate.read_text()) if candidate.is_file() else {}


def _settings(args: argparse.Namespace):
    from dpi.stages import SolveSettings

    return SolveSettings.from_config(_config(args.config), args.threads)


def cmd_synth(args: argparse.Namespace) -> None:
    """Render a synthetic capture with ground truth."""
    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    values = {f.name: getattr(args, f.name) for f in fields(SynthConfig) if getattr(args, f.name, None) is not None}
    make_synthetic_capture(args.out, SynthConfig.from_dict(values), threads=args.threads)
    print(f"wrote {args.out}")


def cmd_validate(args: argparse.Namespace) -> None:
    """Validate a capture folder; optionally write capture.json."""
    from dpi.capture import load_capture, write_capture_json

    capture = load_capture(args.capture)
    if args.out:
        write_capture_json(capture, args.out)
    print(f"{args.capture}: {len(capture.views)} views ({len(capture.held_out_views)} held out), "
          f"provenance {json.dumps(capture.provenance)}")


def cmd_init(args: argparse.Namespace) -> None:
    """Path-traced initialisation."""
    from dpi.stages import init_stage

    init_stage(args.capture_json, args.out, args.scene, _config(args.config).get("init", {}), _settings(args))


def cmd_sample(args: argparse.Namespace) -> None:
    """One posterior sample of a method."""
    from dpi.stages import sample_stage

    method_cfg = dict(_config(args.config).get("method_params", {}).get(args.method, {}))
    method_cfg.pop("samples", None)
    sample_stage(args.capture_json, args.init, args.out, args.scene, args.method, args.k, method_cfg,
                 _settings(args))


def cmd_evaluate(args: argparse.Namespace) -> None:
    """Metrics of one sample."""
    from dpi.stages import evaluate_stage

    spp = _config(args.config).get("evaluate", {}).get("spp", 64)
    evaluate_stage(args.capture_json, args.sample, args.out, args.scene, args.method, args.k, spp, _settings(args))


def cmd_summary(args: argparse.Namespace) -> None:
    """Aggregate metric files into a CSV table."""
    from dpi.stages import summary_stage

    summary_stage(args.evals, args.out, args.samples_out)


def cmd_relight(args: argparse.Namespace) -> None:
    """Re-render a decomposition under a new environment map, from new views, with material edits."""
    from dataclasses import replace

    from dpi.relight import MaterialEdit, RelightConfig, relight_sample

    edit = MaterialEdit(args.albedo_scale, args.roughness, args.metallic)
    cfg = RelightConfig(args.envmap, args.rotate_deg, args.env_height, args.orbit, args.orbit_elevation_deg,
                        args.exposure, args.seed, edit)
    render = replace(_settings(args).render, spp=args.spp)
    names = relight_sample(args.capture_json, args.sample, args.out, cfg, render)
    print(f"wrote {len(names)} views to {args.out}")


def cmd_preprocess(args: argparse.Namespace) -> None:
    """Derive the cameras, masks, mesh and UV atlas a capture lacks (the workflow's preprocessing)."""
    from dpi.capture import inspect_capture
    from dpi.preprocess.stages import STAGES, needed_stages, preprocess_capture

    stages = needed_stages(inspect_capture(args.capture))
    if args.dry_run:
        for stage in STAGES:
            print(f"{stage:9s} {'run' if stage in stages else 'skipped: given by the capture'}")
        return
    config = _config(args.config)
    threads = args.threads or config.get("threads", {}).get("preprocess", 1)
    report = preprocess_capture(args.capture, args.out, config.get("preprocess", {}), threads)
    for stage, summary in report.items():
        print(f"{stage:9s} " + ("given" if summary == "given" else f"derived in {summary.get('seconds', 0):.1f} s"))
    print(f"wrote {args.out}")


def _rgb(text: str) -> tuple[float, float, float]:
    """R,G,B (or one value for all three) as three floats."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R,G,B numbers, got {text!r}") from None
    if len(values) not in (1, 3):
        raise argparse.ArgumentTypeError(f"expected one or three numbers, got {text!r}")
    return tuple(values * 3 if len(values) == 1 else values)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the `dpi` command."""
    parser = argparse.ArgumentParser(prog="dpi", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    def add(name: str, fn, help_text: str, capture_json: bool = False) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(fn=fn)
        p.add_argument("--threads", type=int, default=None, help="CPU threads (Dr.Jit and torch; COLMAP and OpenCV)")
        p.add_argument("--config", default=None, help="config.yaml with render/problem/stage settings")
        if capture_json:
            p.add_argument("capture_json", help="capture.json written by `dpi validate --out`")
        return p

    p = add("synth", cmd_synth, "render a synthetic capture with ground truth")
    p.add_argument("out", help="capture folder to create")
    p.add_argument("--shape", choices=("blob", "bumpy_torus"))
    for name, typ in (("views", int), ("width", int), ("height", int), ("spp", int), ("env_height", int),
                      ("texture_size", int), ("held_out_every", int), ("seed", int), ("roughness", float),
                      ("metallic", float), ("sun_elevation_deg", float), ("sun_azimuth_deg", float),
                      ("turbidity", float)):
        p.add_argument(f"--{name.replace('_', '-')}", dest=name, type=typ)
    p.add_argument("--envmap", help="EXR to use as ground-truth illumination instead of a procedural sky")
    p.add_argument("--image-format", dest="image_format", choices=("exr", "png"))
    p.add_argument("--prior", choices=("outdoor", "indoor"))

    p = add("validate", cmd_validate, "validate a capture folder")
    p.add_argument("capture", help="capture folder")
    p.add_argument("--out", help="write the normalised capture.json here")

    p = add("init", cmd_init, "path-traced initialisation", capture_json=True)
    p.add_argument("out", help="output folder (envmap.exr, albedo/roughness/metallic.exr, log.json)")
    p.add_argument("--scene", default="scene", help="scene name (seeds the run)")

    p = add("sample", cmd_sample, "one posterior sample of a method", capture_json=True)
    p.add_argument("init", help="init folder")
    p.add_argument("out", help="output folder")
    p.add_argument("--method", required=True)
    p.add_argument("--k", type=int, default=0, help="sample index (seeds the run)")
    p.add_argument("--scene", default="scene")

    p = add("evaluate", cmd_evaluate, "metrics of one sample", capture_json=True)
    p.add_argument("sample", help="sample folder")
    p.add_argument("out", help="metrics JSON to write")
    p.add_argument("--method", default="method")
    p.add_argument("--k", type=int, default=0)
    p.add_argument("--scene", default="scene")

    p = add("summary", cmd_summary, "aggregate metric JSONs into summary.csv")
    p.add_argument("evals", nargs="+", help="per-sample metric JSON files")
    p.add_argument("--out", required=True)
    p.add_argument("--samples-out", dest="samples_out", default=None, help="also write per-sample rows here")

    p = add("relight", cmd_relight, "re-render a decomposition under a new environment map and/or from new "
            "views, optionally with edited materials (relighting, material editing)", capture_json=True)
    p.add_argument("sample", help="decomposition folder (envmap.exr, albedo/roughness/metallic.exr), e.g. "
                   "results/demo/dps/0 or results/demo/init")
    p.add_argument("out", help="output folder: {view}.exr (linear) and {view}.png (sRGB) per view, relight.json")
    p.add_argument("--envmap", help="EXR environment map to light with, any size (resampled to H x 2H); "
                   "default: the decomposition's own")
    p.add_argument("--rotate", dest="rotate_deg", type=float, default=0.0, metavar="DEG",
                   help="turn the environment by DEG degrees about the up (+Y) axis, "
                   "counter-clockwise seen from above")
    p.add_argument("--env-height", dest="env_height", type=int, metavar="H",
                   help="resample the map to H x 2H (default: the decomposition's map height)")
    p.add_argument("--orbit", type=int, default=0, metavar="N",
                   help="render N cameras on a ring around the object instead of the capture's cameras")
    p.add_argument("--orbit-elevation", dest="orbit_elevation_deg", type=float, default=20.0, metavar="DEG",
                   help="elevation of the orbit cameras (default 20)")
    p.add_argument("--albedo-scale", dest="albedo_scale", type=_rgb, metavar="R,G,B",
                   help="multiply the albedo per channel (one value scales all three)")
    p.add_argument("--roughness", type=float, help="replace the roughness texture by this value")
    p.add_argument("--metallic", type=float, help="replace the metallic texture by this value")
    p.add_argument("--spp", type=int, default=64, help="samples per pixel (default 64)")
    p.add_argument("--exposure", type=float, default=1.0, help="exposure of the PNGs (the EXRs stay linear)")
    p.add_argument("--seed", type=int, default=0, help="sampler seed")

    p = add("preprocess", cmd_preprocess, "derive what a photo capture lacks (cameras, masks, mesh, UV atlas) "
            "without Snakemake")
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.description = """Derive what a capture lacks, as the workflow's rules poses -> masks -> geometry -> uv do,
skipping every stage whose output the capture gives:

  poses     COLMAP structure from motion     runs without transforms.json / camera.xml
  masks     colour keying or GrabCut         runs without masks/
  geometry  voxel carving + mesh clean-up    runs without mesh.ply / mesh.obj
  uv        xatlas UV atlas                  runs without a mesh that has UVs

Writes OUT/capture.json, OUT/poses/, OUT/masks/, OUT/geometry/mesh.ply and mesh_uv.ply, with each
stage's summary (JSON): the layout of the workflow's results/{scene}/, so `dpi init OUT/capture.json ...`
reads the derived inputs. Settings come from the `preprocess:` section of --config (default: the
repository's config.yaml), --threads (COLMAP and OpenCV threads) from its threads.preprocess. A
known focal length in pixels belongs in the capture's scene.yaml (focal_length_px). Every needed
stage runs again on each call; the workflow caches them."""
    p.add_argument("capture", metavar="CAPTURE", help="capture folder: images/ and whatever else it gives")
    p.add_argument("out", metavar="OUT", help="results folder to write (e.g. results/myobject)")
    p.add_argument("-n", "--dry-run", dest="dry_run", action="store_true",
                   help="only list which stages would run and which the capture makes unnecessary")

    register_prior_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point: one clear message (not a traceback) for invalid input."""
    args = build_parser().parse_args(argv)
    try:
        args.fn(args)
    except (CaptureError, FileExistsError, ValueError, SfMError) as exc:
        print(f"dpi {args.command}: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
