"""Resume files: a loop cut off after k steps and rerun continues to the result of an uninterrupted run;
another run's file or a broken one is ignored; the file is gone once the run is done."""

import math
import importlib
from contextlib import contextmanager

import pytest
import torch
from test_dps import tiny_prior

from dpi.capture import load_capture
from dpi.render.renderer import RenderConfig
from dpi.solve.checkpoint import run_key
from dpi.solve.dip import DeepImagePrior, DIPConfig
from dpi.solve.dps import DPSConfig, dps_sample
from dpi.solve.init import InitConfig, path_traced_init, starting_materials
from dpi.solve.optimize import FreeEnvMap, OptimizeConfig, fit_env_model
from dpi.solve.priors import smoothness_penalty
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.solve.trace import Trace

FIT = OptimizeConfig(iterations=7, views_per_step=1)
CLOSE = dict(rtol=1e-4, atol=1e-5)  # Dr.Jit's parallel gradient atomics: equal up to float rounding
NETWORK_CLOSE = dict(rtol=3e-3, atol=3e-3)
"""dip: a CNN generates the map, and 7 Adam steps through it grow that rounding to ~5e-4 on a loaded machine"""


class Interrupted(Exception):
    """Stands for the kill of a job."""


@pytest.fixture(scope="module")
def problem_and_init(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    return problem, path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept


@contextmanager
def cut_after(monkeypatch, owner, method: str, steps: int):
    """Make `owner.<method>` (a problem's or a module's, called once per loop step) raise Interrupted in step
    `steps`."""
    real, calls = getattr(owner, method), []

    def counted(*args, **kwargs):
        calls.append(1)
        if len(calls) > steps:
            raise Interrupted
        return real(*args, **kwargs)

    with monkeypatch.context() as patch, pytest.raises(Interrupted):
        patch.setattr(owner, method, counted)
        yield


ENV_MODELS = {
    "free": lambda init, seed: FreeEnvMap(init.env.log()),
    "dip": lambda init, seed: DeepImagePrior(4, init.env.log().mean(dim=(0, 1)),
                                             DIPConfig(channels=4, depth=2, code_channels=2), seed),
}


def run_fit(problem, init, env_model: str, seed: int, **checkpointing):
    """A joint fit (smoothness prior, one random view per step) from the init; returns (log-env, materials, trace)."""
    trace = Trace()
    log_env, materials = fit_env_model(problem, ENV_MODELS[env_model](init, seed), starting_materials(init), FIT,
                                       seed, trace, smoothness_penalty, 0.1, progress=False, **checkpointing)
    return log_env, materials, trace


def assert_same_fit(a, b, close=CLOSE):
    torch.testing.assert_close(a[0], b[0], **close)
    for (name, x), (_, y) in zip(a[1].items(), b[1].items()):
        torch.testing.assert_close(x, y, **close, msg=name)
    assert [s["step"] for s in a[2].steps] == [s["step"] for s in b[2].steps] == list(range(FIT.iterations))
    assert [s["loss"] for s in a[2].steps] == pytest.approx([s["loss"] for s in b[2].steps], rel=close["rtol"],
                                                            abs=close["atol"])


@pytest.mark.parametrize("env_model", ENV_MODELS)
def test_cut_fit_continues_to_the_uninterrupted_result(problem_and_init, tmp_path, monkeypatch, env_model):
    problem, init = problem_and_init
    resume = tmp_path / ".resume.pt"
    with cut_after(monkeypatch, problem, "data_loss", steps=5):
        run_fit(problem, init, env_model, seed=4, checkpoint=resume, checkpoint_every=3)
    assert resume.is_file()  # saved before step 3; steps 3 and 4 are lost and redone

    resumed = run_fit(problem, init, env_model, seed=4, checkpoint=resume, checkpoint_every=3)
    assert resumed[2].info["resumed_from_step"] == 3 and not resume.exists()
    assert_same_fit(resumed, run_fit(problem, init, env_model, seed=4), NETWORK_CLOSE if env_model == "dip" else CLOSE)


def test_cut_init_keeps_both_readings_half_way_and_continues(problem_and_init, tmp_path, monkeypatch):
    problem = problem_and_init[0]
    monkeypatch.setattr("dpi.solve.init.BOTH_FINISH", (0.0, math.inf))  # both readings fitted to the end
    cfg = InitConfig(iterations=8, views_per_step=1)
    resume = tmp_path / ".resume.pt"
    with cut_after(monkeypatch, problem, "data_loss", steps=4 + 4 + 2):  # both halves, then 2 steps of the rough
        path_traced_init(problem, cfg, seed=5, progress=False, checkpoint=resume, checkpoint_every=3)
    glossy_file = tmp_path / ".resume.glossy.pt"
    assert resume.is_file() and glossy_file.is_file()

    calls = []
    with monkeypatch.context() as patch:
        real = problem.data_loss
        patch.setattr(problem, "data_loss", lambda *a, **k: calls.append(1) or real(*a, **k))
        resumed = path_traced_init(problem, cfg, seed=5, progress=False, checkpoint=resume, checkpoint_every=3)
    assert len(calls) == (8 - 6) + (8 - 4)  # the rough fit from its save at step 6, the glossy from its half
    fresh = path_traced_init(problem, cfg, seed=5, progress=False)
    assert not resume.exists() and not glossy_file.exists()
    a, b = resumed.record, fresh.record
    assert a["kept"] == b["kept"] and a["closing_loss"] == pytest.approx(b["closing_loss"], rel=CLOSE["rtol"])
    torch.testing.assert_close(resumed.kept.env, fresh.kept.env, **CLOSE)
    for (name, x), (_, y) in zip(resumed.kept.materials.items(), fresh.kept.materials.items()):
        torch.testing.assert_close(x, y, **CLOSE, msg=name)
    assert [s["step"] for s in resumed.kept.trace.steps] == list(range(8))


@pytest.mark.parametrize("sampler", ["paper", "proximal"])
def test_cut_dps_sample_continues_to_the_uninterrupted_result(problem_and_init, tmp_path, monkeypatch, sampler):
    problem, init = problem_and_init
    monkeypatch.setattr("dpi.solve.dps.loop.STRIP_FRAMES", 3)
    cfg = DPSConfig.from_dict({"sampler": sampler, "steps": 4, "refine": {"iterations": 1},
                               **({"proximal": {"start_noise": 1.0}} if sampler == "proximal" else {})})
    resume = tmp_path / ".resume.pt"
    # the module whose code calls the network once a step: paper's own (with a graph), else state.predicted_step
    module = importlib.import_module("dpi.solve.dps.paper" if sampler == "paper" else "dpi.solve.dps.state")
    with cut_after(monkeypatch, module, "network_step", steps=3):
        dps_sample(problem, tiny_prior(), init, cfg, seed=1, progress=False, checkpoint=resume, checkpoint_every=2)
    assert resume.is_file()

    resumed = dps_sample(problem, tiny_prior(), init, cfg, seed=1, progress=False, checkpoint=resume,
                         checkpoint_every=2)
    fresh = dps_sample(problem, tiny_prior(), init, cfg, seed=1, progress=False)
    a, b = resumed.decomposition, fresh.decomposition
    assert a.trace.info["resumed_from_step"] == 2 and not resume.exists()
    torch.testing.assert_close(a.env, b.env, **CLOSE)
    for (name, x), (_, y) in zip(a.materials.items(), b.materials.items()):
        torch.testing.assert_close(x, y, **CLOSE, msg=name)
    assert [s["step"] for s in a.trace.steps] == list(range(4))
    assert [s["loss"] for s in a.trace.steps] == pytest.approx([s["loss"] for s in b.trace.steps], rel=CLOSE["rtol"],
                                                               abs=CLOSE["atol"])
    assert len(resumed.snapshots) == len(fresh.snapshots) == 3
    for x, y in zip(resumed.snapshots, fresh.snapshots):
        torch.testing.assert_close(x, y, **CLOSE)


@pytest.mark.parametrize("stale", ["other run", "unreadable"])
def test_a_file_not_of_this_run_is_ignored(problem_and_init, tmp_path, monkeypatch, capsys, stale):
    problem, init = problem_and_init
    resume = tmp_path / ".resume.pt"
    if stale == "other run":
        with cut_after(monkeypatch, problem, "data_loss", steps=4):
            run_fit(problem, init, "free", seed=8, checkpoint=resume, checkpoint_every=3)
    else:
        resume.write_bytes(b"not a checkpoint")
    assert resume.is_file()

    result = run_fit(problem, init, "free", seed=9, checkpoint=resume, checkpoint_every=3)
    assert result[2].info["resumed_from_step"] is None and not resume.exists()
    assert "starting afresh" in capsys.readouterr().out
    assert_same_fit(result, run_fit(problem, init, "free", seed=9))


def test_run_key_tells_runs_apart():
    start = torch.zeros(2, 3)
    key = run_key({"lr": 0.1, "steps": 5}, 3, start)
    assert key == run_key({"steps": 5, "lr": 0.1}, 3, start.clone())
    changed = start.clone()
    changed[1, 2] = 1e-7
    assert len({key, run_key({"lr": 0.1, "steps": 5}, 3, changed), run_key({"lr": 0.1, "steps": 6}, 3, start),
                run_key({"lr": 0.1, "steps": 5}, 4, start), run_key({"lr": 0.1, "steps": 5}, 3, start.double())}) == 5
