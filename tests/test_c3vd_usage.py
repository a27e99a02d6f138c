"""What a new user of ``colonbench suites build c3vd`` meets: a zip given as the download, lists in messages,
folders the importer does not read, a missing argument, and trying the importer without the dataset. On the
synthetic C3VD-layout sequence of tests/test_c3vd.py."""

import importlib.util
import re
import shutil
from pathlib import Path

import pytest

from colonbench.cli import main
from colonbench.errors import InputError
from colonbench.video import c3vd
from colonbench.video.c3vd_synth import C3VD_CAMERA, phantom_tube, withdrawal_poses, write_sequence

ROOT = Path(__file__).resolve().parents[1]
CAMERA = C3VD_CAMERA.scaled(0.1)          # as tests/test_c3vd.py: C3VD's lens on a 135 x 108 image


@pytest.fixture(scope="module")
def download(tmp_path_factory):
    """tests/test_c3vd.py's synthetic download: one registered sequence of 24 frames, the intrinsics beside it."""
    mesh, line = phantom_tube()
    root = tmp_path_factory.mktemp("c3vd-usage")
    write_sequence(root / "c1_cecum_t1_v1", mesh, withdrawal_poses(line, 24), CAMERA)
    return root


def _nothing_in(folder: Path) -> bool:
    return not folder.exists() or not any(folder.iterdir())


def test_a_zip_given_as_the_download_is_told_to_unzip(tmp_path, capsys):
    data = tmp_path / "suites"
    zipped = tmp_path / "c1_cecum_t1_v1.zip"
    zipped.write_bytes(b"PK\x03\x04")
    assert main(["suites", "build", "c3vd", "--from", str(zipped), "--data", str(data)]) == 2
    err = capsys.readouterr().err
    assert f"{zipped}: a file, not a folder" in err and "unzip it" in err, err
    assert "no such folder" not in err and "Traceback" not in err and _nothing_in(data)
    other = tmp_path / "notes.txt"
    other.write_text("not a download")
    with pytest.raises(InputError, match=r"notes\.txt: a file, not a folder; --from takes the folder") as refused:
        c3vd.find_download(other)
    assert "unzip" not in str(refused.value)


def test_a_list_of_names_is_shown_whole_when_short():
    from colonbench.errors import listing

    assert listing(["a"]) == "a" and listing(["a", "b"]) == "a, b" and listing([]) == ""
    assert listing("abcd") == "a, b, c, d"
    assert listing("abcdef") == "a, b, c, d and 2 more" and listing("abcdef", most=5) == "a, b, c, d, e and 1 more"


def test_one_zip_in_the_download_is_named_without_dots(tmp_path):
    (tmp_path / "one").mkdir()
    (tmp_path / "one" / "c1_cecum_t1_v1.zip").write_bytes(b"PK")
    with pytest.raises(InputError) as one:
        c3vd.find_download(tmp_path / "one")
    assert "1 .zip file(s) (c1_cecum_t1_v1.zip): unzip them first" in str(one.value)
    assert "..." not in str(one.value)
    (tmp_path / "six").mkdir()
    for k in range(6):
        (tmp_path / "six" / f"c{k}_cecum_t1_v1.zip").write_bytes(b"PK")
    with pytest.raises(InputError, match=r"6 \.zip file\(s\) \(c0_cecum_t1_v1\.zip, .* c3_cecum_t1_v1\.zip and 2 "
                                         r"more\): unzip them first"):
        c3vd.find_download(tmp_path / "six")


def test_one_checked_depth_frame_without_a_valid_pixel_is_named_without_dots(tmp_path):
    import numpy as np
    import tifffile

    frame = tmp_path / "0000_depth.tiff"
    tifffile.imwrite(frame, np.zeros((CAMERA.height, CAMERA.width), np.uint16))
    with pytest.raises(InputError) as refused:
        c3vd.check_conventions("empty", np.eye(4)[None], [frame], CAMERA, lambda p: np.zeros(len(p)))
    assert "its checked depth frames (0000_depth.tiff) hold no valid pixel" in str(refused.value)


