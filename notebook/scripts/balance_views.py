"""Which broad balance of light the training views prefer, and which part of a decomposition carries it (issue 77).

    .venv/bin/python notebook/scripts/balance_views.py [--work results/benchmarks/light_dev ...] [--scenes ...]
        [--samples dps_proximal] [--out notebook/results/balance_views.csv]

For each scene of the study folders (`posterior_study.py --dev`'s, the posterior study's) with a true map and true
textures, the training views' transport is recorded as a dps sample records it (dpi.solve.dps.data_term: under the
sample's starting materials, guided by the init's map), and each row is one albedo: the samples' grey start, the
init's, the truth's; then the truth's under transports recorded with the true roughness (`truth_roughness`), the
true metallic (`truth_metallic`) or both (`truth_materials`) in place of the start's: what the start's reading of
each costs. Its columns:
- the relative data loss at the exposure's optimum (the share of the views' energy left unexplained) of the true map
  (`loss_true`), of the true map with the init's 2-row balance (`loss_init_balance`) and with a flat 2-row balance
  (`loss_flat`): the balance the views prefer under that albedo;
- `field`: the albedo's broad field over the object's normals (the RMS slope of its log luminance on the smooth
  normal, over the dielectric texels), the part of the light's balance an albedo can hold; a row `samples` gives the
  mean field of the `--samples` folder's albedos (no losses).
The CSV is rewritten whole; it prints the rows.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from dpi.capture import read_ground_truth
from dpi.config.pipeline import Pipeline
from dpi.evaluation.truth import true_materials
from dpi.io.exr import read_exr
from dpi.io.images import luminance, resize
from dpi.io.layout import INIT
from dpi.render.texels import chart_of, texel_values, texture_from
from dpi.solve.dps.start import glossy_start, sample_start_materials, start_transport
from dpi.solve.init import METAL_TEXEL
from dpi.solve.materials import MaterialTextures
from dpi.solve.transport import LightTransport, record_transport
from dpi.stages.inverse import load_problem
from dpi.studies.engine import work_dir, workflow_config, write_rows
from dpi.studies.scenes import STUDY_SCENES, drawn_scenes

BALANCE_ROWS = 2
"""rows of the balance swapped between maps: sky against ground, four sides"""
SEED = 97
"""the transport's recording seed"""


