"""Where every artefact of a run lives: the one place that builds a results path from its parts.

`Layout(results, captures)` names the run-wide files (summary, report, prior training) and each
scene's `SceneLayout` the files under `results/{scene}/`:

    capture.json                       validated capture
    undistorted/                       its views taken through a lens, as pinhole views (photos with distortion)
    mesh_given.ply                     its glTF mesh converted to PLY (captures with mesh.glb / mesh.gltf)
    poses/transforms.json, points.ply  cameras from structure from motion       (photo captures)
    masks/{view}.png                   foreground masks                          (photo captures)
    geometry/mesh.ply, mesh_uv.ply     carved surface, and with a UV atlas       (photo captures)
    init/                              initialisation: envmap.exr, textures, log.json
    {method}/{k}/                      posterior sample k: envmap.exr, textures, trace.json
    {method}/plan.json                 the sample stop rule's decision
    {method}/env_log_std.exr, albedo_std.exr, roughness_std.exr   per-texel spread across the method's samples
    {method}/env_mean.exr              the samples' geometric mean map (median luminance 1)
    eval/{method}/{k}.json             metrics of one sample (eval/init/0.json: the initialisation)
    eval/{method}/{k}/{view}.exr       its held-out views re-rendered by the evaluation
    eval/envmaps.png                   every method's env-map samples
    eval/uncertainty.png               every method's spread maps: where the photos do not tell
    logs/, benchmarks/                 one log and one timing file per job

The Snakemake rules, the `dpi` command, the stages, the report and the benchmarks all ask this
module; a rule's wildcard pattern is the same call with "{scene}", "{method}" and "{k}" as arguments.
It imports nothing from dpi, so every module can use it.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

INIT = "init"
"""the initialisation's name where a method's would stand (eval/init/0.json, summary rows)"""
ENV_FILE = "envmap.exr"
TEXTURE_NAMES = ("albedo", "roughness", "metallic")
SAMPLE_TRACE = "trace.json"
INIT_TRACE = "log.json"
SYNTH_MARKER = ".synth.json"
"""written last into a synthetic capture folder, with the parameters it was rendered with"""
SUMMARY_FILE = "summary.json"
"""each preprocessing stage's counts, errors and seconds, next to its outputs"""


def package_data(*parts: str) -> Path:
    """A file shipped inside the dpi package (dpi/data/...): the default config and its schema, the prior
    models, NIQE's pristine model. Found through importlib.resources, so an installed wheel finds them too."""
    return Path(str(files("dpi").joinpath("data", *parts)))


def texture_file(name: str) -> str:
    """File name of a material texture (albedo, roughness, metallic) in a decomposition folder."""
    return f"{name}.exr"


def view_file(folder: str | Path, view: str) -> Path:
    """A rendered view in a folder of views (the evaluation's held-out renders)."""
    return Path(folder) / f"{view}.exr"


def decomposition_files(folder: str | Path, trace: str = SAMPLE_TRACE) -> dict[str, Path]:
    """The files of a decomposition folder: env, albedo, roughness, metallic and its trace."""
    folder = Path(folder)
    return {"env": folder / ENV_FILE, **{name: folder / texture_file(name) for name in TEXTURE_NAMES},
            "trace": folder / trace}


def poses_files(folder: str | Path) -> dict[str, Path]:
    """The poses stage's outputs: cameras (transforms.json), sparse points (points.ply) and its summary."""
    folder = Path(folder)
    return {"cameras": folder / "transforms.json", "points": folder / "points.ply", "summary": folder / SUMMARY_FILE}


def geometry_files(folder: str | Path) -> dict[str, Path]:
    """The geometry and uv stages' outputs: the carved mesh, its summary, and the mesh with a UV atlas."""
    folder = Path(folder)
    return {"mesh": folder / "mesh.ply", "summary": folder / SUMMARY_FILE, "mesh_uv": folder / "mesh_uv.ply",
            "uv_summary": folder / "uv_summary.json"}


