"""How visible the textures' chart seams are, per capture and method: the evaluation's albedo seam ratio
(dpi.evaluation.seams: seam pairs' lookup difference over mesh edges'; about 1 or below is seamless).

Reads what runs already wrote: each `LABEL=DIR` names a results folder of the workflow or of a study (it holds
`{scene}/eval/{method}/{seed}.json`), so the demo, the skull photos (benchmarks/real_photos/real_photos.py) and the posterior
study's scanned capture are scored as the user's report scores them. The atlas the uv stage made, where it made
one, gives the given and the kept face counts and the texture size. Rows go to benchmarks/seams/seams.csv.

    .venv/bin/python benchmarks/seams/seams.py demo=results skull=results/benchmarks/real_photos/results \\
        scan=results/benchmarks/posterior_study/results --scenes demo skull_photos torus_scan
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dpi.io.layout import SceneLayout
from dpi.studies.engine import results_csv, settings_hash, write_rows

CSV = results_csv("seams")


def scene_rows(label: str, scene: SceneLayout) -> list[dict]:
    """One row per evaluated sample of a scene: its albedo seam ratio, and the atlas the uv stage made."""
    atlas = scene.geometry["uv_summary"]
    summary = json.loads(atlas.read_text()) if atlas.is_file() else {}
    rows = []
    for path in sorted(scene.root.glob("eval/*/*.json")):
        seam = json.loads(path.read_text())["metrics"].get("albedo_seam")
        if not isinstance(seam, (int, float)):
            continue
        rows.append({"capture": label, "scene": scene.root.name, "method": path.parent.name, "seed": int(path.stem),
                     "albedo_seam": round(float(seam), 4), "given_faces": summary.get("given_faces", ""),
                     "faces": summary.get("faces", ""), "texture_size": summary.get("texture_size", "")})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sources", nargs="+", metavar="LABEL=DIR", help="a label and a results folder")
    parser.add_argument("--scenes", nargs="*", default=None, help="scenes to score (default: all in each folder)")
    parser.add_argument("--out", type=Path, default=CSV)
    args = parser.parse_args()

    rows = []
    for source in args.sources:
        label, _, folder = source.partition("=")
        if not folder:
            parser.error(f"{source}: expected LABEL=DIR")
        for scene_dir in sorted(p for p in Path(folder).iterdir() if (p / "eval").is_dir()):
            if args.scenes is None or scene_dir.name in args.scenes:
                rows.extend(scene_rows(label, SceneLayout(scene_dir)))
    if not rows:
        raise SystemExit("no evaluated samples with a seam ratio in " + ", ".join(args.sources))
    write_rows(args.out, rows, settings_hash({"sources": args.sources, "scenes": args.scenes}))
    print(f"{'capture':<8} {'scene':<14} {'method':<16} {'n':>2} {'seam ratio (max)':>17}")
    keys = sorted({(r["capture"], r["scene"], r["method"]) for r in rows})
    for key in keys:
        values = [r["albedo_seam"] for r in rows if (r["capture"], r["scene"], r["method"]) == key]
        print(f"{key[0]:<8} {key[1]:<14} {key[2]:<16} {len(values):>2} {max(values):>17.2f}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
