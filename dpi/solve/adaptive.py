"""Skip what a scene does not need, decided from its init stage and first samples, with the reason.

Two decisions, each logged where its result is written and switched off in config.yaml's
`adaptive` section:
- sample stop rule: when the first MIN_SAMPLES posterior samples of a method agree (their env-map
  sigma2_sample below `agree_tolerance`), the scene is unambiguous for that method (e.g. a
  mirror-like object shows its illumination) and the remaining samples are not drawn;
- fewer diffusion steps for diffuse scenes: when the init stage finds rough, non-metallic
  materials everywhere, the renderer only sees a low-pass of the map, so the diffusion methods
  run `DIFFUSE_STEPS_FACTOR` of their steps.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dpi.io.settings import Weight, settings, settings_from_dict
from dpi.solve.materials import MaterialTextures
from dpi.solve.spread import normalized_env, sample_variance

DIFFUSE_ROUGHNESS = 0.6
"""init roughness that (at its 25th percentile) makes a scene diffuse: a GGX lobe ~30 deg wide"""
DIFFUSE_MAX_METALLIC = 0.1
"""metallic (at its 75th percentile) above which a scene is never treated as diffuse"""
DIFFUSE_STEPS_FACTOR = 0.5
"""fraction of the diffusion steps run for a diffuse scene"""
MIN_SAMPLES = 2
"""samples always drawn before the stop rule looks at them (a spread needs two)"""


@settings
class AdaptiveConfig:
    """Switches and thresholds of the adaptive decisions (config.yaml `adaptive`)."""

    sample_stop: bool = True
    """stop drawing samples of a method once its first ones agree"""
    agree_tolerance: Weight = 1e-3
    """env-map sigma2_sample (as in summary.csv) below which the first samples agree"""
    diffuse_steps: bool = True
    """run fewer diffusion steps when the init stage finds a diffuse object"""

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "AdaptiveConfig":
        """Config from config.yaml's `adaptive` section."""
        return settings_from_dict(cls, values)


def stop_rule_applies(cfg: AdaptiveConfig, samples: int) -> bool:
    """Whether a method drawing `samples` samples waits for the stop rule after its first ones."""
    return cfg.sample_stop and samples > MIN_SAMPLES


def plan_samples(first_envs: list[np.ndarray], samples: int, cfg: AdaptiveConfig) -> dict[str, Any]:
    """How many samples to draw in all, given the first ones' env maps; with the measured spread and why."""
    spread = sample_variance([normalized_env(env) for env in first_envs])
    if not np.isfinite(spread):
        raise ValueError(f"non-finite env-map spread across the first {len(first_envs)} samples")
    agree = spread < cfg.agree_tolerance
    drawn = len(first_envs) if agree else samples
    verb = "agree" if agree else "differ"
    reason = (f"first {len(first_envs)} samples {verb}: env sigma2_sample {spread:.3g} "
              f"{'<' if agree else '>='} agree_tolerance {cfg.agree_tolerance:g}; drawing {drawn} of {samples}")
    return {"samples": drawn, "requested": samples, "spread": spread, "reason": reason}


def plan_steps(init: MaterialTextures, steps: int, cfg: AdaptiveConfig) -> tuple[int, str]:
    """Diffusion steps for a scene given its init materials, and why."""
    roughness = float(np.quantile(init.roughness.detach().numpy(), 0.25))
    metallic = float(np.quantile(init.metallic.detach().numpy(), 0.75))
    seen = f"init roughness p25 {roughness:.2f}, metallic p75 {metallic:.2f}"
    if not cfg.diffuse_steps:
        return steps, f"{seen}; diffuse step reduction off"
    if roughness >= DIFFUSE_ROUGHNESS and metallic <= DIFFUSE_MAX_METALLIC:
        reduced = max(1, int(round(steps * DIFFUSE_STEPS_FACTOR)))
        return reduced, (f"{seen}: diffuse (roughness >= {DIFFUSE_ROUGHNESS:g}), the views see only low "
                         f"frequencies of the map; {reduced} of {steps} diffusion steps")
    return steps, f"{seen}: not diffuse; all {steps} diffusion steps"
