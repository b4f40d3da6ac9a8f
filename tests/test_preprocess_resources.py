"""Cluster resources of the preprocessing rules: config.yaml `resources:` (dpi's defaults for the rest),
as a dry run on a photos-only capture plans them."""

from __future__ import annotations

import re

import numpy as np
from workflow_helpers import snakemake, write_config


def planned_resources(output: str) -> dict[str, dict[str, str]]:
    """rule -> {resource: value} of every job in a dry run's output."""
    plans = {}
    for rule, body in re.findall(r"^rule (\w+):\n(.*?)(?=^\S|\Z)", output, flags=re.M | re.S):
        found = re.search(r"^\s+resources: (.*)$", body, flags=re.M)
        if found:
            plans[rule] = dict(item.split("=", 1) for item in found.group(1).split(", "))
    return plans


def test_preprocess_rules_request_configured_resources(tmp_path):
    from dpi.io.images import write_srgb

    for i in range(3):
        write_srgb(tmp_path / "captures" / "photos" / "images" / f"{i}.png", np.full((8, 8, 3), 0.3, np.float32))
    write_config(tmp_path / "config.yaml", {"scenes": ["photos"], "resources": {"masks": {"mem_mb": 1234}}})
    plans = planned_resources(snakemake(tmp_path, "-n", "results/photos/geometry/mesh_uv.ply"))
    assert set(plans) >= {"poses", "masks", "geometry", "uv"}
    assert plans["masks"]["mem_mb"] == "1234" and plans["masks"]["runtime"] == "60"  # dpi's default
    for rule in ("poses", "geometry", "uv"):
        assert int(plans[rule]["mem_mb"]) >= 1000 and int(plans[rule]["runtime"]) >= 10, plans[rule]
