"""The `dpi` command: every stage of the workflow on a scene, without Snakemake.

    dpi config                          # the resolved settings, every default filled in
    dpi capture demo                    # (render the synthetic scene, then) validate: results/demo/capture.json
    dpi preprocess myobject             # the cameras, masks, mesh and UVs a photo capture lacks
    dpi init demo
    dpi sample demo dps 0
    dpi evaluate demo dps 0             # (`dpi evaluate demo init` scores the initialisation)
    dpi summary                         # results/eval/summary.csv over the config's scenes and methods
    dpi report                          # the env-map figures and results/report.html
    dpi export demo                     # results/demo/export/demo.glb and demo.usda, every sample a variant

A stage command reads and writes what its Snakemake rule does (dpi.io.layout) with the settings the
workflow resolves (dpi.config.pipeline): dpi's defaults, ./config.yaml when present, then each `--config`
file, so `snakemake --configfile my.yaml` and `dpi ... --config my.yaml` give the same files. The
tools work on paths:

    dpi synth captures/torus --shape bumpy_torus --views 24
    dpi validate captures/torus --out results/torus/capture.json
    dpi relight results/demo/capture.json results/demo/dps/0 results/demo/relit --envmap sky.exr --orbit 8
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path

import yaml

from dpi.capture import PRIORS, CaptureError
from dpi.config.validation import ConfigError
from dpi.io.lock import ResultsLocked
from dpi.preprocess.sfm import SfMError
from dpi.prior.commands import register as register_prior_commands


def _pipeline(args: argparse.Namespace):
    """The resolved config of the command's --config files; a command on a scene (other than a dry run) holds its
    results folder's lock (dpi.io.lock) while it runs, and refuses a results folder with a link inside it
    (dpi.io.atomic.check_no_links)."""
    from dpi.config.pipeline import load_pipeline
    from dpi.io.atomic import check_no_links
    from dpi.io.lock import lock_results

    pipeline = load_pipeline(args.config)
    if getattr(args, "scene", None) is not None and not getattr(args, "dry_run", False):
        lock_results(pipeline.layout.results)
        check_no_links(pipeline.layout.results)
    return pipeline


def _job(args: argparse.Namespace, kind: str, method: str | None = None, k: int = 0):
    """The stage job record of a command on a scene, as its rule builds it: the resolved config, the scene,
    method and sample, and --threads, else the config's threads of the job kind (as the workflow's job has)."""
    from dpi.stages import INIT, StageJob

    pipeline = _pipeline(args)
    return StageJob(pipeline, getattr(args, "scene", None), method or INIT, k,
                    threads=args.threads or pipeline.threads(kind))


def cmd_config(args: argparse.Namespace) -> None:
    """Print the resolved config, or with --schema the JSON schema it is checked against."""
    if args.schema:
        from dpi.config.pipeline import CONFIG_SCHEMA
        from dpi.config.validation import config_schema

        print(json.dumps(config_schema(CONFIG_SCHEMA), indent=1))
        return
    print(yaml.safe_dump(_pipeline(args).describe(), sort_keys=False), end="")


def cmd_synth(args: argparse.Namespace) -> None:
    """Render a synthetic capture with ground truth."""
    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    values = {f.name: getattr(args, f.name) for f in fields(SynthConfig) if getattr(args, f.name, None) is not None}
    make_synthetic_capture(args.out, SynthConfig.from_dict(values), threads=args.threads)
    print(f"wrote {args.out}")


def cmd_validate(args: argparse.Namespace) -> None:
    """Validate a capture folder; optionally write capture.json as the capture stage does (distortion removed
    and a glTF mesh converted beside it)."""
    from dpi.capture import load_capture, read_capture_json
    from dpi.preprocess.derive import normalise_capture

    if args.out:
        normalise_capture(args.capture, args.out)
        capture = read_capture_json(args.out)
    else:
        capture = load_capture(args.capture)
    print(f"{args.capture}: {len(capture.views)} views ({len(capture.held_out_views)} held out), "
          f"provenance {json.dumps(capture.provenance)}")


def cmd_capture(args: argparse.Namespace) -> None:
    """Rules synth_capture (a synthetic scene whose folder is missing) and capture."""
    from dpi.stages import capture_stage, synth_capture_stage

    job = _job(args, "synth")
    if job.pipeline.is_synthetic(job.scene) and not job.pipeline.layout.synth_marker(job.scene).is_file():
        synth_capture_stage(job)
    capture_stage(job)
    print(f"wrote {job.paths.capture_json}")


def cmd_preprocess(args: argparse.Namespace) -> None:
    """The rules capture, poses, masks, geometry and uv for what a capture lacks."""
    from dpi.stages import STAGES, needed_stages, preprocess_scene

    job = _job(args, "preprocess")
    stages = needed_stages(job.given)
    if args.dry_run:
        for stage in STAGES:
            print(f"{stage:9s} {'run' if stage in stages else 'skipped: given by the capture'}")
        return
    report = preprocess_scene(job)
    for stage, summary in report.items():
        print(f"{stage:9s} " + ("given" if summary == "given" else f"derived in {summary.get('seconds', 0):.1f} s"))
    print(f"wrote {job.paths.root}")


def cmd_init(args: argparse.Namespace) -> None:
    """Rule init."""
    from dpi.stages import init_stage

    init_stage(_job(args, "init"))


def cmd_sample(args: argparse.Namespace) -> None:
    """Rule sample."""
    from dpi.stages import sample_stage

    sample_stage(_job(args, "sample", args.method, args.k))


def cmd_evaluate(args: argparse.Namespace) -> None:
    """Rules evaluate and evaluate_init."""
    from dpi.stages import evaluate_stage

    evaluate_stage(_job(args, "evaluate", args.method, args.k))


def existing_evaluations(pipeline) -> list[Path]:
    """The metric files present of the config's scenes: the initialisation and each method's samples."""
    from dpi.io.layout import INIT

    paths = []
    for name in pipeline.scenes:
        scene = pipeline.layout.scene(name)
        paths += [scene.evaluation(INIT)] + [scene.evaluation(m, k) for m in pipeline.methods
                                             for k in range(pipeline.samples(m))]
    return [p for p in paths if p.is_file()]


def cmd_summary(args: argparse.Namespace) -> None:
    """Rule summary, over the metric files present."""
    from dpi.stages import summary_stage

    job = _job(args, "evaluate")
    pipeline = job.pipeline
    evaluations = existing_evaluations(pipeline)
    if not evaluations:
        raise ValueError(f"no metric files of scenes {', '.join(pipeline.scenes)} under {pipeline.layout.results}")
    summary_stage(job, evaluations)
    print(f"wrote {pipeline.layout.summary} ({len(evaluations)} samples)")


def present_samples(job) -> list[tuple[str, list[Path]]]:
    """Per method of the config with samples present in the job's scene, the folders of those samples (what the
    workflow's rules take from the stop rule's plans)."""
    rows = [(m, [job.paths.sample_dir(m, k) for k in range(job.pipeline.samples(m))
                 if job.paths.sample_files(m, k)["albedo"].is_file()]) for m in job.pipeline.methods]
    return [(m, folders) for m, folders in rows if folders]


def cmd_report(args: argparse.Namespace) -> None:
    """Rules envmap_figure and uncertainty (each scene, over the samples present) and report."""
    from dataclasses import replace

    from dpi.io.layout import ENV_FILE
    from dpi.stages import envmap_figure_stage, report_stage, uncertainty_stage

    run = _job(args, "evaluate")
    pipeline = run.pipeline
    for name in pipeline.scenes:
        job = replace(run, scene=name)
        present = present_samples(job)
        envmap_figure_stage(job, [(m, [folder / ENV_FILE for folder in folders]) for m, folders in present])
        spread = [(m, folders) for m, folders in present if len(folders) >= 2]
        if spread:
            uncertainty_stage(job, spread)
    report_stage(run)
    print(f"wrote {pipeline.layout.report_html}")


def cmd_export(args: argparse.Namespace) -> None:
    """Rule export, over the samples present."""
    from dpi.stages import export_stage

    job = _job(args, "evaluate")
    export_stage(job, present_samples(job))


def cmd_relight(args: argparse.Namespace) -> None:
    """Re-render a decomposition under a new environment map, from new views, with material edits."""
    from dataclasses import replace

    from dpi.export.relight import MaterialEdit, RelightConfig, relight_sample

    edit = MaterialEdit(args.albedo_scale, args.roughness, args.metallic)
    cfg = RelightConfig(args.envmap, args.rotate_deg, args.env_height, args.orbit, args.orbit_elevation_deg,
                        args.exposure, edit)
    render = replace(_pipeline(args).solve_settings(args.threads).render, spp=args.spp)
    names = relight_sample(args.capture_json, args.sample, args.out, cfg, render)
    print(f"wrote {len(names)} views to {args.out}")


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
    from dpi.io.layout import INIT
    from dpi.solve.methods import METHODS

    parser = argparse.ArgumentParser(prog="dpi", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    def add(name: str, fn, help_text: str, scene: bool = False) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(fn=fn)
        p.add_argument("--threads", type=int, default=None,
                       help="CPU threads (Dr.Jit and torch; COLMAP and OpenCV); default: the config's for the job")
        p.add_argument("--config", action="append", default=[], metavar="FILE",
                       help="settings merged over dpi's defaults and ./config.yaml, in order (repeatable)")
        if scene:
            p.add_argument("scene", help="scene name: its capture is captures_dir/SCENE, its results results_dir/SCENE")
        return p

    p = add("config", cmd_config, "print the resolved config (defaults, ./config.yaml, --config files, preset)")
    p.add_argument("--schema", action="store_true",
                   help="print the JSON schema the config is checked against (each field's bounds and default)")

    p = add("synth", cmd_synth, "render a synthetic capture with ground truth into a folder")
    p.add_argument("out", help="capture folder to create")
    p.add_argument("--shape", choices=("blob", "bumpy_torus"))
    for name, typ in (("views", int), ("width", int), ("height", int), ("spp", int), ("env_height", int),
                      ("texture_size", int), ("held_out_every", int), ("seed", int), ("roughness", float),
                      ("metallic", float), ("sun_elevation_deg", float), ("sun_azimuth_deg", float)):
        p.add_argument(f"--{name.replace('_', '-')}", dest=name, type=typ)
    p.add_argument("--environment", help="ground-truth light: sunsky (default), outdoor, indoor (procedural), or a "
                   "panorama file (.exr, .hdr)")
    p.add_argument("--image-format", dest="image_format", choices=("exr", "png"))
    p.add_argument("--prior", choices=PRIORS)

    p = add("validate", cmd_validate, "validate a capture folder")
    p.add_argument("capture", help="capture folder")
    p.add_argument("--out", help="write the normalised capture.json here")

    add("capture", cmd_capture, "validate a scene's capture into its capture.json (rendering a synthetic scene "
        "of the config first when its folder is missing)", scene=True)

    p = add("preprocess", cmd_preprocess, "derive what a photo capture lacks (cameras, masks, mesh, UV atlas)",
            scene=True)
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.description = """Derive what a scene's capture lacks, as the workflow's rules poses -> masks -> geometry ->
uv do, skipping every stage whose output the capture gives:

  poses     COLMAP structure from motion     runs without transforms.json / camera.xml
  masks     colour keying or GrabCut         runs without masks/
  geometry  voxel carving + mesh clean-up    runs without mesh.ply / mesh.obj
  uv        xatlas UV atlas                  runs without a mesh that has UVs

