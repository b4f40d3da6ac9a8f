"""The photo stages' tables: the masks' witnesses on synthetic photo captures."""

from __future__ import annotations

from pathlib import Path

from table_format import latest, markdown, read_rows

HERE = Path("benchmarks") / "preprocess"
"""the study's folder, relative to a checkout's root"""


def mask_witnesses(root: Path) -> str:
    """Synthetic photo captures (benchmarks/preprocess/preprocess.py --out .../mask_witnesses.csv): derived masks
    against the truth, and what the masks' witnesses flagged, per shape and sweep."""
    rows = latest(read_rows(root / HERE / "mask_witnesses.csv", ("shape", "background", "elevations_deg")),
                  ("shape", "background", "views", "size", "arc_deg", "stereo"))
    body = [[r["shape"], r["background"], f"{r['views']:g} of {r['size']:g} px", f"{r['arc_deg']:g}",
             *([f"{r['mask_iou']:.3f}", f"{r['mask_iou_min']:.3f}",
                f"{r['flagged_below_08']:g} of {r['masks_below_08']:g}", f"{r['flagged_above_09']:g}", "-"]
               if not r["error"] else ["-", "-", "-", "-", r["error"]])]
            for r in sorted(rows, key=lambda r: (r["arc_deg"], r["shape"]))]
    return markdown(["shape", "backdrop", "views", "sweep [deg]", "mask IoU", "min", "flagged, views under 0.8",
                     "flagged, views over 0.9", "stopped"], body)


TABLES = {"mask_witnesses": mask_witnesses}
"""the study's tables by the name their markers use"""
