"""How real the posterior study's env maps look, method by method, on its real-light scenes.

    .venv/bin/python benchmarks/light_realism.py --panoramas DIR [--work results/benchmarks/posterior_study]

For every sample the posterior study drew on a real-light scene (dpi.studies.scenes.REAL_LIGHT_SCENES), the
realism distance (dpi.evaluation.realism) of its env map to the manifest's held-out real panoramas of the scene's
family, less the scene's own panorama (a map that copies the truth should not pass for realism; its accuracy is
env PSNR's business). Rows (scene, group, method, sampler, seed, realism) go to
benchmarks/results/light_realism.csv, rewritten whole; it prints mean +- std per group, method and sampler.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from dpi.evaluation.realism import patches, sliced_wasserstein
from dpi.io.exr import read_exr
from dpi.prior.data import read_panorama
from dpi.prior.panoramas import panorama_files
from dpi.studies.engine import mean_std_cells, read_rows, results_csv, study_layout, work_dir, write_rows
from dpi.studies.scenes import REAL_LIGHT_SCENES

COLUMNS = ("scene", "group", "method", "sampler", "seed", "realism")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--panoramas", type=Path, required=True, help="folder holding the manifest's panoramas")
    parser.add_argument("--work", type=Path, default=work_dir("posterior_study"), help="the posterior study's folder")
    parser.add_argument("--study", type=Path, default=results_csv("posterior_study"),
                        help="the posterior study's CSV: which samples exist, with their method and sampler")
    args = parser.parse_args()
    layout = study_layout(args.work)
    clouds: dict[str, dict[str, torch.Tensor]] = {}
    for family in ("outdoor", "indoor"):
        clouds[family] = {path.name: patches(read_panorama(path))
                          for path in panorama_files(args.panoramas, family, "held_out")}
    rows = []
    for r in read_rows(args.study):
        if r["scene"] not in REAL_LIGHT_SCENES:
            continue
        synth = REAL_LIGHT_SCENES[r["scene"]][1]
        label = r["method"] if not r["sampler"] else f"{r['method']}_{r['sampler']}"
        env_file = layout.scene(r["scene"]).sample_files(label, int(r["seed"]))["env"]
        if not env_file.exists():
            continue
        references = torch.cat([c for name, c in clouds[synth["prior"]].items() if name != synth["panorama"]])
        rows.append({**{k: r[k] for k in COLUMNS[:4]}, "seed": int(r["seed"]),
                     "realism": round(sliced_wasserstein(patches(read_exr(env_file)), references), 4)})
    rows = list({tuple(row[k] for k in COLUMNS[:5]): row for row in rows}.values())
    write_rows(results_csv("light_realism"), rows, settings="")
    keys = sorted({(row["group"], row["method"], row["sampler"]) for row in rows})
    print(f"{'group':<12} {'method':<12} {'sampler':<24} {'n':>3} {'realism':>16}")
    for key in keys:
        sel = [row for row in rows if (row["group"], row["method"], row["sampler"]) == key]
        print(f"{key[0]:<12} {key[1]:<12} {key[2]:<24} {len(sel):>3} "
              f"{mean_std_cells(sel, (('realism', '.3f'),))[0]:>16}")


if __name__ == "__main__":
    main()