@dataclass(frozen=True)
class SceneLayout:
    """The files of one scene under results/{scene}/."""

    root: Path

    @property
    def capture_json(self) -> Path:
        return self.root / "capture.json"

    @property
    def poses_dir(self) -> Path:
        return self.root / "poses"

    @property
    def poses(self) -> dict[str, Path]:
        return poses_files(self.poses_dir)

    @property
    def masks(self) -> Path:
        return self.root / "masks"

    @property
    def geometry_dir(self) -> Path:
        return self.root / "geometry"

    @property
    def geometry(self) -> dict[str, Path]:
        return geometry_files(self.geometry_dir)

    @property
    def working_dir(self) -> Path:
        """Images and masks at the working resolution (dpi.capture.working), a folder per size."""
        return self.root / "working"

    @property
    def given_mesh_ply(self) -> Path:
        """The capture's glTF mesh converted to PLY (dpi.capture.mesh_convert)."""
        return self.root / "mesh_given.ply"

    @property
    def undistorted_dir(self) -> Path:
        """Images and masks of views taken through a lens, undistorted to pinhole views (dpi.capture.undistort)."""
        return self.root / "undistorted"

    def sample_dir(self, method: str, k: int | str = 0) -> Path:
        """Folder of posterior sample k of a method; the initialisation's for method `init`."""
        return self.root / INIT if method == INIT else self.root / method / str(k)

    def other_reading_dir(self) -> Path:
        """The init's other reading, where some samples start from it (dpi.solve.init: both readings explain the
        views about equally)."""
        return self.root / INIT / "other"

    def sample_files(self, method: str, k: int | str = 0) -> dict[str, Path]:
        """decomposition_files of a sample folder, with the trace the stage writes there."""
        return decomposition_files(self.sample_dir(method, k), INIT_TRACE if method == INIT else SAMPLE_TRACE)

    def plan(self, method: str) -> Path:
        """The sample stop rule's plan of a method."""
        return self.root / method / "plan.json"

    def evaluation(self, method: str, k: int | str = 0) -> Path:
        """Metrics of sample k of a method (of the initialisation for method `init`)."""
        return self.root / "eval" / method / f"{k}.json"

    def evaluation_views(self, method: str, k: int | str = 0) -> Path:
        """Folder of the held-out views the evaluation rendered with sample k, one {view}.exr each."""
        return self.root / "eval" / method / str(k)

    def evaluation_log(self, method: str, k: int | str = 0) -> Path:
        """Log of the evaluation job of sample k of a method (of the initialisation for method `init`)."""
        return self.log("eval", method) if method == INIT else self.log("eval", method, str(k))

    def uncertainty(self, method: str) -> dict[str, Path]:
        """A method's maps across its samples (dpi.solve.spread): env log-luminance std, albedo std, and the env maps'
        geometric mean (what they share)."""
        return {"env": self.root / method / "env_log_std.exr", "albedo": self.root / method / "albedo_std.exr",
                "roughness": self.root / method / "roughness_std.exr",
                "env_mean": self.root / method / "env_mean.exr"}

    @property
    def export_dir(self) -> Path:
        """The scene's assets for other tools (dpi.export)."""
        return self.root / "export"

    def export_asset(self, suffix: str) -> Path:
        """The scene's asset of a format: export/{scene}.glb, export/{scene}.usda."""
        return self.export_dir / f"{self.root.name}.{suffix}"

    def export_envmap(self, label: str, suffix: str) -> Path:
        """A sample's env map beside the assets: export/envmaps/{method}_{k}.hdr (and .exr)."""
        return self.export_dir / "envmaps" / f"{label}.{suffix}"

    def export_texture(self, label: str, texture: str) -> Path:
        """A sample's texture as the USD stage reads it: export/textures/{method}_{k}_{texture}.png."""
        return self.export_dir / "textures" / f"{label}_{texture}.png"

    @property
    def envmap_figure(self) -> Path:
        return self.root / "eval" / "envmaps.png"

    @property
    def uncertainty_figure(self) -> Path:
        return self.root / "eval" / "uncertainty.png"

    def log(self, *parts: str) -> Path:
        """A job's log file: logs/{parts}.log."""
        return (self.root / "logs").joinpath(*parts).with_suffix(".log")

    def benchmark(self, *parts: str) -> Path:
        """A job's timing file (Snakemake `benchmark:`): benchmarks/{parts}.tsv."""
        return (self.root / "benchmarks").joinpath(*parts).with_suffix(".tsv")