def normal_texture(problem, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(size, size, 3) unit smooth normals of the problem's mesh in texture space, and its chart texels (size, size)."""
    mesh = problem.mesh
    covered, normals = texel_values(mesh["uvs"].astype(np.float64), mesh["faces"], mesh["normals"].astype(np.float64),
                                    size)
    normals = texture_from(covered, normals)
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    return normals, chart_of(covered)


def coarse_log(env: torch.Tensor) -> torch.Tensor:
    """(1, 3, rows, 2 rows) log of the map area-averaged to BALANCE_ROWS rows."""
    return torch.nn.functional.interpolate(env.permute(2, 0, 1)[None], size=(BALANCE_ROWS, 2 * BALANCE_ROWS),
                                           mode="area").clamp_min(1e-12).log()


def with_balance(env: torch.Tensor, balance: torch.Tensor) -> torch.Tensor:
    """`env` (H, 2H, 3; H a multiple of BALANCE_ROWS) with its coarse log balance moved to `balance` (per channel, up to
    its mean): each coarse cell scaled by one factor, so the finer detail is kept and the coarse balance is exact."""
    change = balance - coarse_log(env)
    change = change - change.mean(dim=(2, 3), keepdim=True)
    up = torch.nn.functional.interpolate(change, size=env.shape[:2], mode="nearest")
    return env * torch.exp(up[0].permute(1, 2, 0))


def relative_loss(transport: LightTransport, env: torch.Tensor, albedo: torch.Tensor) -> float:
    """Squared residual over the views' energy at the least-squares exposure of `env` (on the transport's grid)."""
    image, observed = transport.image(env, albedo).double(), transport.observed.double()
    scale = float((image * observed).sum() / image.square().sum().clamp_min(1e-30))
    return float((scale * image - observed).square().sum() / observed.square().sum())


def broad_field(albedo: np.ndarray, normals: np.ndarray, mask: np.ndarray) -> float:
    """RMS slope of the albedo's log luminance on the normal over the `mask` texels (least squares with a level)."""
    y = np.log(np.maximum(luminance(albedo)[mask], 1e-4))
    design = np.concatenate([np.ones((int(mask.sum()), 1)), normals[mask]], axis=1)
    return float(np.sqrt(np.mean(np.square(np.linalg.lstsq(design, y, rcond=None)[0][1:]))))


def scene_rows(scene: str, folder: Path, pipeline: Pipeline, samples: str) -> list[dict]:
    """The rows of one scene (module notes)."""
    problem = load_problem(folder / "capture.json", pipeline.solve_settings(1))
    init = problem.load_decomposition(folder / INIT)
    cfg = pipeline.method_settings("dps")
    start = sample_start_materials(init)
    transport = start_transport(problem, init, start, cfg.proximal.transport, SEED)
    truth_env = torch.as_tensor(read_ground_truth(problem.capture.gt["envmap"], "envmap")).float()
    size = init.materials.albedo.shape[0]
    truth = true_materials(problem, size)
    normals, chart = normal_texture(problem, size)
    dielectric = chart & (init.materials.metallic[..., 0] <= METAL_TEXEL).numpy()
    maps = {"loss_true": truth_env, "loss_init_balance": with_balance(truth_env, coarse_log(init.env)),
            "loss_flat": with_balance(truth_env, coarse_log(truth_env).mean(dim=(2, 3), keepdim=True).expand(
                -1, -1, BALANCE_ROWS, 2 * BALANCE_ROWS))}
    grid = (transport.height, 2 * transport.height)  # every transport's
    maps = {name: resize(env, *grid) for name, env in maps.items()}
    group = STUDY_SCENES[scene][0]

    def recorded_under(roughness: torch.Tensor, metallic: torch.Tensor) -> LightTransport:
        materials = MaterialTextures(truth.albedo, roughness, metallic)
        return record_transport(problem, materials, init.env, cfg.proximal.transport, SEED, transport.height,
                                every_texel=not glossy_start(init))

    readings = (("start", start.albedo, transport), ("init", init.materials.albedo, transport),
                ("truth", truth.albedo, transport),
                ("truth_roughness", truth.albedo, recorded_under(truth.roughness, start.metallic)),
                ("truth_metallic", truth.albedo, recorded_under(start.roughness, truth.metallic)),
                ("truth_materials", truth.albedo, recorded_under(truth.roughness, truth.metallic)))
    rows = []
    for label, albedo, recorded in readings:
        rows.append({"scene": scene, "group": group, "albedo": label,
                     **{name: round(relative_loss(recorded, env, albedo), 4) for name, env in maps.items()},
                     "field": round(broad_field(albedo.detach().numpy(), normals, dielectric), 3)})
    drawn = [read_exr(p) for p in sorted((folder / samples).glob("*/albedo.exr"))]
    drawn = [a for a in drawn if a.shape[0] == size]
    if drawn:
        rows.append({"scene": scene, "group": group, "albedo": "samples", **{name: float("nan") for name in maps},
                     "field": round(float(np.mean([broad_field(a, normals, dielectric) for a in drawn])), 3)})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, nargs="+", default=[work_dir("light_dev")], help="study folders")
    parser.add_argument("--scenes", nargs="*", default=None, help="default: every scene with true textures")
    parser.add_argument("--samples", default="dps_proximal", help="method folder whose albedos' field is shown")
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "results" / "balance_views.csv")
    args = parser.parse_args()
    pipeline = Pipeline(workflow_config())
    rows = [row for name, folder in drawn_scenes(args.work, args.scenes)
            for row in scene_rows(name, folder, pipeline, args.samples)]
    write_rows(args.out, rows, settings="")
    for row in rows:
        print(" ".join(f"{k} {v}" for k, v in row.items()))


if __name__ == "__main__":
    main()
