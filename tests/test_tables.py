"""Generated result tables: known answers on a tiny CSV, the markers' round trip, and the committed documents
up to date with the committed CSVs."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
from doc_tables import main, render_document, update_tables  # noqa: E402
from table_format import Metric, grouped_table, stats  # noqa: E402


def test_stats_known_answer_skips_non_numbers():
    mean, std = stats([1.0, 3.0, "", float("nan"), None])
    assert mean == 2.0 and std == 1.0
    assert stats(["", None]) is None


def test_grouped_table_means_spread_and_best():
    rows = [{"group": "a", "method": "x", "v": 1.0}, {"group": "a", "method": "x", "v": 3.0},
            {"group": "a", "method": "y", "v": 5.0}, {"group": "b", "method": "x", "v": 0.5}]
    table = grouped_table(rows, ("group", "method"), (Metric("value", "v", ".1f", +1),), rank_by="group")
    lines = table.splitlines()
    assert lines[0] == "| group | method | n | value |"
    assert lines[2] == "| a | x | 2 | 2.0 ± 1.0 |"
    assert lines[3] == "| a | y | 1 | **5.0** |"  # the best of group a; one row has no spread
    assert lines[4] == "| b | x | 1 | 0.5 |"  # alone in its group: nothing to rank


def test_markers_are_replaced_and_unknown_names_refused(tmp_path):
    text = "intro\n<!-- table:presets -->\nstale\n<!-- /table:presets -->\nend\n"
    out = render_document(text, tmp_path)
    assert out.startswith("intro\n<!-- table:presets -->\n| preset |") and out.endswith("<!-- /table:presets -->\nend\n")
    assert "stale" not in out and render_document(out, tmp_path) == out
    with pytest.raises(KeyError, match="nope"):
        render_document("<!-- table:nope -->\n<!-- /table:nope -->", tmp_path)


def test_committed_documents_match_their_csvs():
    assert update_tables(ROOT, check=True) == [], "run `make tables` and commit the documents"


def test_tables_check_fails_on_a_stale_document(tmp_path, capsys):
    (tmp_path / "README.md").write_text("<!-- table:presets -->\nold\n<!-- /table:presets -->\n")
    assert main(["--root", str(tmp_path), "--check"]) == 2
    assert "out of date" in capsys.readouterr().out
    assert main(["--root", str(tmp_path)]) == 0
    assert main(["--root", str(tmp_path), "--check"]) == 0


def test_every_shown_table_has_a_study_folder_and_a_command_make_studies_runs():
    from doc_tables import listing

    makefile = (ROOT / "Makefile").read_text().replace("$(VENV)", ".venv").replace("$(PANORAMAS)", "../shared/panoramas")
    rows = listing(ROOT)
    assert {"posterior", "posterior_full", "calibration", "contraction", "hotdog"} <= {r[0] for r in rows}
    for table, documents, folder, commands in rows:
        if table == "presets":  # read from dpi's default config, not from a study's CSV
            continue
        assert commands != "-", f"{folder}/README.md gives no command for table {table} ({documents})"
        for command in commands.split(" ; "):
            assert command.split(" WORK")[0] in makefile, f"make studies does not run {command!r}"