@dataclass(frozen=True)
class Layout:
    """Capture folders under `captures`, every result under `results` (config keys captures_dir, results_dir)."""

    results: Path
    captures: Path

    @classmethod
    def from_config(cls, config: dict) -> "Layout":
        """The layout of a resolved config."""
        return cls(Path(config["results_dir"]), Path(config["captures_dir"]))

    def problem(self, scenes: list[str]) -> str | None:
        """Why results and captures cannot share this layout, or None: a scene named like one of the run's own
        entries of results_dir (eval/, logs/, report.html, ...), results_dir equal to captures_dir or inside a
        scene's capture folder (a run would write into the inputs)."""
        run = {path.relative_to(self.results).parts[0] for path in (
            self.summary, self.samples_table, self.report_html, self.report_figures, self.log("run"),
            self.prior_data("family"), self.prior_dir("family"), self.study_dir("study"))}
        for scene in scenes:
            if scene in run:
                return f"scenes: {scene!r} is the name of a folder results_dir keeps for the run; rename the scene"
        results, captures = self.results.resolve(), self.captures.resolve()
        if results == captures:
            return f"results_dir: {self.results} is captures_dir; results go to a folder of their own"
        for scene in scenes:
            if results.is_relative_to(self.capture_dir(scene).resolve()):
                return f"results_dir: {self.results} lies inside the capture folder of scene {scene!r}; " \
                       "captures are never written"
        return None

    def capture_dir(self, scene: str) -> Path:
        """Input folder of a scene (never written, except by `dpi synth` for a synthetic scene)."""
        return self.captures / scene

    def synth_marker(self, scene: str) -> Path:
        return self.capture_dir(scene) / SYNTH_MARKER

    def scene(self, scene: str) -> SceneLayout:
        return SceneLayout(self.results / scene)

    @property
    def summary(self) -> Path:
        """Metrics per scene and method, aggregated over samples."""
        return self.results / "eval" / "summary.csv"

    @property
    def samples_table(self) -> Path:
        """The same metrics per sample."""
        return self.results / "eval" / "samples.csv"

    @property
    def report_html(self) -> Path:
        return self.results / "report.html"

    @property
    def report_figures(self) -> Path:
        return self.results / "report"

    def log(self, name: str) -> Path:
        """Log of a run-wide job (summary, report)."""
        return self.results / "logs" / f"{name}.log"

    def prior_data(self, family: str) -> Path:
        """Procedural env-map dataset of a prior family."""
        return self.results / "prior_data" / family

    def prior_dir(self, family: str) -> Path:
        return self.results / "prior" / family

    def study_dir(self, name: str) -> Path:
        """A study's folder (benchmarks/*.py): its own run, laid out as `Layout.of_study` says."""
        return self.results / "benchmarks" / name

    @classmethod
    def of_study(cls, root: Path) -> "Layout":
        """The run in study folder `root`: its captures/ and results/ side by side."""
        return cls(root / "results", root / "captures")

    def prior_model(self, family: str) -> Path:
        """A prior trained by the workflow (EMA weights), usable in illumination_prior.checkpoints."""
        return self.prior_dir(family) / "model.pt"

    def prior_checkpoint(self, family: str) -> Path:
        """The resumable training checkpoint behind prior_model."""
        return self.prior_dir(family) / "train" / "checkpoint.pt"

    def prior_log(self, family: str, job: str) -> Path:
        return self.prior_dir(family) / "logs" / f"{job}.log"

    def prior_benchmark(self, family: str, job: str) -> Path:
        return self.prior_dir(family) / "benchmarks" / f"{job}.tsv"
