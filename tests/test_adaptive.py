"""The adaptive decisions of dpi.solve.adaptive on known inputs: agreeing or differing samples, diffuse or glossy init."""

import numpy as np
import pytest

from dpi.solve.adaptive import AdaptiveConfig, plan_samples, plan_steps, stop_rule_applies
from dpi.solve.materials import MaterialTextures

rng = np.random.default_rng(0)
SKY = rng.uniform(0.1, 5.0, size=(8, 16, 3)).astype(np.float32)


def test_identical_samples_stop_at_the_first_ones():
    plan = plan_samples([SKY, SKY.copy()], samples=5, cfg=AdaptiveConfig())
    assert plan["samples"] == 2 and plan["requested"] == 5 and plan["spread"] == 0.0
    assert "agree" in plan["reason"] and "drawing 2 of 5" in plan["reason"]


def test_a_global_brightness_change_is_not_a_disagreement():
    """Spread is measured on median-normalised maps, like summary.csv's env sigma2_sample."""
    assert plan_samples([SKY, 3.0 * SKY], samples=4, cfg=AdaptiveConfig())["samples"] == 2


def test_different_samples_draw_all():
    other = rng.uniform(0.1, 5.0, size=SKY.shape).astype(np.float32)
    plan = plan_samples([SKY, other], samples=4, cfg=AdaptiveConfig())
    assert plan["samples"] == 4 and plan["spread"] > AdaptiveConfig().agree_tolerance and "differ" in plan["reason"]


def test_non_finite_samples_are_an_error():
    broken = SKY.copy()
    broken[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        plan_samples([SKY, broken], samples=3, cfg=AdaptiveConfig())


def test_stop_rule_only_applies_beyond_the_first_samples_and_can_be_switched_off():
    assert stop_rule_applies(AdaptiveConfig(), 3) and not stop_rule_applies(AdaptiveConfig(), 2)
    assert not stop_rule_applies(AdaptiveConfig(sample_stop=False), 10)


@pytest.mark.parametrize("roughness, metallic, steps", [(0.9, 0.0, 50), (0.3, 0.0, 100), (0.9, 1.0, 100)])
def test_only_a_rough_dielectric_runs_fewer_steps(roughness, metallic, steps):
    materials = MaterialTextures.constant(8, roughness=roughness, metallic=metallic)
    chosen, reason = plan_steps(materials, 100, AdaptiveConfig())
    assert chosen == steps
    assert f"{steps} of 100" in reason if steps < 100 else "all 100" in reason


def test_step_reduction_can_be_switched_off():
    materials = MaterialTextures.constant(8, roughness=0.9)
    assert plan_steps(materials, 100, AdaptiveConfig(diffuse_steps=False))[0] == 100


def test_unknown_settings_are_rejected():
    with pytest.raises(ValueError, match="agree_tol"):
        AdaptiveConfig.from_dict({"agree_tol": 1.0})
