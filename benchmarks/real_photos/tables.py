"""The real photo captures' table."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from table_format import latest, markdown, read_rows

HERE = Path("benchmarks") / "real_photos"
"""the study's folder, relative to a checkout's root"""


def real_photos(root: Path) -> str:
    """Real photo captures end to end (benchmarks/real_photos/real_photos.py): poses (against a published solution where there
    is one), derived masks against the checked ones and the witnesses' flags, the photo stages' seconds, held-out
    views per method and where a run stopped; the newest row per capture and run (the defaults, or a named variant)."""
    rows = latest(read_rows(root / HERE / "real_photos.csv", ("capture", "variant", "size", "stopped")),
                  ("capture", "variant"))

    def cell(value: Any, spec: str, scale: float = 1.0) -> str:
        return "-" if not isinstance(value, float) or math.isnan(value) else f"{scale * value:{spec}}"

    body = [[r["capture"], r["variant"].replace("_", " "), f"{r['views']:.0f} of {r['size']}", f"{r['registered']:.0%}",
             f"{r['reprojection_px']:.2f}" + ("" if cell(r.get("reference_reprojection_px"), ".2f") == "-" else
                                              f" (published {r['reference_reprojection_px']:.2f})"),
             f"{cell(r['rotation_error_deg'], '.2f')} / {cell(r['centre_error'], '.1f', 100)}",
             f"{r['mask_iou']:.3f} (min {r['mask_iou_min']:.2f})",
             f"{r['masks_flagged']:.0f} ({r['flagged_below_08']:.0f} of {r['masks_below_08']:.0f} / "
             f"{cell(r['flagged_below_09'], '.0f')} of {cell(r['masks_below_09'], '.0f')} / "
             f"{r['flagged_above_09']:.0f})",
             " / ".join(cell(r[f"{s}_seconds"], ".0f") for s in ("poses", "masks", "geometry", "uv")),
             " / ".join(cell(r[f"{m}_view_psnr"], ".2f") for m in ("init", "dps", "none")), f"{r['seconds'] / 60:.1f}",
             r["stopped"] or "-"]
            for r in rows]
    return markdown(["capture", "run", "photos", "registered", "reproj. [px]", "vs published: rotation [deg] / centre [%]",
                     "mask IoU vs checked", "flagged (checked: <0.8 / <0.9 / >0.9 IoU)",
                     "poses / masks / geometry / uv [s]", "held-out PSNR init / dps / none [dB]", "min", "stopped at"],
                    body)


TABLES = {"real_photos": real_photos}
"""the study's tables by the name their markers use"""