Writes capture.json, poses/, masks/, geometry/mesh.ply and mesh_uv.ply, with each stage's summary, into
the scene's results folder, so `dpi init SCENE` reads the derived inputs. Settings come from the config's
`preprocess:` section, --threads (COLMAP and OpenCV threads) from its threads.preprocess. A known focal
length in pixels belongs in the capture's scene.yaml (focal_length_px). Every needed stage runs again on
each call; the workflow caches them."""
    p.add_argument("-n", "--dry-run", dest="dry_run", action="store_true",
                   help="only list which stages would run and which the capture makes unnecessary")

    add("init", cmd_init, "path-traced initialisation of a scene", scene=True)

    p = add("sample", cmd_sample, "posterior sample K of a method", scene=True)
    p.add_argument("method", choices=METHODS)
    p.add_argument("k", type=int, nargs="?", default=0, help="sample index (seeds the run; default 0)")

    p = add("evaluate", cmd_evaluate, f"metrics of sample K of a method ({INIT}: of the initialisation)", scene=True)
    p.add_argument("method", choices=(INIT, *METHODS))
    p.add_argument("k", type=int, nargs="?", default=0, help="sample index (default 0)")

    add("summary", cmd_summary, "aggregate the config's metric files into summary.csv and samples.csv")
    add("report", cmd_report, "the env-map figure of each scene and the HTML report")

    add("export", cmd_export, "the scene's samples as one glTF (.glb) and one USD (.usda) asset, every sample a "
        "variant, with their env maps beside them (results/SCENE/export/)", scene=True)

    p = add("relight", cmd_relight, "re-render a decomposition under a new environment map and/or from new "
            "views, optionally with edited materials (relighting, material editing)")
    p.add_argument("capture_json", help="capture.json of the scene (results/SCENE/capture.json)")
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

    register_prior_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point: one clear message (not a traceback) for invalid input."""
    args = build_parser().parse_args(argv)
    try:
        args.fn(args)
    except (CaptureError, ConfigError, FileExistsError, FileNotFoundError, ValueError, SfMError, ResultsLocked) as exc:
        print(f"dpi {args.command}: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
