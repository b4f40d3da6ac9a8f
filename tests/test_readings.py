"""The init's two readings in the workflow: which reading each sample starts from, and the record it leaves."""

import pytest
from stage_jobs import stage_job

from dpi.io.atomic import write_json
from dpi.stages.inverse import reading_line, sample_init


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
    line = reading_line(record)
    assert "rough 0.02" in line and "glossy 0.011" in line and "kept glossy" in line
    assert "25% of the samples from the rough reading" in line
    stopped = reading_line({"closing_loss": {"rough": 0.02, "glossy": 0.05}, "stopped": "glossy", "kept": "rough",
                            "other": None, "other_share": 0.0})
    assert "glossy stopped half-way" in stopped and "samples from" not in stopped
