"""Doors a careless or hostile input could open, each closed with one line: no message quotes a host file's
contents, nothing is read from outside the capture, YAML alias bombs and deep nests stop at once, a results folder
has one writer, written files follow the umask, and every file named after a view fits the file system."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
import trimesh
from capture_helpers import edit_transforms, make_capture

from dpi.capture import CaptureError, load_capture, read_scene_options
from dpi.capture.folder import MAX_VIEW_NAME_BYTES
from dpi.config.pipeline import read_yaml as read_config
from dpi.evaluation.relighting import RELIGHT_MAPS, relit_name
from dpi.io.atomic import write_text
from dpi.io.lock import ResultsLocked, lock_results
from dpi.io.structured import MAX_ALIASES, MAX_DEPTH, MAX_NODES, StructuredFileError, read_json, read_yaml

SECRET = "root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1:daemon:/usr/sbin:/usr/sbin/nologin\n"


@pytest.fixture
def host_file(tmp_path):
    """A file outside every capture, holding lines that must never appear in a message."""
    path = tmp_path / "host" / "passwd"
    path.parent.mkdir()
    path.write_text(SECRET)
    return path


def assert_quiet(message: str) -> None:
    """A message holds none of the host file's lines and is one line."""
    assert "root:x" not in message and "daemon" not in message and "\n" not in message, message


def test_a_scene_yaml_linked_to_a_host_file_is_refused_without_its_contents(tmp_path, host_file):
    root = make_capture(tmp_path / "s")
    (root / "scene.yaml").symlink_to(host_file)
    with pytest.raises(CaptureError, match="scene.yaml: scene.yaml lies outside the capture folder") as info:
        read_scene_options(root)
    assert_quiet(str(info.value))


def test_unknown_keys_that_are_not_option_names_are_counted_not_quoted(tmp_path):
    root = make_capture(tmp_path / "s")
    lines = "".join(f"{line!r}: 1\n" for line in SECRET.splitlines())  # a host file's lines as keys
    (root / "scene.yaml").write_text("prior: outdoor\npriors: indoor\n" + lines)
    with pytest.raises(CaptureError, match=r"unknown keys: priors and 2 that are not option names") as info:
        read_scene_options(root)
    assert_quiet(str(info.value))


@pytest.mark.parametrize("link", ["images/r_0.png", "masks/r_1.png", "gt/albedo.exr", "mesh.ply"])
def test_a_capture_file_linked_from_elsewhere_is_refused(tmp_path, link):
    root = make_capture(tmp_path / "s")
    outside = tmp_path / "elsewhere" / (root / link).name
    outside.parent.mkdir()
    shutil.move(root / link, outside)
    (root / link).symlink_to(outside)
    with pytest.raises(CaptureError, match="lies outside the capture folder"):
        load_capture(root)


def test_an_images_folder_linked_to_the_host_is_refused_before_it_is_listed(tmp_path):
    root = make_capture(tmp_path / "s")
    shutil.rmtree(root / "images")
    (root / "images").symlink_to("/")
    with pytest.raises(CaptureError, match=r"images: the image folder lies outside the capture folder") as info:
        load_capture(root)
    assert "etc" not in str(info.value) and "bin" not in str(info.value)


@pytest.mark.parametrize("make, cause", [
    (lambda p: (p.unlink(), p.symlink_to(p.name)), "is a link that loops or cannot be followed"),
    (lambda p: (p.unlink(), os.mkfifo(p)), "is not a regular file"),
])
def test_a_looping_link_or_a_pipe_among_the_images_is_one_line(tmp_path, make, cause):
    root = make_capture(tmp_path / "s")
    make(root / "images" / "r_1.png")
    start = time.perf_counter()
    with pytest.raises(CaptureError, match=cause) as info:
        load_capture(root)
    assert "r_1.png" in str(info.value) and time.perf_counter() - start < 1.0


