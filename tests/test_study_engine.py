"""The study engine: rows carry commit and settings hash, a rerun with the same settings reuses its rows and one
with other settings writes new rows, and the tables show the newest row of each key."""

from pathlib import Path

import pytest

from dpi.prior.sample import DEFAULT_MODELS
from dpi.studies.engine import (PROVENANCE, SAMPLE_COLUMNS, SETTINGS_STAMP, Job, append_row, claim_sample_dir,
                                current_commit, latest, read_rows, run_study, settings_hash)
from dpi.studies.scenes import real_light_scenes

SCORED: list[tuple] = []


def fake_score(job: Job) -> dict:
    """A sample's row without drawing it: its metrics follow its settings."""
    SCORED.append((job.scene, job.seed, job.method_cfg["steps"]))
    return {"scene": job.scene, "group": job.group, "method": job.method, "sampler": job.sampler, "seed": job.seed,
            **{k: float(job.method_cfg["steps"]) for k in SAMPLE_COLUMNS[5:]}}


def jobs(root: Path, steps: int) -> list[Job]:
    return [Job(root, "blob", "ambiguous", {"shape": "blob"}, "dps", "proximal", seed, {"steps": steps}, {})
            for seed in (0, 1)]


def test_settings_hash_is_stable_and_tells_settings_apart():
    assert settings_hash({"a": 1, "b": [1, 2]}) == settings_hash({"b": [1, 2], "a": 1})
    assert settings_hash({"a": 1}) != settings_hash({"a": 2})
    assert jobs(Path("x"), 10)[0].settings_hash != jobs(Path("x"), 20)[0].settings_hash
    assert jobs(Path("x"), 10)[0].settings_hash == jobs(Path("y"), 10)[1].settings_hash  # not the seed, not the folder


def test_rows_carry_provenance_and_a_foreign_header_is_refused(tmp_path):
    out = tmp_path / "study.csv"
    append_row(out, {"scene": "s", "value": 1.5}, ("scene", "value"), "abc")
    assert out.read_text().splitlines()[0] == "scene,value," + ",".join(PROVENANCE)
    row = read_rows(out)[0]
    assert row == {"scene": "s", "value": 1.5, "commit": current_commit(), "settings_hash": "abc"}
    with pytest.raises(ValueError, match="study.csv.*another --out"):
        append_row(out, {"scene": "s", "other": 1}, ("scene", "other"), "abc")


def test_rerun_reuses_rows_and_other_settings_add_rows(tmp_path):
    out = tmp_path / "study.csv"
    SCORED.clear()
    first = run_study(jobs(tmp_path, 10), out, SAMPLE_COLUMNS, fake_score, 0, prepare=lambda job: None)
    assert len(first) == 2 and SCORED == [("blob", 0, 10), ("blob", 1, 10)]
    again = run_study(jobs(tmp_path, 10), out, SAMPLE_COLUMNS, fake_score, 0, prepare=lambda job: None)
    assert again == first and len(SCORED) == 2  # nothing drawn again
    other = run_study(jobs(tmp_path, 20), out, SAMPLE_COLUMNS, fake_score, 0, prepare=lambda job: None)
    assert [r["env_psnr"] for r in other] == [20.0, 20.0] and len(SCORED) == 4
    rows = read_rows(out)
    assert len(rows) == 4 and len({r["settings_hash"] for r in rows}) == 2
    newest = latest(rows, ("scene", "method", "sampler", "seed"))
    assert [r["env_psnr"] for r in newest] == [20.0, 20.0]


def test_a_sample_drawn_with_other_settings_is_drawn_again(tmp_path):
    """The sample folder is keyed by method and seed; its stamp tells whose settings drew what is in it."""
    ten, twenty = jobs(tmp_path, 10)[0], jobs(tmp_path, 20)[0]
    claim_sample_dir(ten)
    (ten.sample_dir / "envmap.exr").write_text("drawn")
    claim_sample_dir(ten)
    assert (ten.sample_dir / "envmap.exr").exists()  # same settings: kept (a killed draw resumes)
    claim_sample_dir(twenty)
    assert not (ten.sample_dir / "envmap.exr").exists()
    assert (twenty.sample_dir / SETTINGS_STAMP).read_text() == twenty.settings_hash


def test_a_job_reads_the_configured_prior_of_its_family(tmp_path):
    config = {"illumination_prior": {"checkpoints": {"outdoor": "big.pt"}}}
    outdoor, indoor = ({"shape": "blob", "prior": family} for family in ("outdoor", "indoor"))
    assert Job(tmp_path, "a", "g", outdoor, "dps", "", 0, {}, config).pipeline.prior_checkpoint("a") == Path("big.pt")
    assert Job(tmp_path, "b", "g", indoor, "dps", "", 0, {}, config).pipeline.prior_checkpoint("b") == \
        DEFAULT_MODELS["indoor"]
    assert Job(tmp_path, "a", "g", outdoor, "dps", "", 0, {}, config).settings_hash != \
        Job(tmp_path, "a", "g", outdoor, "dps", "", 0, {}, {"illumination_prior": {"checkpoints": {}}}).settings_hash


def test_real_light_scenes_need_the_manifest_panoramas(tmp_path):
    (tmp_path / "my_own.hdr").write_bytes(b"")  # a user's own panorama is training data, never a held-out light
    with pytest.raises(FileNotFoundError, match="no outdoor panoramas in the held_out split"):
        real_light_scenes(tmp_path)
    job = Job(tmp_path, "a", "real", {"environment": str(tmp_path / "x" / "sky.hdr")}, "dps", "", 0, {}, {})
    elsewhere = Job(tmp_path, "a", "real", {"environment": "/data/sky.hdr"}, "dps", "", 0, {}, {})
    assert job.settings_hash == elsewhere.settings_hash  # a panorama by its name, not where it lies


def test_a_default_written_out_hashes_like_one_left_out(tmp_path):
    """The hash reads the resolved settings: spelling out a dataclass default changes nothing, another value does."""
    def job(config: dict) -> Job:
        return Job(tmp_path, "blob", "ambiguous", {"shape": "blob"}, "none", "", 0, {}, config)

    assert job({}).settings_hash == job({"render": {"spp": 16}, "init": {"iterations": 200}}).settings_hash
    assert job({}).settings_hash != job({"render": {"spp": 8}}).settings_hash


def test_held_out_light_scenes_are_valid_and_apart_from_every_other():
    """Each held-out scene builds a synthetic capture, and none shares an object (shape and seed) with a study's or a
    design scene: what it judges was not chosen on it."""
    from dpi.studies.scenes import DEV_SCENES, HELD_OUT_LIGHT_SCENES, POSTERIOR_SCENES, REAL_LIGHT_SCENES
    from dpi.synth.capture import SynthConfig

    def objects(scenes):
        return {(synth.get("shape", "blob"), synth["seed"]) for _, synth in scenes.values()}

    for _, synth in HELD_OUT_LIGHT_SCENES.values():
        SynthConfig.from_dict({k: v for k, v in synth.items() if k not in ("panorama", "prior")})
    assert not objects(HELD_OUT_LIGHT_SCENES) & objects({**POSTERIOR_SCENES, **REAL_LIGHT_SCENES, **DEV_SCENES})
