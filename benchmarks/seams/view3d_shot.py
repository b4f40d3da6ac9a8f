"""A picture of the report's 3D view for the docs: a scene's exported asset in model-viewer, as the report shows it
(dpi.evaluation.view3d), one sample a picture, rendered by headless Chromium (its software WebGL) and placed side by
side in one picture (JPEG: about half the palette PNG's size).

    .venv/bin/python benchmarks/seams/view3d_shot.py results demo --samples dps_0 none_0 --out benchmarks/seams/view3d_demo.jpg
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import tempfile
from pathlib import Path

from PIL import Image

from dpi.evaluation.view3d import asset_variants, install_viewer, view3d_section
from dpi.io.layout import SceneLayout

WAIT_MS = 20_000
"""virtual time Chromium gives the page to load the asset and prefilter the map before its picture"""
SIZE = (520, 470)


def shot(page: Path, sample: str, out: Path, browser: str) -> None:
    """One screenshot of `page` showing `sample` (the view's ?sample= parameter)."""
    subprocess.run([browser, "--headless", "--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                    "--hide-scrollbars", f"--window-size={SIZE[0]},{SIZE[1]}", f"--virtual-time-budget={WAIT_MS}",
                    f"--screenshot={out}", f"{page.as_uri()}?sample={sample}"],
                   check=True, capture_output=True, timeout=300)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", type=Path, help="the workflow's results folder")
    parser.add_argument("scene")
    parser.add_argument("--samples", nargs="*", default=None, help="variant names (default: the asset's first two)")
    parser.add_argument("--exposure", type=float, default=1.0, help="the capture's exposure (the view divides by it)")
    parser.add_argument("--out", type=Path, required=True, help="the picture (.jpg or .png)")
    args = parser.parse_args()

    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if browser is None:
        raise SystemExit("no Chromium on PATH (Debian: apt-get install chromium)")
    scene = SceneLayout(args.results / args.scene)
    samples = args.samples or [name for name, _ in asset_variants(scene.export_asset("glb").read_bytes())][:2]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if install_viewer(folder) is None:
            raise SystemExit("model-viewer is not installed (scripts/setup.sh)")
        body = "\n".join(view3d_section(args.scene, scene, True, args.exposure))
        page = folder / "view.html"
        page.write_text(f"<!doctype html><html><head><meta charset='utf-8'><script src='model-viewer.min.js'></script>"
                        f"<style>body {{ margin: 8px; font: 13px sans-serif; }} .note {{ display: none; }}</style>"
                        f"</head><body>{body}</body></html>")
        pictures = []
        for sample in samples:
            png = folder / f"{sample}.png"
            shot(page, sample, png, browser)
            pictures.append(Image.open(png).convert("RGB"))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    strip = Image.new("RGB", (sum(p.width for p in pictures), max(p.height for p in pictures)))
    for k, picture in enumerate(pictures):
        strip.paste(picture, (sum(p.width for p in pictures[:k]), 0))
    strip.save(args.out, quality=85)  # quality: a JPEG's; a PNG ignores it
    print(f"wrote {args.out} ({', '.join(samples)})")


if __name__ == "__main__":
    main()