def test_a_mask_path_out_of_the_capture_is_refused(tmp_path, host_file):
    root = make_capture(tmp_path / "s", masks=False)

    def point_out(data):
        for frame in data["frames"]:
            frame["mask_path"] = str(host_file)
    edit_transforms(root, point_out)
    with pytest.raises(CaptureError, match="the mask_path of frame .* lies outside the capture folder") as info:
        load_capture(root)
    assert_quiet(str(info.value))


def test_a_scene_xml_mesh_out_of_the_capture_is_refused(tmp_path):
    root = make_capture(tmp_path / "s", mesh=False)
    mesh = tmp_path / "elsewhere" / "object.obj"
    mesh.parent.mkdir()
    trimesh.creation.icosphere(subdivisions=1).export(mesh)
    (root / "scene.xml").write_text('<scene version="3.0.0"><shape type="obj"><string name="filename" '
                                    'value="../elsewhere/object.obj"/></shape></scene>')
    with pytest.raises(CaptureError, match="the mesh of scene.xml lies outside the capture folder"):
        load_capture(root)


def bomb(levels: int = 9) -> str:
    """The billion-laughs YAML: each level lists the one below nine times."""
    lines = ['a0: &a0 ["lol"]']
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def doubling_bomb(levels: int = 31) -> str:
    """An alias chain under the alias count: each level lists the one below twice (2^levels values, 1 kB)."""
    lines = ['a0: &a0 ["lol"]'] + [f"a{i}: &a{i} [*a{i - 1}, *a{i - 1}]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("text, problem", [
    (bomb(), f"more than {MAX_ALIASES} aliases"),
    (doubling_bomb(), f"expand it to more than {MAX_NODES} values"),
    ("a: " + "[" * (MAX_DEPTH + 50) + "]" * (MAX_DEPTH + 50) + "\n", f"nested deeper than {MAX_DEPTH} levels"),
    ("a: " + "[" * 100000 + "\n", f"nested deeper than {MAX_DEPTH} levels"),
])
def test_alias_bombs_and_deep_nests_stop_at_once_in_every_yaml_reader(tmp_path, text, problem):
    root = make_capture(tmp_path / "s")
    (root / "scene.yaml").write_text(text)
    (tmp_path / "config.yaml").write_text(text)
    for read in (lambda: read_scene_options(root), lambda: read_config(tmp_path / "config.yaml")):
        start = time.perf_counter()
        with pytest.raises((CaptureError, StructuredFileError), match=problem) as info:
            read()
        assert time.perf_counter() - start < 1.0
        assert "\n" not in str(info.value)


def test_deep_json_and_huge_files_stop_with_one_line(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 200000 + "]" * 200000)
    start = time.perf_counter()
    with pytest.raises(StructuredFileError, match=f"deep.json: nested deeper than {MAX_DEPTH} levels"):
        read_json(deep)
    assert time.perf_counter() - start < 1.0
    huge = tmp_path / "huge.yaml"
    huge.write_bytes(b"#" * 64 + b"\n")
    with pytest.raises(StructuredFileError, match="huge.yaml: 65 bytes, more than the 64"):
        read_yaml(huge, max_bytes=64)


@pytest.mark.parametrize("text, where", [("a:\n\tb: 1\n", "line 2, column 1"),
                                         ("a: !python/object:os.system x\n", "line 1, column 4")])
def test_a_yaml_error_is_one_line_with_file_line_and_column(tmp_path, text, where):
    path = tmp_path / "my.yaml"
    path.write_text(text)
    with pytest.raises(StructuredFileError, match=f"my.yaml: invalid YAML .*{where}") as info:
        read_config(path)
    assert "\n" not in str(info.value)


def test_a_transforms_json_with_a_syntax_error_names_line_and_column(tmp_path):
    root = make_capture(tmp_path / "s")
    (root / "transforms.json").write_text('{"frames": [\n  {"file_path": "r_0",}\n]}')
    with pytest.raises(CaptureError, match=r"transforms.json: invalid JSON \(.* at line 2, column 23\)"):
        load_capture(root)


def test_written_files_follow_the_umask(tmp_path):
    old = os.umask(0o002)
    try:
        write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o664


