"""The init's two readings in the workflow: which reading each sample starts from, and the record it leaves."""

import pytest
from stage_jobs import stage_job

from dpi.io.atomic import write_json
from dpi.solve.init import readings_line
from dpi.stages.inverse import sample_init


class FolderProblem:
    """Stands in for an InverseProblem: a decomposition is the folder it was read from."""

    def load_decomposition(self, folder):
        return folder


@pytest.mark.parametrize("record, expected", [
    ({"kept": "glossy", "other": "rough", "other_share": 0.5}, ["glossy", "rough", "glossy", "rough"]),
    ({"kept": "rough", "other": None, "other_share": 0.0}, ["rough"] * 4),
    (None, ["rough"] * 4),  # an init written before the readings: its one reading
])
def test_each_sample_starts_from_its_reading(tmp_path, record, expected):
    jobs = [stage_job(tmp_path / "captures" / "scene", tmp_path / "results", "dps", k) for k in range(4)]
    init = jobs[0].paths.sample_files("init")["trace"]
    init.parent.mkdir(parents=True)
    write_json(init, {"info": {"readings": record} if record else {}})
    drawn = [sample_init(job, FolderProblem()) for job in jobs]
    assert [reading for reading, _ in drawn] == expected
    for reading, folder in drawn:
        kept = (record or {}).get("kept", "rough")
        assert folder == (jobs[0].paths.sample_dir("init") if reading == kept else jobs[0].paths.other_reading_dir())


def test_the_init_log_line_says_what_was_fitted_and_kept():
    record = {"closing_loss": {"rough": 0.02, "glossy": 0.011}, "kept": "glossy", "other": "rough",
              "other_share": 0.25}
    line = readings_line(record)
    assert "rough 0.02" in line and "glossy 0.011" in line and "kept glossy" in line
    assert "the rough reading's probability 0.25" in line
    stopped = readings_line({"closing_loss": {"rough": 0.02, "glossy": 0.05}, "stopped": "glossy", "kept": "rough",
                            "other": None, "other_share": 0.0})
    assert "glossy stopped half-way" in stopped and "probability" not in stopped


def test_the_report_notes_two_readings_only_where_samples_start_from_both(tmp_path):
    from dpi.evaluation.report import readings_note

    scene = stage_job(tmp_path / "captures" / "scene", tmp_path / "results").paths
    assert readings_note(scene) == []  # no init yet
    init = scene.sample_files("init")["trace"]
    init.parent.mkdir(parents=True)
    record = {"closing_loss": {"rough": 0.02, "glossy": 0.011}, "kept": "glossy", "other": None, "other_share": 0.0}
    write_json(init, {"info": {"readings": record}})
    assert readings_note(scene) == []  # one reading clearly better
    write_json(init, {"info": {"readings": {**record, "other": "rough", "other_share": 1e-50}}})
    write_json(scene.sample_files("dps", 0)["trace"], {"info": {"reading": "glossy"}})
    assert readings_note(scene) == []  # the other reading is possible but starts no sample
    write_json(scene.sample_files("dps", 1)["trace"], {"info": {"reading": "rough"}})
    note, = readings_note(scene)
    assert "Two readings" in note and "1 of the samples start from the rough one" in note
