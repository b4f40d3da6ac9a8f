"""dps samplers: the proximal x0-space step converges to exact data, guidance fits the views better than
the prior alone, every sampler plugs into the one loop, and the sample stage runs dps end to end."""

from __future__ import annotations

import json
from dataclasses import replace
import math

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.io.settings import SettingsError, settings_from_dict
from dpi.light.tonecurve import LogEncoding
from dpi.prior.diffusion import base_diffusion
from dpi.prior.sample import Prior, draw_samples
from dpi.prior.unet import SMALL_CONFIGS, UNetModel
from dpi.render.renderer import RenderConfig
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps import SAMPLERS, DPSConfig, dps_phases, dps_sample, posterior_steps, start_run
from dpi.solve.dps.map_solve import PRIOR_STD, Resampling, posterior_variance
from dpi.solve.dps.proximal import ProximalConfig
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.materials import MaterialTextures
from dpi.solve.prior_space import prior_to_env
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.solve.sun_model import map_energy, sun_direction_of, sun_env
from dpi.solve.transport import AlbedoLookup, LightTransport
from dpi.synth.shapes import blob


def log_prior(height: int = 8) -> Prior:
    """An untrained tiny network in the log encoding (its x0_hat is no map; the data must do the work)."""
    torch.manual_seed(0)
    return Prior(model=UNetModel(SMALL_CONFIGS["tiny"]).eval(), diffusion=base_diffusion(1000, True),
                 encoding=LogEncoding(), family="outdoor", height=height, median_target=1.0)


class LinearProblem:
    """An exact, noise-free linear measurement of an env map per channel, y_v = A_v L (stands in for the renderer
    and, as `transport`, for the recorded light transport: the albedo plays no part)."""

    def __init__(self, truth: torch.Tensor, views: int = 3, pixels: int = 40, seed: int = 0):
        generator = torch.Generator().manual_seed(seed)
        self.settings = ProblemConfig(env_height=truth.shape[0], texture_size=4)
        texels = truth.shape[0] * truth.shape[1]
        self.operators = [torch.rand(pixels, texels, generator=generator) / texels for _ in range(views)]
        self.images = [a @ truth.reshape(-1, 3) for a in self.operators]
        self.masks = [torch.ones(pixels, dtype=torch.bool) for _ in range(views)]
        self.train_ids = list(range(views))

    def render(self, env, materials, view, seed, spp=None):
        return self.operators[view] @ env.reshape(-1, 3)

    def view_loss(self, rendered, view):
        return (rendered - self.images[view]).square().mean()

    def data_loss(self, env, materials, views, seed, spp=None):
        return sum(self.view_loss(self.render(env, materials, v, seed), v) for v in views)

    def sample_views(self, count, generator):
        return list(self.train_ids)

    @property
    def mesh(self) -> dict[str, np.ndarray]:
        """A blob with UVs, for what reads the problem's mesh (a sample's broad albedo field; the albedo plays no part
        here)."""
        import trimesh

        shape = blob(resolution=8, seed=0)
        normals = trimesh.Trimesh(shape.vertices, shape.faces, process=False).vertex_normals
        return {"positions": shape.vertices, "normals": np.asarray(normals), "uvs": shape.uvs, "faces": shape.faces}

    def constrain_(self, materials):
        """No mesh, no seams: the materials clamped."""
        return materials.clamp_()

    def transport(self) -> LightTransport:
        """The measurement as an exact light transport: its offset is A (both halves, every channel), its slope 0."""
        operator = torch.cat(self.operators)  # (P, N)
        pixels, texels = operator.shape
        matrix = torch.zeros(2, 2, 3, pixels, texels)
        matrix[1] = operator
        size = self.settings.texture_size
        lookup = AlbedoLookup(torch.zeros(0, dtype=torch.long), torch.zeros(0, dtype=torch.long), torch.zeros(0),
                              (pixels, size * size))
        return LightTransport(matrix, lookup, torch.cat(self.images).double(), self.settings.env_height,
                              MaterialTextures.constant(size), pixels, 0.0)


