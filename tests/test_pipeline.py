"""dpi.config.pipeline and dpi.io.layout: one config resolution, one typed view of it, one place for every path."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import yaml

from dpi.cli import main
from dpi.config.pipeline import DEFAULT_CONFIG, Pipeline, merge, read_yaml, resolve_config
from dpi.io.layout import INIT, Layout, package_data
from dpi.prior.sample import DEFAULT_FAMILY, DEFAULT_MODELS
from dpi.render.renderer import RenderConfig

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def elsewhere(tmp_path, monkeypatch):
    """Each test runs in an empty directory: no ./config.yaml unless it writes one."""
    monkeypatch.chdir(tmp_path)


def test_merge_is_snakemakes_dicts_by_key_and_anything_else_replaced():
    base = {"a": {"x": 1, "y": 2}, "l": [1, 2], "s": 1}
    assert merge(base, {"a": {"y": 3}, "l": [3], "s": {"t": 1}}) == {"a": {"x": 1, "y": 3}, "l": [3], "s": {"t": 1}}
    assert base == {"a": {"x": 1, "y": 2}, "l": [1, 2], "s": 1}


def test_layers_defaults_then_local_config_then_files_then_preset(tmp_path):
    defaults = Pipeline(resolve_config())
    assert "spp" not in defaults.config["render"]  # the default preset sets nothing: the dataclass's default holds
    assert defaults.solve_settings().render.spp == RenderConfig().spp
    (tmp_path / "config.yaml").write_text(yaml.safe_dump({"render": {"spp": 3}, "problem": {"texture_size": 8}}))
    local = resolve_config()
    assert local["render"]["spp"] == 3 and local["problem"] == {"texture_size": 8}
    later = resolve_config({"problem": {"texture_size": 4}}, {"preset": "draft", "render": {"max_depth": 2}})
    assert later["problem"]["texture_size"] == 4 and later["render"] == {"spp": 3, "max_depth": 2}
    assert later["init"]["iterations"] == later["presets"]["draft"]["init"]["iterations"]  # unset: the preset's


def test_a_left_out_key_means_its_dataclass_default():
    pipeline = Pipeline(resolve_config())
    assert "max_depth" not in pipeline.config["render"]
    assert pipeline.solve_settings(3).render == RenderConfig(threads=3)
    assert pipeline.describe()["render"]["max_depth"] == RenderConfig().max_depth


def test_the_schema_holds_no_defaults():
    schema = (package_data("config.schema.yaml")).read_text()
    assert "default:" not in schema.replace("defaults", "")


def test_scene_family_and_its_prior():
    pipeline = Pipeline(resolve_config({"synthetic": {"lit": {"prior": "indoor"}}}))
    assert pipeline.scene_family("demo") == DEFAULT_FAMILY and pipeline.scene_family("lit") == "indoor"
    assert pipeline.prior_checkpoint("lit") == DEFAULT_MODELS["indoor"] and DEFAULT_MODELS["indoor"].is_file()
    assert pipeline.method_prior("demo", "none") is None and pipeline.method_prior("demo", "dps").is_file()
    own = Pipeline(resolve_config({"illumination_prior": {"family": "indoor", "checkpoints": {"indoor": "m.pt"}}}))
    assert own.scene_family("demo") == "indoor" and own.prior_checkpoint("demo") == Path("m.pt")


def test_prior_training_settings_shared_then_per_family():
    pipeline = Pipeline(resolve_config({"prior": {"steps": 7, "outdoor": {"count": 5}}}))
    indoor, outdoor = pipeline.prior_job("indoor"), pipeline.prior_job("outdoor")
    assert (indoor.count, indoor.data_height) == (1200, 32) and outdoor.count == 5
    cfg = outdoor.train_config()
    assert cfg.steps == 7 and cfg.model == "small_32x64"


def test_wildcard_patterns_are_the_layout_of_real_names():
    layout = Layout(Path("results"), Path("captures"))
    pattern, real = layout.scene("{scene}"), layout.scene("blob")
    fill = {"scene": "blob", "method": "dps", "k": 2}
    assert str(pattern.sample_files("{method}", "{k}")["env"]).format(**fill) == str(real.sample_files("dps", 2)["env"])
    assert str(pattern.evaluation("{method}", "{k}")).format(**fill) == str(real.evaluation("dps", 2))
    assert real.sample_dir(INIT) == real.root / INIT and real.sample_files(INIT)["trace"].name == "log.json"


def test_dpi_config_prints_the_resolved_settings(tmp_path, capsys):
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump({"samples": 5}))
    assert main(["config", "--config", "mine.yaml"]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed["samples"] == 5 and printed["scenes"] == read_yaml(DEFAULT_CONFIG)["scenes"]
    assert printed["method_params"]["dps"]["samples"] == 3
    assert "start_noise" in printed["method_params"]["dps"]["proximal"]


@pytest.mark.parametrize("given", [{}, {"preset": "draft"},
                                   {"method_params": {m: {} for m in ("none", "smoothness", "dip", "sds", "dps")}},
                                   {"method_params": {"none": {"iterations": 50}, "dip": {"lr_env": 0.01}}}])
def test_dpi_configs_output_reads_back_to_itself(tmp_path, capsys, monkeypatch, given):
    """`dpi config --config <(dpi config --config X)` prints what `dpi config --config X` does, for every section."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.yaml").write_text(yaml.safe_dump(given))
    assert main(["config", "--config", "x.yaml"]) == 0
    first = capsys.readouterr().out
    (tmp_path / "printed.yaml").write_text(first)
    assert main(["config", "--config", "printed.yaml"]) == 0
    assert capsys.readouterr().out == first


def test_a_bad_config_file_is_one_message(tmp_path, capsys):
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump({"method_params": {"dps": {"stepz": 3}}}))
    assert main(["init", "demo", "--config", "bad.yaml"]) == 2
    assert "method_params.dps.stepz: unknown DPSConfig setting" in capsys.readouterr().err


def test_no_import_cycles_among_dpi_modules():
    """Every import between dpi modules, at module level or inside a function, runs one way."""
    modules = {".".join(p.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__"): p
               for p in (REPO / "dpi").rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):  # imports for type checkers only do not run
            if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
                node.body = []
        targets = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        graph[name] = {t for t in targets if t in modules and t != name}

    def reaches(start: str, goal: str, seen: set[str]) -> bool:
        return any(n == goal or (n not in seen and not seen.add(n) and reaches(n, goal, seen)) for n in graph[start])

    assert [m for m in graph if reaches(m, m, set())] == []


def test_a_method_left_out_of_method_params_keeps_its_own_defaults():
    from dpi.solve.methods import method_config

    assert method_config("none", {}).optimize.iterations == 150  # ClassicConfig's, not OptimizeConfig's 400
    assert method_config("dip", {"iterations": 20}).optimize.lr_env == 0.01  # the rest stays dip's own