HOLD = "import sys, time; from dpi.io.lock import lock_results; lock_results(sys.argv[1]); " \
       "print('held', flush=True); " \
       "time.sleep(60)"


def test_a_second_writer_of_a_results_folder_is_refused_and_a_killed_one_frees_it(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path / "results")], stdout=subprocess.PIPE,
                              text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(ResultsLocked, match=rf"another dpi run \(process {holder.pid}\) is writing here"):
            lock_results(tmp_path / "results")
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    lock_results(tmp_path / "results")  # the kernel released the killed holder's lock


def test_a_lock_file_that_is_a_link_is_not_followed(tmp_path, host_file):
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / ".dpi.lock").symlink_to(host_file)
    with pytest.raises(ResultsLocked, match="cannot open the results lock"):
        lock_results(tmp_path / "results")
    assert host_file.read_text() == SECRET


def test_a_lock_that_is_a_fifo_and_a_results_dir_that_is_a_file_are_one_line(tmp_path):
    (tmp_path / "results").mkdir()
    os.mkfifo(tmp_path / "results" / ".dpi.lock")
    start = time.perf_counter()
    with pytest.raises(ResultsLocked, match="the results lock is not a plain file; remove it"):
        lock_results(tmp_path / "results")
    assert time.perf_counter() - start < 1.0
    (tmp_path / "file").write_text("x")
    with pytest.raises(ResultsLocked, match="results_dir is a file, not a folder"):
        lock_results(tmp_path / "file")


def test_every_file_named_after_the_longest_view_fits_the_file_system(tmp_path):
    """The longest name a job writes around a view (a relit view's truth, as an atomic write's temporary
    name: a dot, 8 random characters and a dot more) stays within 255 bytes."""
    view = "v" * MAX_VIEW_NAME_BYTES
    longest = max(len(relit_name(light, view, truth)) for light in RELIGHT_MAPS for truth in (False, True))
    assert longest + len(".exr") + 10 <= 255
    write_text(tmp_path / f"{relit_name(max(RELIGHT_MAPS, key=len), view, True)}.exr", "x")


def test_an_image_named_longer_than_a_view_may_be_is_refused(tmp_path):
    root = make_capture(tmp_path / "s", transforms=False, masks=False)
    long_name = "v" * (MAX_VIEW_NAME_BYTES + 1)
    os.rename(root / "images" / "r_0.png", root / "images" / f"{long_name}.png")
    with pytest.raises(CaptureError, match=f"has a name of {MAX_VIEW_NAME_BYTES + 1} bytes"):
        load_capture(root)


def test_the_config_dpi_prints_is_accepted_back(tmp_path):
    printed = subprocess.run([sys.executable, "-m", "dpi.cli", "config"], capture_output=True, text=True, check=True)
    (tmp_path / "printed.yaml").write_text(printed.stdout)
    again = subprocess.run([sys.executable, "-m", "dpi.cli", "config", "--config", str(tmp_path / "printed.yaml")],
                           capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert again.stdout == printed.stdout
    assert json.dumps(read_config(tmp_path / "printed.yaml"))


def test_an_image_name_with_a_brace_is_refused_in_one_line(tmp_path):
    root = make_capture(tmp_path / "s", transforms=False, masks=False)
    os.rename(root / "images" / "r_0.png", root / "images" / "r_{0}.png")
    with pytest.raises(CaptureError, match=r"images: an image name holds a brace"):
        load_capture(root)


def test_a_link_anywhere_inside_results_is_named(tmp_path):
    from dpi.io.atomic import OutputError, check_no_links

    check_no_links(tmp_path / "absent")  # nothing written yet: nothing to refuse
    (tmp_path / "results" / "demo" / "dps").mkdir(parents=True)
    check_no_links(tmp_path / "results")
    (tmp_path / "outside").mkdir()
    (tmp_path / "results" / "demo" / "dps" / "0").symlink_to(tmp_path / "outside", target_is_directory=True)
    with pytest.raises(OutputError, match=r"results/demo/dps/0: is a link \(to .*outside\) inside results_dir"):
        check_no_links(tmp_path / "results")