class GaussianDenoiser(torch.nn.Module):
    """The exact eps_theta of a prior x0 ~ N(mean, std^2) per texel: E[eps | x_t] (a denoiser with no error)."""

    def __init__(self, mean: float, std: float):
        super().__init__()
        self.mean, self.std = mean, std
        abar = torch.as_tensor(base_diffusion(1000, False).alphas_cumprod, dtype=torch.float32)
        self.abar = torch.nn.Parameter(abar, requires_grad=False)

    def forward(self, x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        abar = self.abar[t].reshape(-1, 1, 1, 1)
        return (1 - abar).sqrt() * (x - abar.sqrt() * self.mean) / (abar * self.std**2 + 1 - abar)


def relative_residual(problem: LinearProblem, env: torch.Tensor) -> float:
    return float(problem.data_loss(env, None, problem.train_ids, 0) / sum(y.square().mean() for y in problem.images))


def gaussian_prior(height: int = 8) -> Prior:
    """A prior of maps whose log radiance is N(0, 2.25^2) per texel around the median, with its exact denoiser."""
    encoding = LogEncoding()
    return Prior(model=GaussianDenoiser(mean=-encoding.offset / encoding.width, std=0.3),
                 diffusion=base_diffusion(1000, False), encoding=encoding, family="outdoor", height=height,
                 median_target=1.0)


def test_proximal_step_with_an_exact_operator_converges_to_the_data(monkeypatch):
    monkeypatch.setattr("dpi.solve.dps.proximal.NOISE_MIX", 0.0)  # deterministic DDIM re-noising
    height = 8
    truth = torch.exp(torch.randn(height, 2 * height, 3, generator=torch.Generator().manual_seed(1)))
    problem = LinearProblem(truth)
    init = Decomposition(torch.ones(height, 2 * height, 3), MaterialTextures.constant(4))
    cfg = DPSConfig.from_dict({"steps": 40, "proximal": {
        "inner_steps": 8, "prox_weight": 0.0, "lr_map": 0.05, "start_noise": 1.0}})
    run, state = start_run(problem, gaussian_prior(height), init, cfg, seed=0, radiance_scale=1.0)
    state.extra["transport"] = problem.transport()
    start = relative_residual(problem, run.env(torch.exp(state.log_map), state).detach())
    records = list(posterior_steps(run, state))
    final = prior_to_env(state.x, run.prior, run.scale * float(torch.exp(state.log_exposure)), height)
    assert len(records) == 40 and all("skipped" not in r for r in records)
    assert relative_residual(problem, final) < 1e-3 < start
    assert records[-1]["loss"] < 0.01 * records[0]["loss"]


def second_step_after_a_moved_map(problem: LinearProblem, proximal: dict, prior_height: int | None = None):
    """A proximal sample's run and state after two steps, its map set far from x0_hat in between; and the second
    step's record (the prior's maps as fine as the problem's unless `prior_height`)."""
    height = problem.settings.env_height
    init = Decomposition(torch.ones(height, 2 * height, 3), MaterialTextures.constant(4))
    cfg = DPSConfig.from_dict({"steps": 10, "proximal": proximal})
    run, state = start_run(problem, gaussian_prior(prior_height or height), init, cfg, seed=0, radiance_scale=1.0)
    state.extra["transport"] = problem.transport()
    steps = posterior_steps(run, state)
    next(steps)
    with torch.no_grad():
        state.log_map.fill_(3.0)
    return run, state, next(steps)


def test_each_steps_fit_starts_from_the_previous_steps_map():
    """A step's data updates start from the previous step's map, not from its x0_hat: with no update the map
    stays where it was moved."""
    problem = LinearProblem(torch.ones(8, 16, 3))
    _, _, record = second_step_after_a_moved_map(problem, {"inner_steps": 1, "lr_map": 1e-12, "map_solve": 0})
    assert record["prox"] > 1e-8


def half_seen_problem(height: int, seed: int) -> tuple[torch.Tensor, LinearProblem, torch.Tensor]:
    """A random true map of `height` rows, one view that sees its upper half texel by texel, and that half."""
    truth = torch.exp(torch.randn(height, 2 * height, 3, generator=torch.Generator().manual_seed(seed)))
    problem = LinearProblem(truth)
    seen = torch.zeros(height, 2 * height, dtype=torch.bool)
    seen[: height // 2] = True
    problem.operators = [torch.eye(2 * height * height)[torch.nonzero(seen.reshape(-1))[:, 0]]]
    problem.images, problem.masks, problem.train_ids = [problem.operators[0] @ truth.reshape(-1, 3)], \
        [torch.ones(int(seen.sum()), dtype=torch.bool)], [0]
    return truth, problem, seen


def test_a_solved_map_fits_what_the_views_see_and_is_x0_hat_elsewhere():
    """With `map_solve` (and no `perturb`) a step's map solves its loss (a weak proximal term): the texels the views
    see take the truth (in one step, from x0_hat), the others x0_hat, whatever the previous step's map was."""
    truth, problem, seen = half_seen_problem(8, seed=1)
    run, state, _ = second_step_after_a_moved_map(problem, {
        "inner_steps": 1, "lr_map": 1e-12, "map_solve": 10, "prox_weight": 1e-6, "perturb": 0})
    env = run.env(torch.exp(state.log_map), state).detach()
    np.testing.assert_allclose(env[seen].numpy(), truth[seen].numpy(), rtol=3e-2)
    x0_hat = run.prior.encoding.to_radiance(state.snapshots[-1]).permute(1, 2, 0)
    ratio = torch.log(env[~seen] / x0_hat[~seen])  # x0_hat up to the map's level, which the exposure holds
    assert float(ratio.std()) < 1e-3


def test_a_perturbed_solve_moves_the_silent_texels_by_the_priors_uncertainty():
    """With `perturb` the solve's target is x0_hat plus a random field of std perturb x r_t (prior space): the
    texels the views see still take the truth, the silent ones leave x0_hat by that std."""
    truth, problem, seen = half_seen_problem(8, seed=1)
    perturb = 0.5
    run, state, _ = second_step_after_a_moved_map(problem, {
        "inner_steps": 1, "lr_map": 1e-12, "map_solve": 10, "prox_weight": 1e-6, "perturb": perturb,
        "perturb_rows": 8})  # white per texel: its std is measurable
    env = run.env(torch.exp(state.log_map), state).detach()
    np.testing.assert_allclose(env[seen].numpy(), truth[seen].numpy(), rtol=3e-2)
    z = run.prior.encoding.to_prior(torch.exp(state.log_map)).detach().reshape(3, *seen.shape).permute(1, 2, 0)
    change = (z - state.snapshots[-1].reshape(3, *seen.shape).permute(1, 2, 0))[~seen]  # up to the map's level, which the exposure holds
    abar = float(run.diffusion.alphas_cumprod[run.index(1)])
    expected = perturb * math.sqrt(posterior_variance(abar, PRIOR_STD))
    assert float(change.std()) == pytest.approx(expected, rel=0.2)


@pytest.mark.parametrize("values,message", [({"perturb": -0.1}, "perturb: must be >= 0, got -0.1"),
                                            ({"map_solve": -1}, "map_solve: must be >= 0, got -1")])
def test_the_push_settings_are_bounded(values, message):
    with pytest.raises(SettingsError, match=f"^{message}$"):
        settings_from_dict(ProximalConfig, values)


def test_a_solve_fits_the_views_by_a_field_on_the_transports_grid():
    """The solved map is x0_hat (8 rows) times a field upsampled from the transport's 4 rows:
    the views (half the coarse texels) are fitted, and log(map / x0_hat) lies in the upsampling's range."""
    height = 4
    truth, problem, seen = half_seen_problem(height, seed=2)
    run, state, _ = second_step_after_a_moved_map(problem, {
        "inner_steps": 1, "lr_map": 1e-12, "map_solve": 10, "prox_weight": 1e-6, "perturb": 0},
        prior_height=2 * height)
    env = run.env(torch.exp(state.log_map), state).detach()
    np.testing.assert_allclose(env[seen].numpy(), truth[seen].numpy(), rtol=3e-2)
    x0_hat = run.prior.encoding.to_radiance(state.snapshots[-1])
    change = (state.log_map - torch.log(x0_hat)).detach().reshape(3, -1).double()
    up = Resampling.between(height, 2 * height).forward.to_dense()  # (8 x 16 texels, 4 x 8)
    fitted = up @ torch.linalg.lstsq(up, change.T).solution
    assert float((fitted - change.T).abs().max()) < 1e-4 < float(change.std())


@pytest.fixture(scope="module")
def problem_and_init(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    return problem, path_traced_init(problem, InitConfig(iterations=10, reading="rough"), seed=0, progress=False).kept


def training_residual(problem: InverseProblem, decomposition: Decomposition) -> float:
    with torch.no_grad():
        return float(problem.data_loss(decomposition.env, decomposition.materials, problem.train_ids, seed=5))


def test_guided_sample_fits_the_views_far_better_than_the_prior_alone(problem_and_init):
    problem, init = problem_and_init
    prior = gaussian_prior()
    cfg = DPSConfig.from_dict({"steps": 12, "refine": {"iterations": 5},
                               "proximal": {"inner_steps": 3, "lr_map": 0.1}})
    guided = dps_sample(problem, prior, init, cfg, seed=3, progress=False).decomposition
    unguided_x = draw_samples(prior, 1, steps=12, seed=3)
    scale = guided.trace.info["radiance_scale"]
    unguided = Decomposition(prior_to_env(unguided_x, prior, scale, problem.settings.env_height), guided.materials)
    assert training_residual(problem, guided) < 0.3 * training_residual(problem, unguided)


@pytest.mark.parametrize("sampler", list(SAMPLERS))
def test_every_sampler_runs_in_the_one_loop_and_is_seeded(problem_and_init, sampler, monkeypatch):
    problem, init = problem_and_init
    monkeypatch.setattr("dpi.solve.dps.loop.STRIP_FRAMES", 2)
    cfg = DPSConfig.from_dict({"sampler": sampler, "steps": 3, "refine": {"iterations": 1},
                               **({"proximal": {"start_noise": 1.0}} if sampler == "proximal" else {})})
    first = dps_sample(problem, log_prior(), init, cfg, seed=4, progress=False)
    again = dps_sample(problem, log_prior(), init, cfg, seed=4, progress=False)
    d = first.decomposition
    assert d.trace.info["sampler"] == sampler and len(d.trace.steps) == 3 and len(first.snapshots) == 2
    assert all(s["seconds_network"] >= 0 and s["seconds"] >= s["seconds_network"] for s in d.trace.steps)
    # Mitsuba's parallel film sums a pixel's samples in whatever order its threads run, so two runs of one seed
    # agree to float rounding, not bit for bit; another seed's sample differs by far more
    torch.testing.assert_close(d.env, again.decomposition.env, rtol=1e-3, atol=1e-3)
    other = dps_sample(problem, log_prior(), init, cfg, seed=5, progress=False).decomposition.env
    assert float((other - d.env).abs().max()) > 1e-2


def test_a_sample_yields_its_phases_in_order_and_the_last_is_its_result(problem_and_init):
    """dps_phases yields one record per reverse step with x0_hat and the solved map, then the loop's, the kept and the
    refined maps; the refined phase carries the sample, whose map is the refined one and whose trace has every step."""
    problem, init = problem_and_init
    cfg = DPSConfig.from_dict({"steps": 3, "refine": {"iterations": 1}, "proximal": {"start_noise": 1.0}})
    phases = list(dps_phases(problem, log_prior(), init, cfg, seed=4, progress=False))
    assert [p["phase"] for p in phases] == ["step"] * 3 + ["loop", "kept", "refined"]
    assert [p["record"]["step"] for p in phases[:3]] == [0, 1, 2]
    height = problem.settings.env_height
    for p in phases[:3]:
        assert p["x0_hat"].shape[-1] == 3 and p["solved"].shape == p["x0_hat"].shape
    assert all(p["env"].shape == (height, 2 * height, 3) and bool(torch.isfinite(p["env"]).all()) for p in phases[3:])
    result = phases[-1]["result"]
    assert torch.equal(result.decomposition.env, phases[-1]["env"]) and len(result.decomposition.trace.steps) == 3


def test_unknown_sampler_is_an_error():
    with pytest.raises(ValueError, match="sampler"):
        DPSConfig.from_dict({"sampler": "telepathy"})
    with pytest.raises(ValueError, match="proximal.inner_steps: must be >= 1"):
        DPSConfig.from_dict({"proximal": {"inner_steps": 0}})


def test_sample_stage_draws_a_dps_sample(tiny_capture, tmp_path):
    from dpi.prior.train import save_atomic
    from dpi.stages import capture_stage, init_stage, sample_stage
    from stage_jobs import stage_job

    prior = log_prior()
    checkpoint = tmp_path / "prior.pt"
    save_atomic({"format": "dpi-prior-v1", "config": prior.model.config.to_dict(), "family": "outdoor",
                 "height": 8, "tone": {**prior.encoding.to_dict(), "median_target": 1.0},
                 "diffusion": {"num_timesteps": 1000, "schedule": "linear"}, "model": prior.model.state_dict(),
                 "ema": None, "step": 0}, checkpoint)
    job = stage_job(tiny_capture, tmp_path / "results", render={"spp": 4},
                    problem={"env_height": 4, "texture_size": 8, "resolution": None}, init={"iterations": 3},
                    method_params={"dps": {"steps": 4, "refine": {"iterations": 2}}},
                    illumination_prior={"checkpoints": {"outdoor": str(checkpoint)}})
    capture_stage(job)
    init_stage(job)
    sample_stage(replace(job, method="dps"))
    out = job.paths.sample_dir("dps", 0)
    trace = json.loads((out / "trace.json").read_text())
    assert trace["info"]["sampler"] == "proximal" and len(trace["steps"]) >= 2
    assert (out / "x0_strip.png").is_file()
    assert np.isfinite(Decomposition.load(out).env.numpy()).all()


def test_a_parametric_sun_is_fitted_and_lands_in_the_map(problem_and_init):
    problem, init = problem_and_init
    cfg = DPSConfig.from_dict({"steps": 4, "proximal": {"start_noise": 1.0}, "refine": {"iterations": 1}, "sun": "on"})
    sunny = dps_sample(problem, log_prior(), init, cfg, seed=2, progress=False).decomposition
    sun = sunny.trace.info["sun"]
    assert 0 < sun["energy_share"] < 1 and len(sun["direction"]) == 3
    footprint = sun_env(torch.tensor(sun["uv"]), torch.ones(3), problem.settings.env_height)[..., :1] > 0
    held = map_energy(sunny.env * footprint)  # the sun's texels hold its irradiance on top of the sky's
    assert bool((held >= 0.999 * torch.tensor(sun["irradiance"])).all())
    off = DPSConfig.from_dict({"steps": 4, "proximal": {"start_noise": 1.0}, "refine": {"iterations": 1}, "sun": "off"})
    plain = dps_sample(problem, log_prior(), init, off, seed=2, progress=False).decomposition
    assert "sun" not in plain.trace.info
    with pytest.raises(ValueError, match="sun.mode: must be one of auto, on, off"):
        DPSConfig.from_dict({"sun": "sometimes"})


def test_a_written_dps_map_holds_one_sun_drawn_as_a_disc(tiny_capture, problem_and_init, tmp_path):
    """A sample's map, with a second sun in the prior's sky, written and read back from envmap.exr: one
    sun-like spot, in the fitted sun's direction, its energy in a few texels of the 64-row map (a disc, not a
    block carried up from a coarser grid), the second sun's energy merged into it."""
    from dpi.io.images import luminance
    from dpi.light.envmap import read_envmap, texel_solid_angles
    from dpi.light.sunlight import find_spots
    from dpi.solve.dps.loop import start_run

    _, coarse = problem_and_init
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=64, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    env = torch.nn.functional.interpolate(coarse.env.permute(2, 0, 1)[None], size=(64, 128), mode="nearest")
    init = Decomposition(env[0].permute(1, 2, 0), coarse.materials, coarse.trace)
    prior = log_prior()
    run, state = start_run(problem, prior, init, DPSConfig.from_dict({"sun": "on"}), seed=0)
    radiance = torch.ones(1, 3, prior.height, 2 * prior.height)
    radiance[..., 2, 11] = 60.0  # the prior's own sun, a texel of its grid
    with torch.no_grad():
        state.sun_uv.copy_(torch.tensor([0.3, 0.3]))
        state.sun_log.copy_(torch.log(torch.tensor([30.0, 28.0, 25.0])))
        written, irradiance, merged = run.written_env(radiance, state)
    assert merged == 1 and bool((irradiance > run.sun_irradiance(state)).all())
    Decomposition(written, init.materials).save(tmp_path / "dps")
    env = read_envmap(tmp_path / "dps" / "envmap.exr")
    spots = find_spots(torch.as_tensor(env, dtype=torch.float64))
    assert len(spots) == 1
    assert float(spots[0].direction @ torch.as_tensor(sun_direction_of(state.sun_uv))) > math.cos(math.radians(1))
    energy = np.sort((luminance(env - spots[0].sky.numpy()) * texel_solid_angles(64)).ravel())[::-1]
    assert energy[:6].sum() > 0.8 * energy.sum()  # a disc of a few texels (a 16 x 16 block held ~1/40 each)


def test_dps_moves_the_albedo_at_its_own_rate_in_the_loop_and_the_refinement(problem_and_init):
    """dps's albedo rate is its own (half the other methods'), and a config's lr_albedo reaches both stages."""
    from dpi.solve.materials import MaterialRates

    problem, init = problem_and_init
    for entry, rate in (({}, 0.01), ({"lr_albedo": 0.03}, 0.03)):
        cfg = DPSConfig.from_dict({"steps": 2, **entry})
        _, state = start_run(problem, log_prior(), init, cfg, seed=0)
        rates = {id(g["params"][0]): g["lr"] for g in state.optimizer.param_groups}
        assert rates[id(state.materials.albedo)] == rate == cfg.refine.optimize(cfg).lr_albedo
    assert DPSConfig().lr_albedo < MaterialRates().lr_albedo