def test_folders_the_importer_does_not_read_are_named_with_the_reason(download, tmp_path, capsys):
    root = tmp_path / "dl"
    shutil.copytree(download, root)
    (root / "c1_cecum_t1_v1" / "rgb").mkdir()                     # a sequence's own folders are not named
    (root / "c1_cecum_t1_v1" / "rgb" / "0000_color.png").write_bytes(b"png")
    (root / "cfhq190l_checkerboard_images").mkdir()                     # nothing the importer reads
    (root / "cfhq190l_checkerboard_images" / "0000.tiff").write_bytes(b"tiff")
    (root / "c2_sigmoid_t1_v1").mkdir()                                # a coverage mesh whose pose.txt is missing
    shutil.copy(root / "c1_cecum_t1_v1" / "coverage_mesh.obj", root / "c2_sigmoid_t1_v1" / "coverage_mesh.obj")
    (root / "more" / "c3_desc_t1_v1" / "depth").mkdir(parents=True)   # depth frames without pose.txt, deeper
    shutil.copy(root / "c1_cecum_t1_v1" / "depth" / "0000_depth.tiff", root / "more" / "c3_desc_t1_v1" / "depth")
    (root / ".hidden").mkdir()
    sequences, _, skipped = c3vd.find_download(root)
    assert [s.name for s in sequences] == ["c1_cecum_t1_v1"]
    why = {s["folder"]: s["reason"] for s in skipped}
    assert set(why) == {"cfhq190l_checkerboard_images", "c2_sigmoid_t1_v1", "more"}, why
    assert "no pose.txt in it or below" in why["cfhq190l_checkerboard_images"]
    assert "coverage_mesh.obj" in why["c2_sigmoid_t1_v1"] and "no pose.txt" in why["c2_sigmoid_t1_v1"]
    assert "c3_desc_t1_v1" in why["more"] and "depth frames" in why["more"]
    data = tmp_path / "suites"
    assert main(["suites", "build", "c3vd", "--from", str(root), "--data", str(data), "--frames-every", "6",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "skipped cfhq190l_checkerboard_images: no pose.txt" in out and "skipped c2_sigmoid_t1_v1: " in out
    # built already: the skipped folders are named again
    assert main(["suites", "build", "c3vd", "--from", str(root), "--data", str(data), "--frames-every", "6"]) == 0
    out = capsys.readouterr().out
    assert "already built" in out and "skipped c2_sigmoid_t1_v1: " in out
    # the download's own folder a sequence: its folders are the sequence's, none is skipped
    _, _, skipped = c3vd.find_download(root / "c1_cecum_t1_v1", intrinsics=root / "camera_intrinsics.txt")
    assert skipped == []


def test_a_download_of_only_skipped_folders_names_them(tmp_path):
    (tmp_path / "a" / "rgb").mkdir(parents=True)
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "pose.txt").write_text("1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1\n")
    with pytest.raises(InputError) as refused:
        c3vd.find_download(tmp_path)
    text = str(refused.value)
    assert "2 folder(s) skipped: " in text and "b (pose.txt without a coverage mesh" in text, text
    assert "a (no pose.txt in it or below" in text, text


def test_a_missing_argument_reads_as_the_usage(tmp_path, capsys):
    for argv, missing in ((["suites", "build", "c3vd"], "--from"), (["suites", "build", "--from", str(tmp_path)],
                                                                    "DATASET")):
        with pytest.raises(SystemExit) as stop:
            main(argv)
        err = capsys.readouterr().err
        assert stop.value.code == 2 and err.startswith("usage: colonbench suites build "), err
        assert f"error: the following arguments are required: {missing}" in err, err
        usage = err.split("colonbench suites build:")[0]
        names = re.search(r"required: (.*)", err).group(1).split(", ")
        assert all(n in usage for n in names), (names, usage)        # each as the usage line spells it
        assert "Traceback" not in err
    # the download's folder given in the dataset's place: told where it goes
    with pytest.raises(SystemExit):
        main(["suites", "build", str(tmp_path)])
    err = capsys.readouterr().err
    assert "argument DATASET: " in err and "c3vd" in err and f"--from {tmp_path}" in err, err


def test_the_docs_say_where_the_intrinsics_are_and_how_to_try_it_without_the_dataset(tmp_path, capsys):
    text = (ROOT / "docs" / "benchmark.md").read_text()
    section = text[text.index("## Real trajectories: C3VD"):]
    assert "camera_intrinsics.txt" in section and "cfhq190l_omnidirectional_params.zip" in section
    command = re.search(r"^python (scripts/c3vd_example\.py) DIR$", section, re.M)
    assert command, "docs/benchmark.md shows how to write the synthetic download"
    spec = importlib.util.spec_from_file_location("c3vd_example", ROOT / command.group(1))
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = tmp_path / "example"
    assert script.main([str(out), "--frames", "12"]) == 0
    assert (out / "camera_intrinsics.txt").is_file() and str(out) in capsys.readouterr().out
    assert main(["suites", "build", "c3vd", "--from", str(out), "--data", str(tmp_path / "suites"), "--quiet"]) == 0
    assert "built c3vd-" in capsys.readouterr().out
    assert script.main([str(out)]) == 2                       # refuses to write over what is there
    assert "not empty" in capsys.readouterr().err
