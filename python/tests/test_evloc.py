"""Tests of the evloc Python package: maps, every event reader, datasets, tracking (bit for bit
against evloc-track), trajectories, the service client with reconnect, and errors."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import evloc
from conftest import PROJECT_ROOT, Server, tool

# ----------------------------------------------------------------------------------------- maps


def test_map_arrays_and_summary(simulated):
    m = evloc.load_map(simulated / "gt_map")
    summary = m.summary()
    info = json.loads((simulated / "info.json").read_text())
    assert m.num_points == summary["num_points"] == info["counts"]["map_points"]
    assert m.positions.shape == (m.num_points, 3) and m.positions.dtype == np.float32
    assert m.gradients.shape == (m.num_points, 3)
    np.testing.assert_allclose(np.linalg.norm(m.gradients, axis=1), 1.0, atol=1e-3)
    assert m.keyframe_cam_from_world.shape == (summary["num_keyframes"], 4, 4)
    assert len(m.keyframe_t_ns) == summary["num_keyframes"] == info["counts"]["map_keyframes"]
    np.testing.assert_allclose(m.positions.min(axis=0), summary["bounding_box_min"])
    np.testing.assert_allclose(m.positions.max(axis=0), summary["bounding_box_max"])
    assert m.cameras[0]["width"] == info["camera"]["width"]
    assert len(m.source_keyframe) == len(m.inverse_depth_sigma) == m.num_points


def test_map_errors_are_evloc_messages(tmp_path, simulated):
    with pytest.raises(evloc.IoError, match="cannot open map"):
        evloc.load_map(tmp_path / "nothing.evmap")
    broken = tmp_path / "broken.evmap"
    data = bytearray((simulated / "gt_map" / "map.evmap").read_bytes())
    data[len(data) // 2] ^= 0xFF
    broken.write_bytes(bytes(data))
    with pytest.raises(evloc.ParseError, match="broken.evmap"):
        evloc.load_map(broken)
    assert issubclass(evloc.ParseError, ValueError) and issubclass(evloc.IoError, OSError)
    assert all(issubclass(e, evloc.Error) for e in (evloc.IoError, evloc.ParseError,
                                                    evloc.InvalidArgumentError))

# --------------------------------------------------------------------------------------- events


def expected_events(path):
    """`t_ns x y p` lines written by the independent writers of core/events/testing."""
    values = np.loadtxt(path, dtype=np.int64, ndmin=2)
    return values[:, 0], values[:, 1], values[:, 2], values[:, 3]


def assert_events_equal(events, expected):
    t, x, y, p = expected
    assert events.dtype == evloc.event_dtype
    np.testing.assert_array_equal(events["t"], t)
    np.testing.assert_array_equal(events["x"], x)
    np.testing.assert_array_equal(events["y"], y)
    np.testing.assert_array_equal(events["p"], p)


def test_ecd_text_reader(data_dir):
    path = os.path.join(data_dir, "ecd", "snippets", "shapes_rotation", "events.txt")
    reader = evloc.open_events(path, chunk_events=7000)
    chunks = list(reader)
    assert reader.format == "ECD text" and len(chunks) == 5
    events = np.concatenate(chunks)
    assert len(events) == 30000
    # The file's own text, parsed here as exact decimals of seconds.
    with open(path, encoding="utf-8") as handle:
        rows = [line.split() for line in handle if line.strip()]
    t = [int(s.split(".")[0]) * 10**9 + int((s.split(".")[1] + "000000000")[:9]) for s, *_ in rows]
    p = [1 if int(r[3]) > 0 else -1 for r in rows]
    assert_events_equal(events, (t, [int(r[1]) for r in rows], [int(r[2]) for r in rows], p))


def test_prophesee_evt3_matches_the_reference_decoding(data_dir):
    reader = evloc.open_events(os.path.join(data_dir, "prophesee", "evt3_sample.raw"))
    assert reader.sensor_size == (1280, 720)
    events = reader.read_all()
    assert len(events) == 219596 and reader.dropped_events == 0
    reference = np.load(os.path.join(data_dir, "prophesee", "evt3_sample.npy"))
    names = reference.dtype.names
    x = reference["x"]
    y = reference["y"]
    p = np.where(reference["p"] > 0, 1, -1)
    t_us = reference["t"].astype(np.int64)
    # The reference decoder (expelliarmus) adds 4096 us at every decreasing EVT_TIME_LOW word
    # (docs/event-formats.md, "The EVT 3.0 reference decoding"): evloc's times are the
    # reference's minus a non-decreasing multiple of 4096 us, 11 of them by the end.
    assert len(reference) == len(events), names
    np.testing.assert_array_equal(events["x"], x)
    np.testing.assert_array_equal(events["y"], y)
    np.testing.assert_array_equal(events["p"], p)
    extra = t_us * 1000 - events["t"]
    assert np.all(extra % 4_096_000 == 0) and np.all(np.diff(extra) >= 0)
    assert extra[0] == 0 and extra[-1] == 11 * 4_096_000
    assert events["t"][0] == 0xB2D000 * 1000


def test_prophesee_evt2(data_dir):
    reader = evloc.open_events(os.path.join(data_dir, "prophesee", "evt2_sample.raw"), 4096)
    events = reader.read_all()
    assert reader.sensor_size == (640, 480) and len(events) > 400000
    assert np.all(np.diff(events["t"]) >= 0)
    assert events["x"].max() < 640 and events["y"].max() < 480


def test_rosbag_reader(tmp_path):
    subprocess.run([sys.executable, os.path.join(PROJECT_ROOT, "core", "events", "testing",
                                                 "write_test_bags.py"), str(tmp_path)],
                   check=True, stdout=subprocess.DEVNULL)
    for compression in ("none", "bz2", "lz4"):
        reader = evloc.open_events(tmp_path / f"test_{compression}.bag", chunk_events=5)
        assert reader.format == "ROS1 bag"
        assert_events_equal(reader.read_all(), expected_events(tmp_path / "expected_dvs.txt"))


def test_aedat4_reader(tmp_path):
    subprocess.run([sys.executable, os.path.join(PROJECT_ROOT, "core", "events", "testing",
                                                 "write_test_aedat4.py"), str(tmp_path)],
                   check=True, stdout=subprocess.DEVNULL)
    for compression in ("none", "lz4", "zstd"):
        reader = evloc.open_events(tmp_path / f"test_{compression}.aedat4")
        assert reader.format == "AEDAT4"
        assert_events_equal(reader.read_all(), expected_events(tmp_path / "expected_events.txt"))


def test_dsec_hdf5_reader(tmp_path):
    h5py = pytest.importorskip("h5py", reason="python3-h5py (scripts/install-deps.sh) writes "
                                              "the reference file")
    rng = np.random.default_rng(1)
    t_us = np.sort(rng.integers(0, 10**6, 5000)).astype(np.uint32)
    x = rng.integers(0, 640, 5000).astype(np.uint16)
    y = rng.integers(0, 480, 5000).astype(np.uint16)
    p = rng.integers(0, 2, 5000).astype(np.uint8)
    path = tmp_path / "events.h5"
    with h5py.File(path, "w") as handle:
        for name, values in (("x", x), ("y", y), ("p", p), ("t", t_us)):
            handle.create_dataset("events/" + name, data=values)
        handle.create_dataset("t_offset", data=np.int64(123456))
    reader = evloc.open_events(path, chunk_events=999)
    assert reader.format == "DSEC HDF5"
    assert_events_equal(reader.read_all(), ((t_us.astype(np.int64) + 123456) * 1000, x, y,
                                            np.where(p > 0, 1, -1)))


def test_evb_reader_and_dataset(simulated):
    dataset = evloc.read_dataset(simulated)
    assert dataset.events_path.endswith("events.evb")
    assert evloc.detect_event_format(dataset.events_path) == "evloc .evb"
    events = evloc.read_events(dataset.events_path)
    info = json.loads((simulated / "info.json").read_text())
    assert len(events) == info["counts"]["events"]
    assert np.all(np.diff(events["t"]) >= 0)
    assert events["x"].max() < dataset.camera["width"]
    np.testing.assert_array_equal(np.concatenate(list(dataset.events(100000))), events)
    assert len(dataset.ground_truth) == info["counts"]["ground_truth_poses"]


def test_reader_errors(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("0.1 1 2 1\n0.2 x 2 1\n")
    with pytest.raises(evloc.ParseError, match="line 2"):
        evloc.read_events(bad)
    with pytest.raises(evloc.IoError):
        evloc.open_events(tmp_path / "missing.raw")

# ------------------------------------------------------------------------------------- tracking


def test_track_dataset_equals_evloc_track_bit_for_bit(simulated, cli_trajectory, tmp_path):
    cli_out, cli_stats = cli_trajectory
    out = tmp_path / "python.txt"
    result = evloc.track_dataset(simulated / "gt_map", simulated, out=out)
    assert out.read_bytes() == cli_out.read_bytes()
    stats = json.loads(cli_stats.read_text())
    assert len(result.steps) == stats["steps"] and result.measurements == stats["measurements"]
    assert [s.name for s in result.steps.statuses] == [s["status"] for s in stats["per_step"]]
    np.testing.assert_array_equal(result.steps.points_used,
                                  [s["points_used"] for s in stats["per_step"]])
    assert result.steps.statuses.count(evloc.Status.TRACKING) > 0.9 * len(result.steps)


def test_track_events_from_arrays_equals_evloc_track(simulated, cli_trajectory):
    dataset = evloc.read_dataset(simulated)
    events = dataset.events().read_all()
    t0, pose = dataset.initial_pose()
    m = evloc.load_map(simulated / "gt_map")
    result = evloc.track_events(m, dataset.camera, events, pose, t0)
    assert result.trajectory.to_tum_text() == cli_trajectory[0].read_text()
    # The same through a (t, x, y, p) tuple with polarity 0/1, and through the live tracker in
    # uneven chunks (the poses do not depend on the batching).
    as_tuple = (events["t"], events["x"], events["y"], (events["p"] > 0).astype(np.uint8))
    again = evloc.track_events(m, dataset.camera, as_tuple, pose, t0)
    np.testing.assert_array_equal(again.trajectory.poses, result.trajectory.poses)
    tracker = evloc.Tracker(m, dataset.camera)
    tracker.reset(pose, t0)
    poses = []
    for begin in range(0, len(events), 77777):
        steps = tracker.add_events(events[begin:begin + 77777])
        poses += [steps.pose[i] for i in range(len(steps))]
    np.testing.assert_array_equal(np.array(poses), result.steps.pose[:len(poses)])
    assert tracker.status == evloc.Status.TRACKING
    assert result.steps.covariance.shape == (len(result.steps), 6, 6)


def test_tracking_options_are_evloc_tracks_flags(simulated):
    dataset = evloc.read_dataset(simulated)
    events = dataset.events().read_all()[:200000]
    t0, pose = dataset.initial_pose()
    m = evloc.load_map(simulated / "gt_map")
    result = evloc.track_events(m, dataset.camera, events, pose, t0, rate=100, polarity=False,
                                variant="EVT-PR", max_points=500)
    assert np.all(np.diff(result.steps.t_ns) == 10_000_000)
    assert result.steps.points_used.max() <= 500
    with pytest.raises(evloc.InvalidArgumentError, match="step_rate_hz"):
        evloc.track_events(m, dataset.camera, events, pose, t0, rate=-3)
    with pytest.raises(evloc.InvalidArgumentError, match="unknown flag '--no-such-option'"):
        evloc.Tracker(m, dataset.camera, no_such_option=1)
    with pytest.raises(evloc.InvalidArgumentError, match="quaternion"):
        evloc.track_events(m, dataset.camera, events, [0, 0, 0, 0, 0, 0, 2], t0)
    with pytest.raises(evloc.InvalidArgumentError, match="time goes back"):
        evloc.track_events(m, dataset.camera, events[::-1], pose, t0)
    with pytest.raises(evloc.InvalidArgumentError, match="'fx' is missing"):
        evloc.Tracker(m, {"width": 640, "height": 480})


def test_trajectory_tum_round_trip_for_evo(cli_trajectory, tmp_path):
    trajectory = evloc.Trajectory.load_tum(cli_trajectory[0])
    copy = tmp_path / "copy.txt"
    trajectory.save_tum(copy)
    # Reading normalises each quaternion again (a last-digit change at most); the bytes of a
    # written run are compared in test_track_events_from_arrays_equals_evloc_track.
    np.testing.assert_allclose(evloc.Trajectory.load_tum(copy).poses, trajectory.poses,
                               rtol=0, atol=1e-15)
    np.testing.assert_array_equal(evloc.Trajectory.load_tum(copy).t_ns, trajectory.t_ns)
    # The TUM layout evo's file_interface.read_tum_trajectory_file parses: 8 numeric columns,
    # `#` comments, timestamps in seconds.
    rows = [line.split() for line in copy.read_text().splitlines() if not line.startswith("#")]
    assert all(len(row) == 8 for row in rows)
    table = np.array(rows, dtype=np.float64)
    np.testing.assert_allclose(table[:, 0], trajectory.timestamps, rtol=0, atol=1e-9)
    np.testing.assert_allclose(table[:, 1:], trajectory.poses, rtol=0, atol=1e-9)
    matrices = trajectory.matrices()
    np.testing.assert_allclose(matrices[:, :3, 3], trajectory.positions)
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", matrices[:, :3, :3],
                                         matrices[:, :3, :3]), np.broadcast_to(np.eye(3),
                                                                               (len(trajectory), 3, 3)),
                               atol=1e-9)
    bad = tmp_path / "bad.txt"
    bad.write_text("0.1 0 0 0 0 0 0 1\n0.2 0 0 zero 0 0 0 1\n")
    with pytest.raises(evloc.ParseError, match="line 2"):
        evloc.Trajectory.load_tum(bad)

# --------------------------------------------------------------------------------------- client


def stream(session, events, chunk=50000):
    for begin in range(0, len(events), chunk):
        session.send(events[begin:begin + chunk])


def test_client_poses_equal_evloc_replay(server, simulated, cli_trajectory, tmp_path):
    dataset = evloc.read_dataset(simulated)
    events = dataset.events().read_all()
    t0, pose = dataset.initial_pose()
    with evloc.Client(server.address) as client:
        maps = client.list_maps()
        assert [m.name for m in maps] == ["room"]
        with client.session("room", dataset.camera, initial_pose=pose, initial_t_ns=t0) as s:
            stream(s, events)
            # As evloc-replay: the last packet ends where its 1 ms window ends.
            s.close(end_t_ns=int(events["t"][-1]) + 1_000_000)
            updates = list(s.poses())
        assert s.end is not None and s.end.events == len(events)
    assert all(isinstance(u.status, evloc.Status) for u in updates)
    assert updates[0].covariance.shape == (6, 6)
    got = evloc.Trajectory([u.t_ns for u in updates], [u.pose for u in updates])
    # The reference client on the same server gives the same steps and poses (evloc-replay
    # normalises each received quaternion once more, RigidFromProto: at most 1 ulp; this client
    # keeps the server's doubles).
    replayed = tmp_path / "replay.txt"
    subprocess.run([tool("tools/replay/evloc-replay"), "--server", server.address, "--map",
                    "room", "--dataset", str(simulated), "--speed", "max", "--out",
                    str(replayed)], check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    reference = evloc.Trajectory.load_tum(replayed)
    np.testing.assert_array_equal(got.t_ns, reference.t_ns)
    np.testing.assert_allclose(got.poses, reference.poses, rtol=0, atol=1e-15)
    # evloc-track's poses, to the last bit of the quaternion (the service normalises the
    # initial pose it receives once more: 1 ulp).
    # The file holds no event after the last one, so evloc-track does not run the step that the
    # end of the last packet completes: one step fewer.
    expected = evloc.Trajectory.load_tum(cli_trajectory[0])
    assert len(expected) == len(got) - 1
    np.testing.assert_array_equal(got.t_ns[:-1], expected.t_ns)
    np.testing.assert_allclose(got.poses[:-1], expected.poses, rtol=0, atol=1e-12)


def test_client_reconnects_to_another_server_from_the_last_pose(maps_folder, simulated,
                                                                 cli_trajectory, tmp_path):
    dataset = evloc.read_dataset(simulated)
    events = dataset.events().read_all()
    t0, pose = dataset.initial_pose()
    first = Server(maps_folder, tmp_path / "first.log")
    second = None
    try:
        with evloc.Client(first.address) as client:
            with client.session("room", dataset.camera, initial_pose=pose, initial_t_ns=t0,
                                reconnect=30, backoff_ms=50, seed=1) as s:
                half = len(events) // 2
                stream(s, events[:half])
                received = []
                for update in s.poses(timeout=60):
                    received.append(update)
                    if update.t_ns >= events["t"][half - 1] - 20_000_000:
                        break
                # The server drains (SIGTERM); another one takes its port.
                port = first.port
                first.stop()
                second = Server(maps_folder, tmp_path / "second.log", port=port)
                stream(s, events[half:])
                s.close()
                received += list(s.poses(timeout=60))
        assert s.reconnects >= 1
        resumed = [u for u in received if u.session > 0]
        assert resumed and all(u.status == evloc.Status.TRACKING for u in resumed)
        expected = evloc.Trajectory.load_tum(cli_trajectory[0])
        last = resumed[-1]
        index = int(np.searchsorted(expected.t_ns, last.t_ns))
        assert expected.t_ns[index] == last.t_ns
        # Resumed from the last pose with 100 ms of priming events: within 2 cm of the
        # uninterrupted run at the end (evloc-replay's reconnect test measures ~1.4 cm).
        assert np.linalg.norm(last.pose[:3] - expected.poses[index, :3]) < 0.02
    finally:
        first.stop()
        if second is not None:
            second.stop()


def test_client_errors(server, simulated):
    dataset = evloc.read_dataset(simulated)
    with evloc.Client(server.address) as client:
        with pytest.raises(evloc.client.ServiceError, match="NOT_FOUND"):
            with client.session("no-such-map", dataset.camera, initial_pose=[0, 0, 0, 0, 0, 0, 1],
                                initial_t_ns=0):
                pass
        bad_camera = dict(dataset.camera, fx=-1.0)
        with pytest.raises(evloc.client.ServiceError, match="INVALID_ARGUMENT"):
            with client.session("room", bad_camera, initial_pose=[0, 0, 0, 0, 0, 0, 1],
                                initial_t_ns=0):
                pass


def test_client_thins_its_stream_only_while_the_server_searches(maps_folder, simulated,
                                                                 tmp_path):
    dataset = evloc.read_dataset(simulated)
    events = dataset.events().read_all()
    # 2 events per pixel and second: 614,400 events/s at 640x480, under the render's ~3 M.
    running = Server(maps_folder, tmp_path / "server.log", extra=("--searching-event-rate", "2"))
    try:
        counts = {}
        for thin in (False, True):
            with evloc.Client(running.address) as client:
                with client.session("room", dataset.camera, initial_pose=None,
                                    initial_t_ns=int(events["t"][0]) - 1,
                                    thin_while_searching=thin) as s:
                    assert s.started.searching_event_rate == 2 * 640 * 480
                    stream(s, events)
                    s.close(end_t_ns=int(events["t"][-1]) + 1_000_000)
                    updates = list(s.poses())
                assert s.end is not None
                # A server behind a searching stream sheds its oldest packets (SessionEnd.
                # events_shed; under a loaded machine it does): those were sent, not thinned.
                counts[thin] = (s.events_thinned, s.end.events + s.end.events_shed, updates)
        assert counts[False][0] == 0 and counts[False][1] == len(events)
        thinned, received, updates = counts[True]
        assert thinned > 0
        assert received + thinned == len(events)
        # Only while searching: after the first update with a pose nothing more is left out,
        # so a session found early keeps most of its events.
        if any(u.pose is not None for u in updates):
            assert thinned < len(events)
    finally:
        running.stop()


def test_thinning_stride_matches_evloc_replays():
    from evloc.client import thinning_stride  # pylint: disable=import-outside-toplevel
    assert thinning_stride(1000, 1_000_000, 0) == 1
    assert thinning_stride(1000, 1_000_000, 1_000_000) == 1
    assert thinning_stride(1001, 1_000_000, 1_000_000) == 2
    assert thinning_stride(11_700, 1_000_000, 6_144_000) == 2
    assert thinning_stride(11_700, 1_000_000, 2_900_000) == 5
    assert thinning_stride(50, 1_000, 1_000_000) == 50
    assert thinning_stride(0, 1_000_000, 1) == 1


def test_packed_encoding_layout():
    data = evloc.encode_packed(np.array([100, 105]), np.array([3, 640]), np.array([4, 479]),
                               np.array([1, -1]), 100)
    assert data == (bytes.fromhex("00000080") + (3).to_bytes(2, "little") +
                    (4).to_bytes(2, "little") + (5).to_bytes(4, "little") +
                    (640).to_bytes(2, "little") + (479).to_bytes(2, "little"))
    with pytest.raises(ValueError):
        evloc.encode_packed(np.array([99]), np.array([0]), np.array([0]), np.array([1]), 100)

# -------------------------------------------------------------------------------------- example


def test_example_tracks_and_plots(simulated, tmp_path):
    out = tmp_path / "example"
    completed = subprocess.run(
        [sys.executable, os.path.join(PROJECT_ROOT, "examples", "python", "track_and_plot.py"),
         "--out", str(out), "--dataset", str(simulated), "--map", str(simulated / "gt_map"),
         "--build", os.environ.get("EVLOC_BUILD_DIR", os.path.join(PROJECT_ROOT, "build"))],
        check=True, capture_output=True, text=True)
    assert "steps TRACKING" in completed.stdout
    png = (out / "trajectory.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 20000
    # The estimate as evo reads a TUM file (plain columns), scored here and by evloc-eval: the
    # same position RMSE (ground truth interpolated at the estimate's times, no alignment).
    table = np.loadtxt(out / "estimate.txt", comments="#")
    truth = np.loadtxt(simulated / "groundtruth.txt", comments="#")
    interpolated = np.stack([np.interp(table[:, 0], truth[:, 0], truth[:, k]) for k in (1, 2, 3)],
                            axis=1)
    rmse_cm = 100 * np.sqrt(np.mean(np.sum((table[:, 1:4] - interpolated) ** 2, axis=1)))
    report = tmp_path / "eval.json"
    subprocess.run([tool("tools/eval/evloc-eval"), "--align", "none", "--gt",
                    str(simulated / "groundtruth.txt"), "--est", str(out / "estimate.txt"),
                    "--json", str(report)], check=True, stdout=subprocess.DEVNULL)
    scores = json.loads(report.read_text())
    assert scores["matched_poses"] == len(table)
    assert abs(scores["ate_t_rmse_cm"] - rmse_cm) < 1e-6, (scores["ate_t_rmse_cm"], rmse_cm)
    assert f"position RMSE {rmse_cm:.2f} cm" in completed.stdout
    assert rmse_cm < 2.0


@pytest.mark.skipif(os.environ.get("EVLOC_LONG_TESTS") != "1",
                    reason="long (simulates and maps with COLMAP, about 1.5 min): ctest -L long "
                           "runs it as evloc_python_example_long_test")
def test_example_from_nothing_simulates_maps_tracks_and_plots(tmp_path):
    out = tmp_path / "example"
    completed = subprocess.run(
        [sys.executable, os.path.join(PROJECT_ROOT, "examples", "python", "track_and_plot.py"),
         "--out", str(out), "--build",
         os.environ.get("EVLOC_BUILD_DIR", os.path.join(PROJECT_ROOT, "build"))],
        check=True, capture_output=True, text=True)
    m = evloc.load_map(out / "map")
    assert m.summary()["num_keyframes"] == 10 and m.num_points > 10000
    rmse_cm = float(completed.stdout.split("position RMSE ")[1].split(" cm")[0])
    assert rmse_cm < 2.0, completed.stdout
    assert (out / "trajectory.png").stat().st_size > 20000


def test_random_inputs_give_errors_never_crashes(simulated, tmp_path):
    """Random arrays, poses, cameras, options and file bytes through the bindings: each call
    returns or raises one of the documented exceptions (a crash would end the test process)."""
    rng = np.random.default_rng(7)
    m = evloc.load_map(simulated / "gt_map")
    camera = evloc.read_dataset(simulated).camera
    allowed = (evloc.Error, ValueError, TypeError, OverflowError, KeyError)
    outcomes = {"ok": 0, "error": 0}
    for case in range(120):
        n = int(rng.integers(0, 2000))
        t = np.sort(rng.integers(-10**9, 10**9, n)) if rng.random() < 0.8 else \
            rng.integers(-10**12, 10**12, n)
        events = (t, rng.integers(-5, 700, n), rng.integers(-5, 500, n), rng.integers(-2, 3, n))
        pose = rng.normal(size=7) if rng.random() < 0.5 else np.r_[rng.normal(size=3), 0, 0, 0, 1]
        options = {}
        if rng.random() < 0.3:
            options[str(rng.choice(["rate", "tau", "max_points", "variant", "polarity"]))] = \
                rng.choice(["-1", "0", "abc", "1e9", "EVT-PR", "on", "nan"])
        cam = dict(camera)
        if rng.random() < 0.2:
            bad_values = [-1, 0, "fisheye", [1.0], float("nan"), 70000]
            cam[str(rng.choice(["fx", "width", "model", "distortion"]))] = \
                bad_values[int(rng.integers(0, len(bad_values)))]
        try:
            evloc.track_events(m, cam, events, pose, int(rng.integers(-10**9, 10**9)), **options)
            outcomes["ok"] += 1
        except allowed:
            outcomes["error"] += 1
        data = rng.integers(0, 256, int(rng.integers(0, 400))).astype(np.uint8).tobytes()
        header = [b"", b"% evt 3.0\n% end\n", b"\x89HDF\r\n\x1a\n", b"#!AER-DAT4.0\r\n",
                  b"#ROSBAG V2.0\n", b"EVB1"][case % 6]
        path = tmp_path / f"random_{case}.dat"
        path.write_bytes(header + data)
        try:
            evloc.read_events(path)
        except allowed:
            pass
    assert outcomes["ok"] > 0 and outcomes["error"] > 0, outcomes


def test_client_with_tls_and_a_token(maps_folder, simulated, tmp_path):
    """The server with TLS (a CA made here with openssl) and bearer tokens: the client with the
    CA and a token file lists the maps and tracks; a wrong token is UNAUTHENTICATED."""
    def openssl(*arguments):
        subprocess.run(["openssl", *arguments], check=True, capture_output=True)

    ca, server_key, server_csr, server_crt = (tmp_path / n for n in
                                              ("ca.crt", "server.key", "server.csr", "server.crt"))
    openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
            "-days", "1", "-subj", "/CN=test-ca", "-keyout", str(tmp_path / "ca.key"), "-out",
            str(ca))
    (tmp_path / "server.ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-subj",
            "/CN=localhost", "-keyout", str(server_key), "-out", str(server_csr))
    openssl("x509", "-req", "-days", "1", "-in", str(server_csr), "-CA", str(ca), "-CAkey",
            str(tmp_path / "ca.key"), "-CAcreateserial", "-extfile", str(tmp_path / "server.ext"),
            "-out", str(server_crt))
    tokens = tmp_path / "tokens.txt"
    tokens.write_text("s3cret-token-for-the-test *\n")
    tokens.chmod(0o600)
    token_file = tmp_path / "token.txt"
    token_file.write_text("s3cret-token-for-the-test\n")
    server = Server(maps_folder, tmp_path / "tls.log",
                    extra=("--tls-cert", str(server_crt), "--tls-key", str(server_key),
                           "--auth-tokens", str(tokens)))
    try:
        dataset = evloc.read_dataset(simulated)
        events = dataset.events().read_all()[:300000]
        t0, pose = dataset.initial_pose()
        address = f"localhost:{server.port}"
        with evloc.Client(address, token_file=token_file, tls={"ca": ca}) as client:
            assert [m.name for m in client.list_maps()] == ["room"]
            with client.session("room", dataset.camera, initial_pose=pose, initial_t_ns=t0) as s:
                stream(s, events)
                s.close()
                updates = list(s.poses())
            assert updates and all(u.status == evloc.Status.TRACKING for u in updates)
        with evloc.Client(address, token="wrong", tls={"ca": ca}) as client:
            with pytest.raises(evloc.ServiceError, match="UNAUTHENTICATED"):
                client.list_maps()
    finally:
        server.stop()


def test_body_twist_is_the_motion_models_twist():
    """body_twist inverts newer = older * exp(dt * twist) (the resumed session's velocity)."""
    older = np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0])
    # 0.05 rad of yaw in 0.1 s: 0.5 rad/s about the camera z axis.
    angle = 0.05
    newer_rotation = [0.0, 0.0, np.sin(angle / 2), np.cos(angle / 2)]
    twist = evloc._native._evloc.body_twist(older, older, 0.1)
    assert np.all(twist == 0)
    # Pure translation: the twist is the displacement per second in the camera frame.
    shifted = older.copy()
    shifted[0] += 0.1
    np.testing.assert_allclose(evloc._native._evloc.body_twist(older, shifted, 0.1),
                               [1, 0, 0, 0, 0, 0], atol=1e-12)
    turned = np.concatenate([older[:3], newer_rotation])
    np.testing.assert_allclose(evloc._native._evloc.body_twist(older, turned, 0.1),
                               [0, 0, 0, 0, 0, 0.5], atol=1e-12)
    with pytest.raises(evloc.Error):
        evloc._native._evloc.body_twist(older, shifted, 0.0)
