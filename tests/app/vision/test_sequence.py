"""app.vision.sequence and ``mcit track``: pose files, clicked points, frames in and overlay video out."""

import csv

import cv2
import numpy as np
import pytest

from app.cli import main
from app.vision.sequence import iter_frames, read_init_points, read_visp_pose, track_sequence
from core.transforms import exp_so3, log_so3, make_T, pose_error

from .sequence_files import write_sequence


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A folder of 5 rendered frames of a moving box, its model (.cao), intrinsics (ViSP .xml), first pose (.pos)."""
    return write_sequence(tmp_path_factory.mktemp("seq"), 5)


def test_visp_pose_and_init_files(tmp_path):
    T = make_T(exp_so3([0.3, -1.0, 2.0]), [0.1, -0.2, 0.5])
    p = tmp_path / "obj.pos"
    p.write_text(" ".join(str(x) for x in np.r_[T[:3, 3], log_so3(T[:3, :3])]))
    assert np.allclose(read_visp_pose(p), T)
    p.write_text("1 2 3")
    with pytest.raises(ValueError, match="six"):
        read_visp_pose(p)
    q = tmp_path / "pts.init"
    q.write_text("# comment\n3 # points\n0 0 0 # first\n0.1 0 0\n0 0.2 0.3\n")
    assert np.allclose(read_init_points(q), [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0.3]])
    q.write_text("4\n0 0 0\n")
    with pytest.raises(ValueError, match="pts.init:1: the number of points is more than"):
        read_init_points(q)
    # ViSP >= 3.7: an .init may load another's points, placed by t= (mcit track --init-points reads it)
    q.write_text("1\n0 0 0\n")
    r = tmp_path / "both.init"
    r.write_text('load("pts.init", t=[0.5; 0; 0])\n1\n0 0 1\n')
    assert np.allclose(read_init_points(r), [[0.5, 0, 0], [0, 0, 1]])


def test_iter_frames_reads_folders_and_videos_once(rendered, tmp_path):
    d = rendered[0]
    frames = list(iter_frames(d / "frames"))
    assert [i for i, _ in frames] == [0, 1, 2, 3, 4]
    assert frames[0][1].shape == (240, 320, 3) and frames[0][1].dtype == np.uint8
    assert [i for i, _ in iter_frames(d / "frames", 2, 2)] == [2, 3]
    video = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    for _, f in frames:
        w.write(f)
    w.release()
    assert [i for i, _ in iter_frames(video, 1)] == [1, 2, 3, 4]
    with pytest.raises(ValueError, match="no such"):
        list(iter_frames(tmp_path / "missing"))


def test_track_sequence_writes_the_overlay_video_and_poses(rendered, tmp_path):
    d, cam, box, truth = rendered
    out = track_sequence(d / "frames", cam, box, truth[0], video_out=tmp_path / "o.avi", csv_out=tmp_path / "p.csv")
    assert [f.index for f in out] == [0, 1, 2, 3, 4] and not any(f.lost for f in out)
    for f, T in zip(out, truth):
        assert pose_error(f.T_world_obj, T)[0] < 0.5
    cap = cv2.VideoCapture(str(tmp_path / "o.avi"))
    n = 0
    while cap.read()[0]:
        n += 1
    # an image folder states no rate: written at the rate mcit serve reads a folder at (a new user saw 10 and 25)
    assert n == 5 and cap.get(cv2.CAP_PROP_FPS) == pytest.approx(10.0)
    rows = list(csv.DictReader(open(tmp_path / "p.csv")))
    assert len(rows) == 5 and float(rows[-1]["tx_m"]) == pytest.approx(truth[-1][0, 3], abs=2e-3)


def test_the_overlay_video_plays_at_the_source_videos_rate(rendered, tmp_path):
    d, cam, box, truth = rendered
    video = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    for _, f in iter_frames(d / "frames"):
        w.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    w.release()
    track_sequence(video, cam, box, truth[0], count=2, video_out=tmp_path / "o.avi")
    assert cv2.VideoCapture(str(tmp_path / "o.avi")).get(cv2.CAP_PROP_FPS) == pytest.approx(10.0)
    track_sequence(video, cam, box, truth[0], count=2, video_out=tmp_path / "p.avi", fps_out=30.0)
    assert cv2.VideoCapture(str(tmp_path / "p.avi")).get(cv2.CAP_PROP_FPS) == pytest.approx(30.0)


def test_mcit_track_command(rendered, tmp_path, capsys):
    d = rendered[0]
    args = ["track", str(d / "frames"), "--model", str(d / "box.cao"), "--intrinsics", str(d / "cam.xml")]
    assert (
        main(args + ["--pose", str(d / "box.pos"), "--out", str(tmp_path / "t.avi"), "--csv", str(tmp_path / "t.csv")])
        == 0
    )
    out = capsys.readouterr().out
    assert "tracked 5 frames" in out and (tmp_path / "t.avi").stat().st_size > 0
    # a pose far from the truth: lost on the first frame, exit status 3, and says how to restart
    (tmp_path / "bad.json").write_text('{"xyz": [0.3, 0.2, 0.9], "rpy_deg": [0, 0, 0]}')
    assert main(args + ["--pose", str(tmp_path / "bad.json"), "--out", str(tmp_path / "b.avi")]) == 3
    assert "LOST at frame 0" in capsys.readouterr().err
    # clicked points initialise the pose
    cam, box, truth = rendered[1:]
    X = box.vertices[[4, 5, 6, 7]]
    (tmp_path / "box.init").write_text("4\n" + "\n".join(" ".join(str(c) for c in x) for x in X))
    clicks = [f"{u:.2f},{v:.2f}" for u, v in cam.project_obj(truth[0], X) + 0.7]
    assert (
        main(
            args
            + ["--init-points", str(tmp_path / "box.init"), "--init-clicks", *clicks, "--out", str(tmp_path / "c.avi")]
        )
        == 0
    )
    # missing pieces are one-line errors
    assert main(["track", str(d / "frames"), "--model", str(d / "box.cao"), "--intrinsics", str(d / "cam.xml")]) == 2
    assert "initial pose" in capsys.readouterr().err


def test_a_start_past_the_last_frame_is_said_and_nothing_is_written(rendered, tmp_path, capsys):
    d = rendered[0]
    args = ["track", str(d / "frames"), "--model", str(d / "box.cao"), "--intrinsics", str(d / "cam.xml")]
    args += ["--pose", str(d / "box.pos"), "--csv", str(tmp_path / "t.csv")]
    assert main(args + ["--start", "9"]) == 1  # was exit 70, an internal error (StopIteration)
    err = capsys.readouterr().err
    assert "has 5 frames (0–4), none at --start 9: give --start from 0 to 4" in err and "Traceback" not in err
    with pytest.raises(SystemExit) as refused:  # argparse's own one line
        main(args + ["--start", "-2"])
    assert refused.value.code == 2
    assert "expected a frame number from 0" in capsys.readouterr().err
    assert not (tmp_path / "t.csv").exists()
